"""An attacker on loopback against the signed (and unsigned) link, both ends, over real UDP.

Each test is a failure found in issue 14: replayed signed frames from a new port, a signing clock
that fell behind, a forged far-future timestamp, junk evicting the GCS from the mock's peer table,
junk corrupting the next datagrams, and the SETUP_SIGNING of a stranger. The "vehicle" or "GCS"
at the attacked end is the real one; the other end is a raw socket with pymavlink bytes.
"""

from __future__ import annotations

import asyncio
import dataclasses
import math
import socket
import time

import pytest
from pymavlink.dialects.v20 import ardupilotmega as mavlink
from refusals import refused

from gcs_planner.mavlink import errors
from gcs_planner.mavlink.link import MavlinkLink
from gcs_planner.mavlink.mission import MissionClient
from gcs_planner.wire.enums import MissionResult
from gcs_planner.wire.framing import frames
from gcs_planner.wire.signing import key_from_passphrase, setup_signing_message
from sitl_mock.fleet import MockFleet

KEY = key_from_passphrase("correct horse battery staple")
JUNK = bytes((0xFD, 0xFF, 0x00))  # a MAVLink 2 start claiming 255 payload bytes, then nothing


def signing_timestamp() -> int:
    """Now in signing units (10 us since 2015-01-01), computed here, independent of the code."""
    return int((time.time() - 1_420_070_400) * 100_000)


def signature_fields(frame: bytes) -> tuple[int, int]:
    """(link id, timestamp) of a signed MAVLink 2 frame."""
    assert frame[0] == 0xFD and frame[2] & 0x01, "not a signed MAVLink 2 frame"
    return frame[-13], int.from_bytes(frame[-12:-6], "little")


def _codec(sysid: int, compid: int, key: bytes | None) -> mavlink.MAVLink:
    codec = mavlink.MAVLink(None, srcSystem=sysid, srcComponent=compid)
    if key is not None:
        codec.signing.secret_key, codec.signing.sign_outgoing = key, True
    return codec


class Peer:
    """A raw UDP endpoint packing (and, with a key, signing) pymavlink frames as sysid/compid; its
    signing timestamp is the clock at each frame, +1 when two frames share a 10 us tick."""

    def __init__(self, sysid: int, compid: int, key: bytes | None = None) -> None:
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.sock.setblocking(False)
        self.codec = _codec(sysid, compid, key)
        self.pending: list[bytes] = []  # frames of a datagram not yet returned by recv

    @property
    def address(self) -> tuple[str, int]:
        return self.sock.getsockname()

    def frame(self, msg: mavlink.MAVLink_message) -> bytes:
        self.codec.signing.timestamp = max(self.codec.signing.timestamp, signing_timestamp())
        raw = msg.pack(self.codec)  # pymavlink adds 1 to the timestamp after signing
        self.codec.seq = (self.codec.seq + 1) % 256
        return raw

    def send(self, data: bytes, to: tuple[str, int]) -> None:
        self.sock.sendto(data, to)

    async def recv(self, timeout_s: float = 3.0) -> bytes:
        """The next frame received (a vehicle sends a tick's frames in one datagram)."""
        while not self.pending:
            data = await asyncio.wait_for(asyncio.get_running_loop().sock_recv(self.sock, 2048), timeout_s)
            self.pending.extend(frames(data)[0])
        return self.pending.pop(0)

    def close(self) -> None:
        self.sock.close()


def _heartbeat() -> mavlink.MAVLink_message:
    return mavlink.MAVLink_heartbeat_message(mavlink.MAV_TYPE_GCS, mavlink.MAV_AUTOPILOT_INVALID, 0, 0, 4, 3)


def _command(command: int, param1: float) -> mavlink.MAVLink_message:
    return mavlink.MAVLink_command_long_message(1, 1, command, 0, param1, 0, 0, 0, 0, 0, 0)


def _forged(sysid: int, compid: int, timestamp: int, msg: mavlink.MAVLink_message) -> bytes:
    """``msg`` from sysid/compid on link 0 with ``timestamp`` and a signature made with the wrong key."""
    wrong = _codec(sysid, compid, key_from_passphrase("attacker"))
    wrong.signing.timestamp = timestamp
    return msg.pack(wrong)


async def _until(predicate, timeout_s: float = 4.0) -> None:
    """Poll ``predicate`` in the running loop (the fleet shares it)."""
    for _ in range(int(timeout_s / 0.01)):
        if predicate():
            return
        await asyncio.sleep(0.01)
    raise AssertionError("condition not reached")


async def _ack(peer: Peer, command: int, timeout_s: float = 3.0) -> mavlink.MAVLink_message:
    parser = mavlink.MAVLink(None)
    while True:
        raw = await peer.recv(timeout_s)
        msg = parser.decode(bytearray(raw))
        if msg.get_type() == "COMMAND_ACK" and msg.command == command:
            return msg


