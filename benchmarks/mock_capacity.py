"""How many mock vehicles one process sustains at 10 Hz position telemetry in real time.

The fleet runs in a child process pinned to one CPU core (speed-up 1, half multirotors, half fixed
wings, all armed and flying after a MAVLink takeoff command, so physics, navigation and telemetry
all run). The parent is the GCS: one UDP socket that greets every vehicle, then counts
GLOBAL_POSITION_INT frames per system id from the raw MAVLink 2 headers of every frame in a
datagram (no full decode, so the GCS side is not the bottleneck). The mock, as stock ArduPilot,
streams only on request: the GCS asks every vehicle for all its streams (REQUEST_DATA_STREAM,
MAVProxy's way) before it arms them. Achieved rate per vehicle = frames / window. On a shared machine
the fleet may get less than its core; the last column (vehicles x achieved/target rate / CPU share
used) estimates what one whole core carries, independent of that.

    nice .venv/bin/python benchmarks/mock_capacity.py --counts 50 100 200 300 --window 5
"""

from __future__ import annotations

import argparse
import multiprocessing as mp
import os
import socket
import time

import numpy as np

os.environ.setdefault("MAVLINK20", "1")
from pymavlink.dialects.v20 import ardupilotmega as mavlink  # noqa: E402

GPI_ID = mavlink.MAVLINK_MSG_ID_GLOBAL_POSITION_INT


def _child(count: int, rate_hz: float, conn, core: int | None) -> None:
    """Run a fleet until told to stop; report addresses, then CPU time and lag."""
    if core is not None and hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {core})
    from sitl_mock.fleet import MockFleet

    types = ["multirotor" if k % 2 else "fixed_wing" for k in range(count)]
    fleet = MockFleet(vehicles=[{"vehicle_type": t} for t in types], rate_hz=rate_hz)
    with fleet:
        conn.send(fleet.addresses)
        conn.recv()  # start of the measured window
        cpu0, ticks0, lag0 = time.process_time(), fleet.ticks, fleet.lag_events
        conn.recv()  # end of the window
        conn.send((time.process_time() - cpu0, fleet.ticks - ticks0, fleet.lag_events - lag0))


def _greet_and_fly(sock: socket.socket, addresses: list[tuple[str, int]]) -> None:
    mav = mavlink.MAVLink(None, srcSystem=255, srcComponent=190)
    hb = mav.heartbeat_encode(mavlink.MAV_TYPE_GCS, mavlink.MAV_AUTOPILOT_INVALID, 0, 0, 0)
    for sysid, addr in enumerate(addresses, 1):
        sock.sendto(hb.pack(mav), addr)
        streams = mav.request_data_stream_encode(sysid, 1, mavlink.MAV_DATA_STREAM_ALL, 10, 1)
        sock.sendto(streams.pack(mav), addr)
    time.sleep(0.3)
    for sysid, addr in enumerate(addresses, 1):
        arm = mav.command_long_encode(sysid, 1, mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0, 0, 0)
        sock.sendto(arm.pack(mav), addr)
    time.sleep(0.3)
    for sysid, addr in enumerate(addresses, 1):
        takeoff = mav.command_long_encode(sysid, 1, mavlink.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, 0, 0, 0, 30)
        sock.sendto(takeoff.pack(mav), addr)


def _count(sock: socket.socket, seconds: float, n: int) -> tuple[np.ndarray, int]:
    """GLOBAL_POSITION_INT frames per sysid (index sysid-1) and all frames, over ``seconds``."""
    gpi = np.zeros(n + 1, dtype=int)
    total = 0
    deadline = time.monotonic() + seconds
    sock.settimeout(0.05)
    while time.monotonic() < deadline:
        try:
            data = sock.recv(512)
        except TimeoutError:
            continue
        for sysid, msg_id in _headers(data):
            total += 1
            if msg_id == GPI_ID and sysid <= n:
                gpi[sysid] += 1
    return gpi[1:], total


def _headers(data: bytes) -> list[tuple[int, int]]:
    """(sysid, message id) of every MAVLink 2 frame in a datagram (a vehicle batches a tick's frames)."""
    out, i = [], 0
    while i + 12 <= len(data) and data[i] == 0xFD:
        out.append((data[i + 5], int.from_bytes(data[i + 7 : i + 10], "little")))
        i += 12 + data[i + 1] + (13 if data[i + 2] & 1 else 0)
    return out


def measure(count: int, rate_hz: float, window_s: float, warmup_s: float, core: int | None) -> dict:
    parent, child = mp.Pipe()
    proc = mp.get_context("spawn").Process(target=_child, args=(count, rate_hz, child, core), daemon=True)
    proc.start()
    addresses = parent.recv()
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 8 << 20)
    sock.bind(("127.0.0.1", 0))
    _greet_and_fly(sock, addresses)
    _count(sock, warmup_s, count)
    parent.send("start")
    gpi, total = _count(sock, window_s, count)
    parent.send("stop")
    cpu_s, ticks, lag = parent.recv()
    proc.join(timeout=10)
    sock.close()
    rates = gpi / window_s
    return {
        "vehicles": count,
        "min_hz": rates.min(),
        "median_hz": float(np.median(rates)),
        "msgs_per_s": total / window_s,
        "cpu_pct": 100.0 * cpu_s / window_s,
        "tick_hz": ticks / window_s,
        "lag": lag,
        # vehicles one fully available core would carry at this rate: load-independent estimate
        "per_core": count * (float(np.median(rates)) / rate_hz) * 100.0 / max(100.0 * cpu_s / window_s, 1e-9),
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--counts", type=int, nargs="+", default=[50, 100, 200, 254])
    ap.add_argument("--rate", type=float, default=10.0, help="position telemetry rate per vehicle [Hz]")
    ap.add_argument("--window", type=float, default=5.0, help="measured window [s]")
    ap.add_argument("--warmup", type=float, default=2.0, help="flying before the window [s]")
    ap.add_argument("--core", type=int, default=0, help="CPU core to pin the fleet to (-1: no pinning)")
    args = ap.parse_args()
    core = None if args.core < 0 else args.core
    print("| vehicles | target Hz | min Hz | median Hz | msgs/s | mock CPU % | ticks/s | lag events"
          " | est. vehicles/core |")  # fmt: skip
    print("|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    for count in args.counts:
        r = measure(count, args.rate, args.window, args.warmup, core)
        print(f"| {r['vehicles']} | {args.rate:.1f} | {r['min_hz']:.2f} | {r['median_hz']:.2f} "
              f"| {r['msgs_per_s']:.0f} | {r['cpu_pct']:.0f} | {r['tick_hz']:.1f} "
              f"| {r['lag']} | {r['per_core']:.0f} |")  # fmt: skip


if __name__ == "__main__":
    main()
