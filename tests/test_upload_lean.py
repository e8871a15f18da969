"""The lean upload path (issue 36): what the link sends while it dispatches one datagram leaves in
one datagram per address, frames in order, split at MAX_DATAGRAM_BYTES; a vehicle that asks for
several items in one datagram gets them in one. Requests are taken undecoded (MavlinkLink.take)
and answered with payloads packed once: the frames are pymavlink's, byte for byte, signed ones
verify with pymavlink, and the transfer answers them as it answers the messages, with the same
checks (another mission type, target or source is ignored)."""

from __future__ import annotations

import asyncio
import os
import socket

import pytest

os.environ.setdefault("MAVLINK20", "1")
from pymavlink.dialects.v20 import ardupilotmega as mavlink  # noqa: E402

from gcs_planner.mavlink.link import MAX_DATAGRAM_BYTES, MavlinkLink, VehicleInfo  # noqa: E402
from gcs_planner.mavlink.mission import MissionClient  # noqa: E402
from gcs_planner.mavlink.networks import NetworkLinks  # noqa: E402
from gcs_planner.mavlink.transfer import Timing, UploadTransfer  # noqa: E402
from gcs_planner.mavlink.transports import UdpProtocol  # noqa: E402
from gcs_planner.wire import codec  # noqa: E402
from gcs_planner.wire.signing import LinkSigning  # noqa: E402
from gcs_planner.wire.types import MissionItem, MissionType  # noqa: E402

PX4_QUAD = mavlink.MAVLink_heartbeat_message(2, 12, 0, 0, 3, 3)


def mission(n: int) -> list[MissionItem]:
    return [
        MissionItem(seq=i, frame=3, command=16, x=473_977_000 + 53 * i, y=85_455_000, z=20.0)
        for i in range(n)
    ]


KEY = b"s" * 32


def messages(datagram: bytes, key: bytes | None = None) -> list[mavlink.MAVLink_message]:
    """Every frame of one datagram, as pymavlink parses it (a byte stream); with ``key`` each must
    carry a good signature (pymavlink raises on a bad one and counts the good ones)."""
    parser = mavlink.MAVLink(None)
    if key is not None:
        parser.signing.secret_key = key
    got = parser.parse_buffer(datagram) or []
    assert key is None or parser.signing.goodsig_count == len(got) > 0
    return got


class Recorder:
    """A transport that keeps each datagram."""

    def __init__(self) -> None:
        self.datagrams: list[tuple[bytes, tuple]] = []

    def sendto(self, data: bytes, addr: tuple) -> None:
        self.datagrams.append((data, addr))

    def is_closing(self) -> bool:
        return False


def test_uncork_keeps_each_address_in_order_and_splits_at_the_mtu():
    a, b = Recorder(), Recorder()
    frames = [bytes([0xFD, k]) * 100 for k in range(20)]  # 200 bytes each: 7 fit in 1400, 19 go to a
    held = (
        [(a, ("h", 1), f) for f in frames[:10]]
        + [(b, ("h", 2), frames[10])]
        + [(a, ("h", 1), f) for f in frames[11:]]
    )
    MavlinkLink._uncork(held)
    assert [d for d, _ in b.datagrams] == [frames[10]]
    sizes = [len(d) for d, _ in a.datagrams]
    assert sizes == [1400, 1400, 1000] and all(s <= MAX_DATAGRAM_BYTES for s in sizes)
    assert b"".join(d for d, _ in a.datagrams) == b"".join(frames[:10] + frames[11:])


