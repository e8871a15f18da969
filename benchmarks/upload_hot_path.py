"""Python CPU per item of the upload's hot path, without sockets: request frame in, item frame out.

A MavlinkLink with a fake transport hears one PX4 HEARTBEAT, a MissionClient starts an upload of
N items, and the script feeds the link the vehicle's N MISSION_REQUEST_INT frames and its
MISSION_ACK the way a UDP socket would (UdpProtocol.datagram_received), one frame a datagram.
It times only that (framing, the CRC and id checks, routing, the transfer's state machine,
framing the packed item; requests are taken undecoded, mission.py; no event loop, no system
calls), so the figure is the client's own Python per item, free of the mock and of the kernel.
Best of --runs uploads after three warm-ups.

    .venv/bin/python benchmarks/upload_hot_path.py [--items 500] [--runs 10]
"""

from __future__ import annotations

import argparse
import asyncio
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from pymavlink.dialects.v20 import ardupilotmega as mavlink  # noqa: E402
from upload_latency import items  # noqa: E402

from gcs_planner.mavlink.link import MavlinkLink  # noqa: E402
from gcs_planner.mavlink.mission import MissionClient  # noqa: E402
from gcs_planner.mavlink.transfer import Timing  # noqa: E402
from gcs_planner.mavlink.transports import UdpProtocol  # noqa: E402

VEHICLE = ("127.0.0.1", 14550)


class FakeTransport:
    """Swallows what the link sends."""

    def __init__(self) -> None:
        self.sent = 0

    def sendto(self, data: bytes, addr: tuple[str, int]) -> None:
        self.sent += 1

    def is_closing(self) -> bool:
        return False

    def close(self) -> None:
        pass


async def upload_cpu_s(protocol: UdpProtocol, client: MissionClient, frames: list[bytes], n: int) -> float:
    """CPU seconds to feed one upload's vehicle frames through the link."""
    task = asyncio.ensure_future(client.upload(items(n)))
    await asyncio.sleep(0)  # the upload sends MISSION_COUNT and subscribes
    c0 = time.process_time()
    for frame in frames:
        protocol.datagram_received(frame, VEHICLE)
    cpu = time.process_time() - c0
    await task
    return cpu


async def main(n: int, runs: int) -> None:
    vehicle = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    heartbeat = mavlink.MAVLink_heartbeat_message(2, 12, 0, 0, 3, 3).pack(vehicle)  # quadrotor, PX4
    frames = [mavlink.MAVLink_mission_request_int_message(255, 190, i, 0).pack(vehicle) for i in range(n)]
    frames.append(mavlink.MAVLink_mission_ack_message(255, 190, 0, 0).pack(vehicle))
    link = MavlinkLink()
    link._bind_clocks(asyncio.get_running_loop())
    transport = FakeTransport()
    link._add_endpoint(transport)
    link._udp = transport
    link.add_peer(VEHICLE)
    protocol = UdpProtocol(link._on_frames)
    protocol.transport = transport  # type: ignore[assignment]
    protocol.datagram_received(heartbeat, VEHICLE)
    client = MissionClient(link, 1, timing=Timing(verdict_s=0))
    for _ in range(3):
        await upload_cpu_s(protocol, client, frames, n)
    best = min([await upload_cpu_s(protocol, client, frames, n) for _ in range(runs)])
    print(f"upload hot path: {1e6 * best / n:.1f} us of Python CPU per item ({n} items, best of {runs})")


if __name__ == "__main__":
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--items", type=int, default=500)
    p.add_argument("--runs", type=int, default=10)
    args = p.parse_args()
    asyncio.run(main(args.items, args.runs))
