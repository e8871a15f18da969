"""Telemetry logging benchmark: MCAP FlightLogger vs pymavlink's plain .tlog writing.

    nice .venv/bin/python benchmarks/logging_throughput.py [--vehicles 100] [--seconds 60]
        [--live-seconds 10] [--zstd-level 3] [--repeat 3]

1. Throughput on one core (process CPU time, best of --repeat), same frames, same run: a
   synthetic flight of N vehicles streaming the mock autopilot's mix (GLOBAL_POSITION_INT +
   ATTITUDE at 10 Hz; HEARTBEAT, SYS_STATUS,
   BATTERY_STATUS, VFR_HUD, MISSION_CURRENT at 1 Hz; HOME_POSITION at 0.2 Hz), real pymavlink
   frames decoded as a receiving link would. The .tlog baseline is the statement mavutil runs per
   received message (``f.write(struct.pack('>Q', usec) + msg.get_msgbuf())``). The MCAP figure
   includes JSON encoding, LocationFix, zstd and closing the file.
2. Size: MCAP vs .tlog of the same frames; bytes per vehicle-hour.
3. Replay to Rerun: read_flight + log_flight_to_rerun into an .rrd, frames/s.
4. Live: sitl_mock.MockFleet (N vehicles) over real UDP into MavlinkLink (as `fly` runs it). The
   mock, as stock ArduPilot, streams only what it is asked for, so every vehicle is first asked for
   the synthetic flight's mix (``LIVE_STREAMS``, SET_MESSAGE_INTERVAL as `fly` asks); then for
   --live-seconds: frames the link delivered against the frames that mix promises (the
   benchmark measures what it says only when they are close), frames in the log (drops in the
   logger), MAVLink sequence gaps (drops before it), and MCAP vs .tlog size of the same frames.
"""

from __future__ import annotations

import argparse
import asyncio
import os
import struct
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

os.environ.setdefault("MAVLINK20", "1")
from pymavlink.dialects.v20 import ardupilotmega as mavlink  # noqa: E402

from gcs_planner.core.geo import Origin, enu_to_geodetic  # noqa: E402
from gcs_planner.telemetry import FlightLogger, read_flight  # noqa: E402

ORIGIN = Origin(47.397742, 8.545594, 488.0)
M = mavlink
LIVE_STREAMS: dict[int, float] = {  # the synthetic flight's mix: message id -> rate [Hz]
    M.MAVLINK_MSG_ID_GLOBAL_POSITION_INT: 10.0,
    M.MAVLINK_MSG_ID_ATTITUDE: 10.0,
    M.MAVLINK_MSG_ID_SYS_STATUS: 1.0,
    M.MAVLINK_MSG_ID_BATTERY_STATUS: 1.0,
    M.MAVLINK_MSG_ID_VFR_HUD: 1.0,
    M.MAVLINK_MSG_ID_MISSION_CURRENT: 1.0,
    M.MAVLINK_MSG_ID_HOME_POSITION: 0.2,
}
LIVE_HZ = sum(LIVE_STREAMS.values()) + 1.0  # + HEARTBEAT, always sent at 1 Hz