@pytest.mark.parametrize("lost", [False, True])
@pytest.mark.parametrize("key", [None, KEY])
def test_requests_in_one_datagram_are_answered_with_the_items_in_one_datagram(key, lost):
    """A PX4-like peer on a raw socket: the first request gets the window (2 items) in one
    datagram; two requests in one datagram get the two next items in one datagram, in order; the
    frames are what pymavlink packs for the same items and sequence numbers (signed: they verify).
    ``lost``: the vehicle says nothing after the window, and the push (the window and one more)
    comes in one datagram too."""

    async def main():
        loop = asyncio.get_running_loop()
        link = await MavlinkLink.open("udpin:127.0.0.1:0", heartbeat_period_s=0, signing_key=key)
        vehicle = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        vehicle.bind(("127.0.0.1", 0))
        vehicle.setblocking(False)
        mav = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
        if key is not None:
            LinkSigning(mav, key)
            mav.signing.timestamp = link.signing.clock.current()

        def send(*msgs) -> None:
            vehicle.sendto(b"".join(m.pack(mav) for m in msgs), link.local_address)

        async def receive() -> list:
            data, _ = await asyncio.wait_for(loop.sock_recvfrom(vehicle, 2048), 5)
            got = messages(data, key)
            if key is None:  # the same bytes as pymavlink's pack of the same item and seq
                gcs = mavlink.MAVLink(None, srcSystem=255, srcComponent=190)
                for m in got:
                    gcs.seq = m.get_seq()
                    assert m.pack(gcs) == bytes(m.get_msgbuf())
                    if m.get_type() == "MISSION_ITEM_INT":
                        want = mavlink.MAVLink_mission_item_int_message(1, 1, *items[m.seq].fields())
                        assert want.pack(gcs) == bytes(m.get_msgbuf())
            return got

        def request(seq: int):
            return mavlink.MAVLink_mission_request_int_message(255, 190, seq, 0)

        try:
            send(PX4_QUAD)
            while 1 not in link.vehicles:
                await asyncio.sleep(0.01)
            upload = asyncio.ensure_future(
                MissionClient(link, 1, timing=Timing(window=2, verdict_s=0)).upload(items)
            )
            (count,) = await receive()
            assert count.get_type() == "MISSION_COUNT" and count.count == 4
            fence = mavlink.MAVLink_mission_request_int_message(255, 190, 3, MissionType.FENCE)
            other_gcs = mavlink.MAVLink_mission_request_int_message(254, 190, 3, 0)
            send(request(0), fence, other_gcs)  # not ours: answered, they would add item 3
            got = await receive()
            assert [(m.get_type(), m.seq) for m in got] == [("MISSION_ITEM_INT", 0), ("MISSION_ITEM_INT", 1)]
            if lost:
                assert [m.seq for m in await receive()] == [0, 1, 2]
                send(request(1), request(2))  # 1 and 2 are on their way: only 3 is new
                assert [m.seq for m in await receive()] == [3]
            else:
                send(request(1), request(2))
                got = await receive()
                assert [m.seq for m in got] == [2, 3]
                assert [(m.x, m.z) for m in got] == [(items[k].x, items[k].z) for k in (2, 3)]
            send(request(3), mavlink.MAVLink_mission_ack_message(255, 190, 0, 0))
            result = await asyncio.wait_for(upload, 5)
            assert result.count == 4 and link.frames_sent == (7 if lost else 5)
        finally:
            vehicle.close()
            await link.close()

    items = mission(4)
    asyncio.run(main())


@pytest.mark.parametrize("networks", [1, 2])
def test_a_window_wider_than_a_batch_leaves_in_datagrams_of_a_batch(networks):
    """Window 16, batch 8 (the defaults): the first request gets items 0-7 and 8-15 as two datagrams,
    so the vehicle can work on the second while the GCS answers the first; the eight requests of
    the first (one datagram) get 16-23 in one datagram. Also through NetworkLinks (fleet ids)."""

    async def main():
        loop = asyncio.get_running_loop()
        links = [await MavlinkLink.open("udpin:127.0.0.1:0", heartbeat_period_s=0) for _ in range(networks)]
        link = links[0] if networks == 1 else NetworkLinks(links)
        vehicle = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        vehicle.bind(("127.0.0.1", 0))
        vehicle.setblocking(False)
        mav = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
        to = links[-1].local_address

        def send(*msgs) -> None:
            vehicle.sendto(b"".join(m.pack(mav) for m in msgs), to)

        async def receive() -> list[int]:
            data, _ = await asyncio.wait_for(loop.sock_recvfrom(vehicle, 2048), 5)
            return [getattr(m, "seq", m.get_type()) for m in messages(data)]

        def request(seq: int):
            return mavlink.MAVLink_mission_request_int_message(255, 190, seq, 0)

        sysid = 1 if networks == 1 else 1 + 256 * (networks - 1)  # the fleet id on the last network
        upload = None
        try:
            send(PX4_QUAD)
            while sysid not in link.vehicles:
                await asyncio.sleep(0.01)
            assert (Timing().window, Timing().batch) == (16, 8)
            upload = asyncio.ensure_future(
                MissionClient(link, sysid, timing=Timing(verdict_s=0)).upload(items)
            )
            assert await receive() == ["MISSION_COUNT"]
            send(request(0))
            assert await receive() == list(range(8))
            assert await receive() == list(range(8, 16))
            send(*(request(k) for k in range(1, 9)))
            assert await receive() == list(range(16, 24))
            send(*(request(k) for k in range(9, 24)), mavlink.MAVLink_mission_ack_message(255, 190, 0, 0))
            assert (await asyncio.wait_for(upload, 5)).count == 24
        finally:
            if upload is not None:
                upload.cancel()
            vehicle.close()
            for one in links:
                await one.close()

    items = mission(24)
    asyncio.run(main())