# ----------------------------------------------------------------- the mock under attack
def test_signed_clear_all_replayed_from_a_new_port_is_refused(mission_of):
    """Failure 2: the vehicle had one replay table per source address; now one per vehicle."""

    async def main():
        async with MockFleet(count=1, signing_key=KEY, flight={"arm_ready_s": 0}) as fleet:
            vehicle = fleet.vehicle(1)
            gcs = Peer(255, 190, KEY)
            captured = gcs.frame(mavlink.MAVLink_mission_clear_all_message(1, 1, 0))
            gcs.send(captured, vehicle.address)  # the operator clears (nothing stored yet)
            host, port = vehicle.address
            link = await MavlinkLink.open(f"udpout:{host}:{port}", signing_key=KEY)
            await MissionClient(link, 1).upload(mission_of(4))  # same stream (255, 190, link 0)
            assert len(vehicle.mission_server.items()) == 4
            attacker = Peer(66, 1)
            rejected = vehicle.link.rejected
            attacker.send(captured, vehicle.address)  # byte for byte, from a port never heard
            await _until(lambda: vehicle.link.rejected > rejected)
            assert len(vehicle.mission_server.items()) == 4
            assert vehicle.link.signing.verifier.replayed >= 1
            assert attacker.address not in vehicle.link.peers
            await link.close()
            gcs.close()
            attacker.close()

    asyncio.run(asyncio.wait_for(main(), 20))


def test_signed_mock_timestamps_follow_the_clock_and_never_repeat():
    """Failure 3: the mock's timestamp was set once at start and advanced 10 us per frame, so a
    receiver started a minute later refused it. A reply packed after t0 must carry >= t0."""

    async def main():
        async with MockFleet(count=1, signing_key=KEY) as fleet:
            vehicle = fleet.vehicle(1)
            gcs = Peer(255, 190, KEY)
            gcs.send(gcs.frame(_heartbeat()), vehicle.address)
            await gcs.recv()  # the vehicle greets its new peer
            await asyncio.sleep(1.0)
            t0 = signing_timestamp()
            request = _command(mavlink.MAV_CMD_REQUEST_MESSAGE, mavlink.MAVLINK_MSG_ID_AUTOPILOT_VERSION)
            gcs.send(gcs.frame(request), vehicle.address)
            stamps = []
            parser = mavlink.MAVLink(None)
            while True:
                raw = await gcs.recv()
                stamps.append(signature_fields(raw)[1])
                if parser.decode(bytearray(raw)).get_type() == "COMMAND_ACK":
                    break
            assert stamps[-1] >= t0  # the old clock was about 1 s (100 000 units) behind
            assert all(b > a for a, b in zip(stamps, stamps[1:], strict=False))
            gcs.close()

    asyncio.run(asyncio.wait_for(main(), 20))


def test_forged_far_future_timestamp_on_the_gcs_stream_locks_nobody_out():
    """Failure 4a: pymavlink stored the timestamp before checking the signature. An attacker who
    can spoof the GCS's source address sends one forged frame with timestamp 2^48 - 1."""

    async def main():
        async with MockFleet(count=1, signing_key=KEY) as fleet:
            vehicle = fleet.vehicle(1)
            gcs = Peer(255, 190, KEY)
            gcs.send(gcs.frame(_heartbeat()), vehicle.address)
            await gcs.recv()
            gcs.send(_forged(255, 190, 2**48 - 1, _heartbeat()), vehicle.address)  # from the GCS's port
            gcs.send(gcs.frame(_command(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 0.0)), vehicle.address)
            ack = await _ack(gcs, mavlink.MAV_CMD_COMPONENT_ARM_DISARM)
            assert ack.result == mavlink.MAV_RESULT_ACCEPTED
            assert vehicle.link.signing.verifier.forged == 1
            assert max(vehicle.link.signing.verifier.streams.values()) < 2**47
            gcs.close()

    asyncio.run(asyncio.wait_for(main(), 20))


def test_junk_from_many_ports_does_not_evict_the_gcs_from_the_peer_table():
    """Failure 5: the peer was added before its frame was decoded (and verified)."""

    async def main():
        for key in (None, KEY):
            async with MockFleet(count=1, signing_key=key) as fleet:
                vehicle = fleet.vehicle(1)
                gcs = Peer(255, 190, key)
                gcs.send(gcs.frame(_heartbeat()), vehicle.address)
                await gcs.recv()
                attackers = [Peer(66, 1) for _ in range(20)]
                for k, attacker in enumerate(attackers):
                    bogus = b"\x00garbage" if k % 2 else _forged(66, 1, signing_timestamp(), _heartbeat())
                    attacker.send(bogus if key else b"\x00garbage", vehicle.address)
                link = vehicle.link
                await _until(lambda: link.rejected >= 20)  # noqa: B023 - awaited in this iteration
                assert link.peers == [gcs.address]
                for peer in (gcs, *attackers):
                    peer.close()

    asyncio.run(asyncio.wait_for(main(), 20))


