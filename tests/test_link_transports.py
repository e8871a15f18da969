"""One MavlinkLink over several endpoints (udpin x N, udpout, tcp) against the mock's transports
(udpin, udpclient, tcp), over real loopback sockets; frames the dialect does not know (PX4's
CURRENT_MODE); the autopilot component latched against a camera's HEARTBEAT."""

from __future__ import annotations

import asyncio
import os
import socket
import time

import pytest

os.environ.setdefault("MAVLINK20", "1")
from pymavlink.dialects.v20 import ardupilotmega as mavlink  # noqa: E402

from gcs_planner.flight.ops import wait_for_vehicles  # noqa: E402
from gcs_planner.mavlink.link import MavlinkLink, is_autopilot_heartbeat, parse_url  # noqa: E402
from gcs_planner.mavlink.mission import MissionClient  # noqa: E402
from gcs_planner.telemetry import FlightLogger, read_flight  # noqa: E402
from gcs_planner.wire.types import MissionItem  # noqa: E402
from sitl_mock.cli import build_parser  # noqa: E402
from sitl_mock.fleet import MockFleet  # noqa: E402
from sitl_mock.vehicle import DEFAULT_HOME, CurrentModeMessage  # noqa: E402

UNGATED = {"arm_ready_s": 0.0}
CURRENT_MODE = 436


def run(coro):
    return asyncio.run(asyncio.wait_for(coro, 60))


def mission(n: int) -> list[MissionItem]:
    return [
        MissionItem(
            seq=i, frame=3, command=16, current=int(i == 0), x=473_977_000 + 53 * i, y=85_455_000, z=20.0
        )
        for i in range(n)
    ]


async def until(predicate, timeout_s: float = 10.0) -> None:
    deadline = time.monotonic() + timeout_s
    while not predicate():
        if time.monotonic() > deadline:
            raise TimeoutError("condition not met")
        await asyncio.sleep(0.02)


def frame(msg, sysid: int, compid: int = 1) -> bytes:
    return msg.pack(mavlink.MAVLink(None, srcSystem=sysid, srcComponent=compid))


def heartbeat(mav_type: int, autopilot: int, base_mode: int = 0, custom_mode: int = 0):
    return mavlink.MAVLink_heartbeat_message(mav_type, autopilot, base_mode, custom_mode, 4, 3)


def test_one_link_over_two_udpin_a_udpout_and_tcp_routes_to_each_vehicle():
    """Vehicle 1 listens on UDP (udpout), 2 on TCP (tcp:), 3 sends to the first udpin port, 4 and 5
    share the second one: each is reached, its mission upload routed out of its own endpoint."""

    async def main():
        listening = [
            {"sysid": 1, "flight": UNGATED},
            {"sysid": 2, "transport": "tcp", "profile": "px4", "flight": UNGATED},
        ]
        async with MockFleet(vehicles=listening) as servers:
            (h1, p1), (h2, p2) = servers.addresses
            link = await MavlinkLink.open(
                "udpin:127.0.0.1:0", "udpin:127.0.0.1:0", f"udpout:{h1}:{p1}", f"tcp:{h2}:{p2}"
            )
            try:
                first, second = link.local_addresses[:2]
                assert link.local_address == first and first != second
                clients = [
                    {"sysid": 3, "transport": "udpclient", "gcs": first, "profile": "px4"},
                    {"sysid": 4, "transport": "udpclient", "gcs": second},
                    {"sysid": 5, "transport": "udpclient", "gcs": second, "profile": "px4"},
                ]
                async with MockFleet(vehicles=[{**c, "flight": UNGATED} for c in clients]) as senders:
                    await wait_for_vehicles(link, [1, 2, 3, 4, 5], 10.0)
                    assert sorted(link.vehicles) == [1, 2, 3, 4, 5] and not link.duplicates()
                    where = {s: link.vehicles[s].address for s in link.vehicles}
                    assert where[1] == (h1, p1)
                    assert where[2] == ("tcp:127.0.0.1", p2)
                    assert where[3][0] == "127.0.0.1"  # the first socket: plain addresses
                    assert where[4][0] == where[5][0] == f"udpin:{second[1]}<-127.0.0.1"
                    assert len(set(where.values())) == 5
                    for sysid in range(1, 6):
                        result = await MissionClient(link, sysid).upload(mission(3 + sysid))
                        assert result.count == 3 + sysid, (sysid, result)
                    for fleet, sysids in ((servers, (1, 2)), (senders, (3, 4, 5))):
                        for sysid in sysids:
                            assert fleet.vehicle(sysid).mission_server.count() == 3 + sysid, sysid
            finally:
                await link.close()

    run(main())


