"""The lean upload path (issue 36): what the link sends while it dispatches one datagram leaves in
one datagram per address, frames in order, split at MAX_DATAGRAM_BYTES; a vehicle that asks for
several items in one datagram gets them in one, and pymavlink reads them back one by one."""

from __future__ import annotations

import asyncio
import os
import socket

os.environ.setdefault("MAVLINK20", "1")
from pymavlink.dialects.v20 import ardupilotmega as mavlink  # noqa: E402

from gcs_planner.mavlink.link import MAX_DATAGRAM_BYTES, MavlinkLink  # noqa: E402
from gcs_planner.mavlink.mission import MissionClient  # noqa: E402
from gcs_planner.mavlink.transfer import Timing  # noqa: E402
from gcs_planner.wire.types import MissionItem  # noqa: E402

PX4_QUAD = mavlink.MAVLink_heartbeat_message(2, 12, 0, 0, 3, 3)


def mission(n: int) -> list[MissionItem]:
    return [
        MissionItem(seq=i, frame=3, command=16, x=473_977_000 + 53 * i, y=85_455_000, z=20.0)
        for i in range(n)
    ]


def messages(datagram: bytes) -> list[mavlink.MAVLink_message]:
    """Every frame of one datagram, as pymavlink parses it (a byte stream)."""
    parser = mavlink.MAVLink(None)
    return parser.parse_buffer(datagram) or []


class Recorder:
    """A transport that keeps each datagram."""

    def __init__(self) -> None:
        self.datagrams: list[tuple[bytes, tuple]] = []

    def sendto(self, data: bytes, addr: tuple) -> None:
        self.datagrams.append((data, addr))


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


def test_requests_in_one_datagram_are_answered_with_the_items_in_one_datagram():
    """A PX4-like peer on a raw socket: the first request gets the window (2 items) in one
    datagram; two requests in one datagram get the two next items in one datagram, in order."""

    async def main():
        loop = asyncio.get_running_loop()
        link = await MavlinkLink.open("udpin:127.0.0.1:0", heartbeat_period_s=0)
        vehicle = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        vehicle.bind(("127.0.0.1", 0))
        vehicle.setblocking(False)
        mav = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)

        def send(*msgs) -> None:
            vehicle.sendto(b"".join(m.pack(mav) for m in msgs), link.local_address)

        async def receive() -> list:
            data, _ = await asyncio.wait_for(loop.sock_recvfrom(vehicle, 2048), 5)
            return messages(data)

        def request(seq: int):
            return mavlink.MAVLink_mission_request_int_message(255, 190, seq, 0)

        try:
            send(PX4_QUAD)
            while 1 not in link.vehicles:
                await asyncio.sleep(0.01)
            items = mission(4)
            upload = asyncio.ensure_future(
                MissionClient(link, 1, timing=Timing(window=2, verdict_s=0)).upload(items)
            )
            (count,) = await receive()
            assert count.get_type() == "MISSION_COUNT" and count.count == 4
            send(request(0))
            got = await receive()
            assert [(m.get_type(), m.seq) for m in got] == [("MISSION_ITEM_INT", 0), ("MISSION_ITEM_INT", 1)]
            send(request(1), request(2))
            got = await receive()
            assert [m.seq for m in got] == [2, 3]
            assert [(m.x, m.z) for m in got] == [(items[k].x, items[k].z) for k in (2, 3)]
            send(request(3), mavlink.MAVLink_mission_ack_message(255, 190, 0, 0))
            result = await asyncio.wait_for(upload, 5)
            assert result.count == 4 and link.frames_sent == 5
        finally:
            vehicle.close()
            await link.close()

    asyncio.run(main())