def test_junk_datagrams_between_valid_ones_cost_nothing_at_the_mock():
    """Failure 6: partial bytes were carried from one datagram into the next (0 of 40 got through)."""

    async def main():
        async with MockFleet(count=1) as fleet:
            vehicle = fleet.vehicle(1)
            gcs = Peer(255, 190)
            request = _command(mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, mavlink.MAVLINK_MSG_ID_ATTITUDE)
            for _ in range(40):
                gcs.send(JUNK, vehicle.address)
                gcs.send(gcs.frame(request), vehicle.address)
            acks = 0
            parser = mavlink.MAVLink(None)
            while acks < 40:
                msg = parser.decode(bytearray(await gcs.recv()))
                acks += msg.get_type() == "COMMAND_ACK"
            assert vehicle.link.rejected == 40
            gcs.close()

    asyncio.run(asyncio.wait_for(main(), 20))


def test_unsigned_mock_with_sysid_enforce_ignores_a_strangers_setup_signing():
    """Failure 4b: ArduPilot takes SETUP_SIGNING from anyone while signing is off; its defence is
    MAV_OPTIONS bit 0 (SYSID_ENFORCE before 4.7), which the mock has (default off, as ArduPilot)."""

    async def main():
        async with MockFleet(count=1) as fleet:
            vehicle = fleet.vehicle(1)
            operator, stranger = Peer(255, 190), Peer(66, 190)
            real32 = mavlink.MAV_PARAM_TYPE_REAL32
            param = mavlink.MAVLink_param_set_message(1, 1, b"MAV_OPTIONS", 1.0, real32)
            operator.send(operator.frame(param), vehicle.address)
            await _until(lambda: vehicle.params["MAV_OPTIONS"] == 1.0)
            stolen = key_from_passphrase("stranger")
            stranger.send(stranger.frame(setup_signing_message(stolen, 1)), vehicle.address)
            await _until(lambda: vehicle.link.peers[-1] == stranger.address)  # it decoded ...
            assert vehicle.link.signing_key is None  # ... and was ignored
            operator.send(operator.frame(setup_signing_message(KEY, 1)), vehicle.address)
            await _until(lambda: vehicle.link.signing_key == KEY)
            operator.close()
            stranger.close()

    asyncio.run(asyncio.wait_for(main(), 20))


# ----------------------------------------------------------------- the GCS link under attack
def test_gcs_refuses_a_replayed_vehicle_frame_and_a_forged_future_one():
    """Failures 2 and 4a on the GCS: one replay table for all addresses; signature checked first."""

    async def main():
        vehicle, attacker = Peer(1, 1, KEY), Peer(1, 1)
        link = await MavlinkLink.open(f"udpout:{vehicle.address[0]}:{vehicle.address[1]}", signing_key=KEY)
        heard: list[bytes] = []
        link.subscribe(lambda msg, raw, t: heard.append(raw))
        beat = mavlink.MAVLink_heartbeat_message(2, 3, 0, 0, 4, 3)
        gcs = await vehicle.recv()  # the GCS's heartbeat: its address
        gcs_addr = ("127.0.0.1", link.local_address[1])
        first = vehicle.frame(beat)
        vehicle.send(first, gcs_addr)
        await _until(lambda: len(heard) == 1)
        attacker.send(first, gcs_addr)  # replayed from another port
        vehicle.send(_forged(1, 1, 2**48 - 1, beat), gcs_addr)  # forged, from the vehicle's port
        vehicle.send(vehicle.frame(beat), gcs_addr)
        await _until(lambda: len(heard) == 2)
        assert link.frames_dropped == 2 and heard[0] == first and heard[1] != first
        assert not link.duplicates() and list(link.vehicles) == [1]
        assert signature_fields(gcs)[0] == 0  # link id 0
        await link.close()
        vehicle.close()
        attacker.close()

    asyncio.run(asyncio.wait_for(main(), 20))