def synthetic_flight(vehicles: int, seconds: float, seed: int = 1) -> list[tuple[object, bytes, float]]:
    """(decoded msg, raw frame, t_s) in receive order; vehicles circle at 8-15 m/s."""
    rng = np.random.default_rng(seed)
    enc = [mavlink.MAVLink(None, srcSystem=s, srcComponent=1) for s in range(1, vehicles + 1)]
    parser = mavlink.MAVLink(None)
    t0 = 1.7e9
    radius = rng.uniform(50, 300, vehicles)
    speed = rng.uniform(8, 15, vehicles)
    centre = rng.uniform(-2000, 2000, (vehicles, 2))
    out: list[tuple[float, int, object]] = []
    for k in range(int(seconds * 10)):
        t = k / 10.0
        ang = speed * t / radius
        e = centre[:, 0] + radius * np.cos(ang) + rng.normal(0, 0.3, vehicles)
        n = centre[:, 1] + radius * np.sin(ang) + rng.normal(0, 0.3, vehicles)
        u = 40 + 5 * np.sin(0.1 * t) + rng.normal(0, 0.2, vehicles)
        lat, lon, alt = enu_to_geodetic(e, n, u, ORIGIN)
        ve, vn = -speed * np.sin(ang), speed * np.cos(ang)
        for i in range(vehicles):
            ts = t0 + t + i * 1e-3
            ms = int(t * 1000)
            yaw = float(np.arctan2(ve[i], vn[i]))
            out.append((ts, i, mavlink.MAVLink_global_position_int_message(
                ms, round(lat[i] * 1e7), round(lon[i] * 1e7), round(alt[i] * 1e3), round(u[i] * 1e3),
                int(vn[i] * 100), int(ve[i] * 100), 0, round(np.degrees(yaw) % 360 * 100))))  # fmt: skip
            out.append((ts + 1e-4, i, mavlink.MAVLink_attitude_message(
                ms, float(rng.normal(0, 0.05)), float(rng.normal(0, 0.05)), yaw, 0, 0, 0.01)))  # fmt: skip
            if k % 10 == i % 10:
                out += [
                    (ts + 2e-4, i, mavlink.MAVLink_heartbeat_message(2, 3, 217, 3, 4, 3)),
                    (
                        ts + 3e-4,
                        i,
                        mavlink.MAVLink_sys_status_message(1, 1, 1, 100, 15800, 1200, 80, 0, 0, 0, 0, 0, 0),
                    ),  # fmt: skip
                    (
                        ts + 4e-4,
                        i,
                        mavlink.MAVLink_battery_status_message(
                            0, 1, 2, 2500, [3950] * 4 + [65535] * 6, 1200, int(t * 5), -1, 80
                        ),
                    ),  # fmt: skip
                    (
                        ts + 5e-4,
                        i,
                        mavlink.MAVLink_vfr_hud_message(
                            float(speed[i]),
                            float(speed[i]),
                            int(np.degrees(yaw)) % 360,
                            45,
                            float(alt[i]),
                            0.0,
                        ),
                    ),
                    (ts + 6e-4, i, mavlink.MAVLink_mission_current_message(int(t // 20))),
                ]
            if k % 50 == i % 50:
                out.append((ts + 7e-4, i, mavlink.MAVLink_home_position_message(
                    round(ORIGIN.lat_deg * 1e7), round(ORIGIN.lon_deg * 1e7), round(ORIGIN.alt_m * 1e3),
                    0.0, 0.0, 0.0, [1.0, 0.0, 0.0, 0.0], 0.0, 0.0, 0.0)))  # fmt: skip
    out.sort(key=lambda r: r[0])
    frames = []
    for ts, i, msg in out:
        raw = bytes(msg.pack(enc[i]))
        enc[i].seq = (enc[i].seq + 1) % 256
        frames.append((parser.decode(bytearray(raw)), raw, ts))
    return frames


def bench_tlog(frames, path: Path) -> float:
    start = time.process_time()
    with open(path, "wb") as f:
        for msg, _raw, t_s in frames:  # what mavutil.mavfile.recv_msg does per message
            usec = int(t_s * 1.0e6) & ~3
            f.write(struct.pack(">Q", usec) + msg.get_msgbuf())
    return time.process_time() - start


def bench_mcap(frames, path: Path, zstd_level: int) -> float:
    start = time.process_time()
    with FlightLogger(path, ORIGIN, zstd_level=zstd_level) as logger:
        for msg, raw, t_s in frames:
            logger.on_frame(msg, raw, t_s)
    return time.process_time() - start


def bench_rerun(path: Path, rrd: Path) -> tuple[float, float, int]:
    from gcs_planner.telemetry.rerun_views import log_flight_to_rerun

    start = time.perf_counter()
    flight = read_flight(path)
    read_s = time.perf_counter() - start
    rec = log_flight_to_rerun(flight, rrd)
    rec.disconnect()
    return read_s, time.perf_counter() - start, len(flight.frames)


def bench_live(vehicles: int, seconds: float, path: Path) -> dict:
    """MockFleet -> MavlinkLink (one UDP socket, like `fly`) -> FlightLogger.on_frame for ``seconds``."""
    from gcs_planner.mavlink.link import MavlinkLink
    from gcs_planner.mavlink.preflight import request_streams
    from sitl_mock.fleet import MockFleet

    tlog = path.with_suffix(".tlog")
    received = 0
    refused: dict[int, list[str]] = {}

    async def record(addresses, logger: FlightLogger) -> None:
        nonlocal received, refused
        link = await MavlinkLink.open(*(f"udpout:{h}:{p}" for h, p in addresses))
        refused = await request_streams(link, list(range(1, vehicles + 1)), LIVE_STREAMS)
        await asyncio.sleep(1.0)  # every requested stream has sent once before the count starts

        def on_frame(msg, raw, t_s) -> None:
            nonlocal received
            received += 1
            logger.on_frame(msg, raw, t_s)

        unsubscribe = link.subscribe(on_frame)
        await asyncio.sleep(seconds)
        unsubscribe()
        await link.close()

    with (
        MockFleet(count=vehicles, speedup=1.0) as fleet,
        FlightLogger(path, ORIGIN, tlog_path=tlog) as logger,
    ):
        cpu0 = time.process_time()
        asyncio.run(record(fleet.addresses, logger))
        cpu_s = time.process_time() - cpu0
    flight = read_flight(path)
    loss = [float(np.mean(flight.link_loss(s)[1])) for s in flight.sysids]
    return {
        "expected": round(LIVE_HZ * vehicles * seconds),
        "refused": sum(len(v) for v in refused.values()),
        "received": received,
        "logged": len(flight.frames),
        "seq_loss_mean": float(np.mean(loss)) if loss else float("nan"),
        "rate": received / seconds,
        "cpu_s": cpu_s,
        "size_ratio": path.stat().st_size / tlog.stat().st_size,
        "bytes_per_vehicle_h": path.stat().st_size / (vehicles * seconds / 3600.0),
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--vehicles", type=int, default=100)
    ap.add_argument("--seconds", type=float, default=60.0, help="synthetic flight length [s]")
    ap.add_argument("--live-seconds", type=float, default=10.0, help="MockFleet run [s] (0: skip)")
    ap.add_argument("--zstd-level", type=int, default=3)
    ap.add_argument("--repeat", type=int, default=3, help="throughput: best of this many runs")
    args = ap.parse_args()
    tmp = Path(tempfile.mkdtemp(prefix="gcs-telemetry-bench-"))
    t = time.perf_counter()
    frames = synthetic_flight(args.vehicles, args.seconds)
    print(f"generated {len(frames)} frames ({args.vehicles} vehicles x {args.seconds:.0f} s) in "
          f"{time.perf_counter() - t:.1f} s", file=sys.stderr)  # fmt: skip
    tlog_cpu = min(bench_tlog(frames, tmp / "flight.tlog") for _ in range(args.repeat))
    mcap_cpu = min(bench_mcap(frames, tmp / "flight.mcap", args.zstd_level) for _ in range(args.repeat))
    tlog_size = (tmp / "flight.tlog").stat().st_size
    mcap_size = (tmp / "flight.mcap").stat().st_size
    vehicle_h = args.vehicles * args.seconds / 3600.0
    read_s, rrd_s, n = bench_rerun(tmp / "flight.mcap", tmp / "flight.rrd")
    rows = [
        ("frames", f"{len(frames)}", ""),
        (".tlog write (pymavlink statement) [msg/s, CPU]", f"{len(frames) / tlog_cpu:,.0f}", ""),
        ("MCAP FlightLogger [msg/s, CPU, incl. close]", f"{len(frames) / mcap_cpu:,.0f}", ">= 50,000"),
        (".tlog size [MB]", f"{tlog_size / 1e6:.2f}", ""),
        ("MCAP size [MB]", f"{mcap_size / 1e6:.2f}", ""),
        ("MCAP / .tlog size", f"{mcap_size / tlog_size:.2f}", "<= 1.5"),
        ("MCAP bytes per vehicle-hour [MB]", f"{mcap_size / vehicle_h / 1e6:.1f}", ""),
        (".tlog bytes per vehicle-hour [MB]", f"{tlog_size / vehicle_h / 1e6:.1f}", ""),
        ("read_flight [frames/s]", f"{n / read_s:,.0f}", ""),
        ("replay to .rrd incl. read [frames/s]", f"{n / rrd_s:,.0f}", ""),
        (".rrd size [MB]", f"{(tmp / 'flight.rrd').stat().st_size / 1e6:.2f}", ""),
    ]
    if args.live_seconds > 0:
        live = bench_live(args.vehicles, args.live_seconds, tmp / "live.mcap")
        if live:
            rows += [
                (
                    f"live: frames the requested mix promises ({LIVE_HZ:g} Hz per vehicle)",
                    f"{live['expected']}",
                    "",
                ),
                ("live: stream requests refused", f"{live['refused']}", "0"),
                (
                    f"live MockFleet {args.vehicles} vehicles -> MavlinkLink: frames",
                    f"{live['received']}",
                    "~ promised",
                ),
                ("live: received / promised", f"{live['received'] / live['expected']:.2f}", "~ 1"),
                ("live: frames in the MCAP log", f"{live['logged']}", "= received"),
                ("live: receive rate [frames/s]", f"{live['rate']:,.0f}", ""),
                ("live: MAVLink seq-gap loss (mean per vehicle)", f"{live['seq_loss_mean']:.4f}", ""),
                ("live: process CPU (mock + GCS + logger) [s]", f"{live['cpu_s']:.1f}", ""),
                ("live: MCAP / .tlog size (same frames)", f"{live['size_ratio']:.2f}", "<= 1.5"),
                ("live: MCAP bytes per vehicle-hour [MB]", f"{live['bytes_per_vehicle_h'] / 1e6:.1f}", ""),
            ]
    print("| metric | value | target |\n|---|---:|---|")
    for name, value, target in rows:
        print(f"| {name} | {value} | {target} |")
    print(f"\nfiles in {tmp}")


if __name__ == "__main__":
    main()
