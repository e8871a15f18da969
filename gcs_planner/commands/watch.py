"""Watch vehicles the tool did not start: log their telemetry to MCAP, optionally with live views.

    gcs-planner watch --connect udpin:0.0.0.0:14550 [-o OUT] [--live | --serve-web] [--duration S]

Asks the first vehicle heard for its telemetry streams (SET_MESSAGE_INTERVAL; ArduPilot sends
what it is asked for), then writes OUT/watch.mcap (the layout of a `fly` log) and, at the end,
OUT/watch.rrd; stops at Ctrl-C, after --duration seconds, or after --count position reports.
The local frame's origin is --origin, else the first vehicle's home (its first
GLOBAL_POSITION_INT at alt - relative_alt).
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import time
from pathlib import Path

from gcs_planner.commands._mission_cli import open_link
from gcs_planner.commands._viewer import check_display, live_recording
from gcs_planner.commands.import_log import parse_origin
from gcs_planner.core.errors import UserError
from gcs_planner.core.geo import Origin
from gcs_planner.mavlink.link import is_autopilot_heartbeat
from gcs_planner.mavlink.preflight import request_streams
from gcs_planner.wire.units import reports_no_fix

FIRST_POSITION_TIMEOUT_S = 30.0


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--connect",
        required=True,
        action="append",
        metavar="URL",
        help="MAVLink endpoint: udpin:HOST:PORT, udpout:HOST:PORT, tcp:HOST:PORT or serial:DEV:BAUD"
        " (repeatable, any mix)",
    )
    p.add_argument("-o", "--out", default="out/watch", help="output folder [out/watch]")
    p.add_argument("--origin", help="LAT,LON,ALT_AMSL of the local frame [the first vehicle's home]")
    p.add_argument("--duration", type=float, default=None, metavar="S", help="stop after S seconds")
    p.add_argument("--count", type=int, default=None, metavar="N", help="stop after N position reports")
    p.add_argument(
        "--live", action="store_true", help="show the Rerun views while watching (spawns a viewer)"
    )
    p.add_argument("--serve-web", action="store_true", help="stream the views to Rerun's web viewer")
    p.add_argument("--signing-passphrase", metavar="TEXT", default=None, help="MAVLink 2 signing passphrase")


def run(args: argparse.Namespace) -> int:
    for name in ("duration", "count"):
        value = getattr(args, name)
        if value is not None and not value > 0:
            raise UserError(f"--{name} must be > 0, got {value}")
    if args.live:
        check_display("--live")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    rec = live_recording(args.live, args.serve_web)
    origin = parse_origin(args.origin) if args.origin else None
    with contextlib.suppress(KeyboardInterrupt):
        positions = asyncio.run(_watch(args, out / "watch.mcap", origin, rec))
        print(f"watched: {positions} position reports")
    from gcs_planner.telemetry import log_flight_to_rerun, read_flight

    flight = read_flight(out / "watch.mcap")
    log_flight_to_rerun(flight, out / "watch.rrd")
    print(f"log: {out / 'watch.mcap'} ({len(flight.frames)} frames from vehicles {flight.sysids})")
    print(f"rerun: {out / 'watch.rrd'}  (open with `rerun {out / 'watch.rrd'}`)")
    return 0


async def _watch(args: argparse.Namespace, mcap_path: Path, origin: Origin | None, rec) -> int:
    from gcs_planner.telemetry import FlightLogger
    from gcs_planner.telemetry.rerun_views import LiveRerunLogger

    link = await open_link(args)
    streams: asyncio.Task | None = None
    try:
        heartbeat = await link.wait_for(is_autopilot_heartbeat, FIRST_POSITION_TIMEOUT_S)
        # ArduPilot streams what it is asked for. Asked beside the logging, not before it: a vehicle
        # that never ACKs costs 6 s a message, and `--duration 3` once ran 49 s and logged the last 3
        streams = asyncio.create_task(request_streams(link, [heartbeat.get_srcSystem()]))
        first = await link.wait_for(
            lambda m: m.get_type() == "GLOBAL_POSITION_INT" and not reports_no_fix(m),
            FIRST_POSITION_TIMEOUT_S,
        )
    except TimeoutError:
        if streams is not None:
            streams.cancel()
        await link.close()
        raise UserError(
            f"no vehicle heartbeat or position report on {' '.join(args.connect)}"
            f" within {FIRST_POSITION_TIMEOUT_S:g} s"
        ) from None
    if origin is None:
        origin = Origin(first.lat * 1e-7, first.lon * 1e-7, (first.alt - first.relative_alt) * 1e-3)
    done = asyncio.Event()
    seen = [0]

    def count(msg, raw: bytes, t_s: float) -> None:
        if msg.get_type() == "GLOBAL_POSITION_INT":
            seen[0] += 1
            if args.count is not None and seen[0] >= args.count:
                done.set()

    try:
        with FlightLogger(mcap_path, origin) as logger:
            link.subscribe(logger.on_frame)
            link.subscribe(count)
            if rec is not None:
                live = LiveRerunLogger(rec, origin, time.time())
                live.start()
                link.subscribe(live.on_frame)
            with contextlib.suppress(TimeoutError):
                await asyncio.wait_for(done.wait(), args.duration)
    finally:
        streams.cancel()
        await link.close()
    return seen[0]