def test_gcs_timestamps_follow_the_clock():
    """Failure 3 on the GCS: a frame sent after t0 carries a timestamp >= t0."""

    async def main():
        vehicle = Peer(1, 1, KEY)
        link = await MavlinkLink.open(
            f"udpout:{vehicle.address[0]}:{vehicle.address[1]}", signing_key=KEY, heartbeat_period_s=0
        )
        await asyncio.sleep(1.0)
        t0 = signing_timestamp()
        link.send(_heartbeat())
        link.send(_heartbeat())
        first = signature_fields(await vehicle.recv())[1]
        second = signature_fields(await vehicle.recv())[1]
        assert t0 <= first < second
        await link.close()
        vehicle.close()

    asyncio.run(asyncio.wait_for(main(), 20))


def test_gcs_junk_datagrams_between_valid_ones_cost_nothing():
    """Failure 6 on the GCS side: 40 valid frames, each after a cut one, all delivered."""

    async def main():
        vehicle = Peer(1, 1)
        link = await MavlinkLink.open(f"udpout:{vehicle.address[0]}:{vehicle.address[1]}")
        heard: list[mavlink.MAVLink_message] = []
        link.subscribe(lambda msg, raw, t: heard.append(msg))
        await vehicle.recv()
        gcs_addr = ("127.0.0.1", link.local_address[1])
        for _ in range(40):
            vehicle.send(JUNK, gcs_addr)
            vehicle.send(vehicle.frame(mavlink.MAVLink_heartbeat_message(2, 3, 0, 0, 4, 3)), gcs_addr)
        await _until(lambda: len(heard) == 40)
        assert link.frames_dropped == 40
        await link.close()
        vehicle.close()

    asyncio.run(asyncio.wait_for(main(), 20))


# ----------------------------------------------------------------- NaN / inf command params
def test_nan_and_inf_command_params_get_a_command_ack_and_no_traceback(caplog):
    """Failure 12: int(NaN) / int(inf) in the handlers raised in the datagram callback (no ACK)."""
    m = mavlink
    commands = [m.MAV_CMD_COMPONENT_ARM_DISARM, m.MAV_CMD_DO_SET_MODE, m.MAV_CMD_MISSION_START,
                m.MAV_CMD_DO_SET_MISSION_CURRENT, m.MAV_CMD_NAV_TAKEOFF, m.MAV_CMD_DO_CHANGE_SPEED,
                m.MAV_CMD_PREFLIGHT_REBOOT_SHUTDOWN, m.MAV_CMD_REQUEST_MESSAGE,
                m.MAV_CMD_SET_MESSAGE_INTERVAL]  # fmt: skip

    async def main():
        async with MockFleet(count=1, profile="px4") as fleet:
            vehicle = fleet.vehicle(1)
            gcs = Peer(255, 190)
            sent = 0
            for command in commands:
                for bad in (math.nan, math.inf, -math.inf):
                    params = [0.0] * 7
                    params[0] = bad
                    gcs.send(gcs.frame(mavlink.MAVLink_command_long_message(1, 1, command, 0, *params)),
                             vehicle.address)  # fmt: skip
                    sent += 1
            results: dict[int, list[int]] = {}
            parser = mavlink.MAVLink(None)
            while sum(map(len, results.values())) < sent:
                msg = parser.decode(bytearray(await gcs.recv()))
                if msg.get_type() == "COMMAND_ACK":
                    results.setdefault(msg.command, []).append(msg.result)
            assert set(results) == set(commands)
            assert results[mavlink.MAV_CMD_COMPONENT_ARM_DISARM] == [mavlink.MAV_RESULT_DENIED] * 3
            assert results[mavlink.MAV_CMD_DO_CHANGE_SPEED] == [mavlink.MAV_RESULT_DENIED] * 3  # p1: type
            assert not vehicle.armed
            gcs.close()

    asyncio.run(asyncio.wait_for(main(), 20))
    assert "Traceback" not in caplog.text and not [r for r in caplog.records if r.exc_info]


def test_nan_hold_time_is_refused_like_ardupilot_and_the_mission_kept(mission_of):
    """AP_Mission::sanity_check_params: NaN in NAV_WAYPOINT param1 -> MISSION_ACK INVALID_PARAM1."""

    async def main():
        async with MockFleet(count=1, profile="ardupilot") as fleet:
            vehicle = fleet.vehicle(1)
            link = await MavlinkLink.open(f"udpout:{vehicle.address[0]}:{vehicle.address[1]}")
            await link.wait_for(lambda m: m.get_type() == "HEARTBEAT", 5)
            client = MissionClient(link, 1)
            await client.upload(mission_of(3))
            before = vehicle.mission_server.items()
            bad = mission_of(4)
            bad[2] = dataclasses.replace(bad[2], param1=math.nan)
            with pytest.raises(errors.MissionError) as caught:
                await client.upload(bad)
            assert refused(caught.value, MissionResult.INVALID_PARAM1)
            assert vehicle.mission_server.items() == before
            await link.close()

    asyncio.run(asyncio.wait_for(main(), 20))