def _unknown_frames(link: MavlinkLink) -> list:
    seen = []
    link.subscribe(lambda msg, raw, t: seen.append(msg) if msg.get_type().startswith("UNKNOWN_") else None)
    return seen


def test_px4_vehicles_on_separate_ports_and_on_one_shared_port_give_no_vehicle_0():
    """Real PX4 streams CURRENT_MODE, which the pinned dialect lacks: it counts for its own vehicle."""

    async def main():
        px4 = {"profile": "px4", "flight": UNGATED}
        async with MockFleet(count=3, **px4) as fleet:
            link = await MavlinkLink.open(*(f"udpout:{h}:{p}" for h, p in fleet.addresses))
            unknown = _unknown_frames(link)
            try:
                await wait_for_vehicles(link, [1, 2, 3], 10.0)
                await until(lambda: {m.get_srcSystem() for m in unknown} == {1, 2, 3})
                assert sorted(link.vehicles) == [1, 2, 3] and not link.duplicates()
            finally:
                await link.close()
        link = await MavlinkLink.open("udpin:127.0.0.1:0")
        unknown = _unknown_frames(link)
        try:
            gcs = link.local_address
            async with MockFleet(count=3, transport="udpclient", gcs=gcs, **px4):
                await wait_for_vehicles(link, [1, 2, 3], 10.0)
                await until(lambda: {m.get_srcSystem() for m in unknown} == {1, 2, 3})
                assert sorted(link.vehicles) == [1, 2, 3] and not link.duplicates()
                assert {m.get_msgId() for m in unknown} == {CURRENT_MODE}
                assert {m.get_srcComponent() for m in unknown} == {1}
        finally:
            await link.close()

    run(main())


def test_unknown_msgid_is_delivered_with_the_header_ids_and_creates_no_vehicle(tmp_path):
    async def main():
        link = await MavlinkLink.open("udpin:127.0.0.1:0", heartbeat_period_s=0)
        got = []
        link.subscribe(lambda msg, raw, t: got.append((msg, raw, t)))
        sender = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            mode = CurrentModeMessage(6, 0x04040000, 0x04040000)
            sender.sendto(frame(mode, 42, 7), link.local_address)
            await until(lambda: len(got) == 1)
            msg, raw, _ = got[0]
            assert msg.get_type() == "UNKNOWN_436" and msg.get_msgId() == CURRENT_MODE
            assert (msg.get_srcSystem(), msg.get_srcComponent()) == (42, 7)
            assert not link.vehicles and link.frames_dropped == 0
            sender.sendto(frame(heartbeat(2, 12), 42, 1), link.local_address)  # PX4 quadrotor
            await until(lambda: 42 in link.vehicles)
            assert list(link.vehicles) == [42] and link.vehicles[42].compid == 1
            return got
        finally:
            sender.close()
            await link.close()

    got = asyncio.run(main())
    with FlightLogger(tmp_path / "u.mcap", DEFAULT_HOME) as logger:  # kept raw, no decoded channel
        for msg, raw, t_s in got:
            logger.on_frame(msg, raw, t_s)
    flight = read_flight(tmp_path / "u.mcap")
    assert flight.sysids == [42] and len(flight.frames) == 2