def test_a_request_answered_from_its_fields_is_answered_as_the_message():
    """UploadTransfer.on_request (the raw path) and on_message: the same items for the same
    requests, the same state; a request for another mission type, to another GCS or from another
    component gets nothing on either path."""
    by_msg, by_fields = (UploadTransfer(1, mission(20), timing=Timing(window=4)) for _ in range(2))
    by_msg.start(0.0)
    by_fields.start(0.0)
    ignored = [
        (5, 255, 190, MissionType.FENCE, 1),
        (5, 254, 190, 0, 1),
        (5, 255, 191, 0, 1),
        (5, 255, 190, 0, 2),
    ]
    asks = [(0, 255, 190, 0, 1), (1, 0, 0, 0, 1), *ignored, (3, 255, 190, 0, 1), (3, 255, 190, 0, 1)]
    asks += [(k, 255, 190, 0, 1) for k in range(4, 20)]
    for t, (seq, system, component, mission_type, source) in enumerate(asks):
        now = 0.01 * t
        msg = mavlink.MAVLink_mission_request_int_message(system, component, seq, mission_type)
        msg._header.srcSystem, msg._header.srcComponent = 1, source
        sent = [m.seq for m in by_msg.on_message(msg, now)]
        assert by_fields.on_request(seq, (1, source), (system, component), mission_type, now) == sent
        assert (seq, system, component, mission_type, source) not in ignored or sent == []
    assert by_msg.stats == by_fields.stats and by_msg.phase == by_fields.phase
    assert by_msg.deadline_s == by_fields.deadline_s and by_msg.stats.sent["MISSION_ITEM_INT"] == 20


@pytest.mark.parametrize("key", [None, KEY])
def test_taken_frames_skip_their_owner_reach_the_other_subscribers_and_are_checked(key):
    """take(): the frame callback gets the request undecoded, the subscriber it replaces nothing,
    another subscriber the decoded message; a bad CRC or (signing) a bad signature is dropped."""
    link = MavlinkLink(signing_key=key)
    link.vehicles[1] = VehicleInfo(1, ("127.0.0.1", 14550))
    protocol = UdpProtocol(link._on_frames)
    protocol.transport = Recorder()  # type: ignore[assignment]
    taken, owned, other = [], [], []
    link.subscribe(lambda m, raw, t: owned.append(m), 1)
    owner = link._by_sysid[1][0]
    link.subscribe(lambda m, raw, t: other.append(m.seq), 1)
    release = link.take(1, [mavlink.MAVLINK_MSG_ID_MISSION_REQUEST_INT], lambda f, t: taken.append(f), owner)
    mav = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    if key is not None:
        LinkSigning(mav, key)
        mav.signing.timestamp = link.signing.clock.current()
    frame = mavlink.MAVLink_mission_request_int_message(255, 190, 3, 0).pack(mav)
    protocol.datagram_received(frame, ("127.0.0.1", 14550))
    assert (taken, owned, other) == ([frame], [], [3])
    bad = bytearray(mavlink.MAVLink_mission_request_int_message(255, 190, 4, 0).pack(mav))
    bad[-1] ^= 0xFF  # the last byte: the CRC's, or (signed) the signature's
    protocol.datagram_received(bytes(bad), ("127.0.0.1", 14550))
    assert (len(taken), other, link.frames_dropped) == (1, [3], 1)
    release()
    protocol.datagram_received(
        mavlink.MAVLink_mission_request_int_message(255, 190, 5, 0).pack(mav), ("127.0.0.1", 14550)
    )
    assert (len(taken), [m.seq for m in owned], other) == (1, [5], [3, 5])


def test_networks_take_and_send_payloads_in_fleet_ids():
    """NetworkLinks: a take on fleet id 257 (network 1, system 1) replaces its owner's subscription
    there, other subscribers get the message in fleet ids; send_payload goes out on network 1."""
    links = [MavlinkLink(), MavlinkLink()]
    fleet = NetworkLinks(links)
    vehicle = ("127.0.0.1", 14551)
    wire = Recorder()
    links[1]._add_endpoint(wire)
    links[1]._udp = wire
    links[1].add_peer(vehicle)
    links[1].vehicles[1] = VehicleInfo(1, vehicle)
    taken, owned, other = [], [], []

    def owner(msg, raw, t_s):
        owned.append(msg)

    fleet.subscribe(owner, 257)
    fleet.subscribe(lambda m, raw, t: other.append(m.get_srcSystem()), 257)
    fleet.take(257, [mavlink.MAVLINK_MSG_ID_MISSION_REQUEST_INT], lambda f, t: taken.append(f), owner)
    frame = mavlink.MAVLink_mission_request_int_message(255, 190, 0, 0).pack(
        mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    )
    links[1]._on_frames([frame], 0, vehicle, wire, vehicle)
    assert (taken, owned, other) == ([frame], [], [257])
    item = codec.packer(mavlink.MAVLink_mission_item_int_message)
    with fleet.corked():
        fleet.send_payload(257, item, item.pack(1, 1, *mission(1)[0].fields()))
    ((datagram, to),) = wire.datagrams
    (sent,) = messages(datagram)
    assert to == vehicle and (sent.get_type(), sent.target_system, sent.seq) == ("MISSION_ITEM_INT", 1, 0)