def test_a_camera_heartbeat_changes_neither_mode_nor_armed():
    armed = mavlink.MAV_MODE_FLAG_SAFETY_ARMED | mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
    apm = mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA
    camera = heartbeat(mavlink.MAV_TYPE_CAMERA, apm, 0, 0)
    assert not is_autopilot_heartbeat(camera)
    assert not is_autopilot_heartbeat(heartbeat(mavlink.MAV_TYPE_GCS, mavlink.MAV_AUTOPILOT_INVALID))
    assert is_autopilot_heartbeat(heartbeat(mavlink.MAV_TYPE_QUADROTOR, apm))

    async def main():
        link = await MavlinkLink.open("udpin:127.0.0.1:0", heartbeat_period_s=0)
        sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        count = [0]
        link.subscribe(lambda *_: count.__setitem__(0, count[0] + 1))

        async def send(msg, compid: int) -> None:
            sock.sendto(frame(msg, 5, compid), link.local_address)
            n = count[0]
            await until(lambda: count[0] > n)

        try:
            await send(camera, 100)  # a camera first: no vehicle yet
            assert not link.vehicles
            await send(heartbeat(mavlink.MAV_TYPE_QUADROTOR, apm, armed, 3), 1)  # AUTO, armed
            info = link.vehicles[5]
            assert (info.compid, info.custom_mode, info.armed, info.mav_type) == (1, 3, True, 2)
            await send(camera, 100)
            await send(heartbeat(mavlink.MAV_TYPE_GIMBAL, apm), 154)
            await send(heartbeat(mavlink.MAV_TYPE_HEXAROTOR, apm, 0, 6), 2)  # autopilot-like, not compid 1
            assert (info.compid, info.custom_mode, info.armed, info.mav_type) == (1, 3, True, 2)
            assert info.address == ("127.0.0.1", sock.getsockname()[1])
            # a vehicle whose autopilot is heard first on another component: compid 1 takes over
            sock.sendto(frame(heartbeat(2, apm, 0, 5), 6, 2), link.local_address)
            await until(lambda: 6 in link.vehicles)
            assert link.vehicles[6].compid == 2 and link.vehicles[6].custom_mode == 5
            await send(heartbeat(2, apm, armed, 4), 1)
            sock.sendto(frame(heartbeat(2, apm, armed, 4), 6, 1), link.local_address)
            await until(lambda: link.vehicles[6].compid == 1)
            assert link.vehicles[6].custom_mode == 4 and link.vehicles[6].armed
        finally:
            sock.close()
            await link.close()

    run(main())


def _closed_port(kind: int = socket.SOCK_STREAM) -> int:
    with socket.socket(socket.AF_INET, kind) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_tcp_to_a_closed_port_is_a_one_line_error_and_closes_the_other_endpoints():
    assert parse_url("tcp:127.0.0.1:5760") == ("tcp", ("127.0.0.1", 5760))
    assert parse_url("tcpout:localhost:5762") == ("tcp", ("localhost", 5762))
    with pytest.raises(ValueError, match="not supported"):
        parse_url("tcpin:127.0.0.1:5760")
    port, udp = _closed_port(), _closed_port(socket.SOCK_DGRAM)

    async def main():
        url = f"tcp:127.0.0.1:{port}"
        with pytest.raises(ConnectionError) as caught:
            await MavlinkLink.open(f"udpin:127.0.0.1:{udp}", url)
        text = str(caught.value)
        assert url in text and "refused" in text and "\n" not in text
        await asyncio.sleep(0.05)  # asyncio closes a socket on the next loop turn
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as again:  # the udpin socket was closed
            again.bind(("127.0.0.1", udp))

    run(main())


def test_mock_tcp_vehicle_serves_one_connection_the_link_reconnects_and_the_cli_flags():
    async def main():
        async with MockFleet(vehicles=[{"transport": "tcp", "flight": UNGATED}]) as fleet:
            host, port = fleet.addresses[0]
            link = await MavlinkLink.open(f"tcp:{host}:{port}")
            try:
                await wait_for_vehicles(link, [1], 5.0)
                reader, writer = await asyncio.open_connection(host, port)  # a second GCS: closed
                assert await asyncio.wait_for(reader.read(), 5.0) == b""
                writer.close()
                n = link.frames_received
                await until(lambda: link.frames_received > n)  # the first one is still served
                vehicle = fleet.vehicle(1)
                served = vehicle.link._conn
                fleet.reboot(1)  # drops the connection, as a SITL restart does: the link reconnects
                await until(lambda: vehicle.link._conn not in (None, served), 5.0)
                n = link.frames_received
                await until(lambda: link.frames_received > n)
            finally:
                await link.close()

    run(main())
    args = build_parser().parse_args(["--tcp", "--base-port", "5760"])
    assert args.tcp and args.out is None
    assert build_parser().parse_args(["--out", "127.0.0.1:14550"]).out == ("127.0.0.1", 14550)
    with pytest.raises(SystemExit):
        build_parser().parse_args(["--tcp", "--out", "127.0.0.1:14550"])
    with pytest.raises(ValueError, match="udpclient vehicle needs gcs"):
        MockFleet(count=1, transport="udpclient")
