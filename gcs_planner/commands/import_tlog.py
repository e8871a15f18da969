"""Convert a MAVProxy / Mission Planner / QGroundControl telemetry log (.tlog) to an MCAP flight log.

    gcs-planner import-tlog FLIGHT.tlog -o FLIGHT.mcap [--plan plan.json] [--scenario s.toml]

The result has the same layout as a log recorded by `fly` (raw frames, decoded JSON channels,
foxglove.LocationFix per vehicle), so `replay` and Foxglove read it the same way.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from gcs_planner.errors import UserError
from gcs_planner.geo import Origin
from gcs_planner.plan import Plan
from gcs_planner.telemetry.tlog import import_tlog


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("tlog", help="telemetry log (.tlog: 8-byte big-endian us timestamp + frame)")
    p.add_argument("-o", "--output", help="MCAP file to write [TLOG with .mcap]")
    p.add_argument("--plan", help="plan.json to attach (also sets the origin)")
    p.add_argument("--scenario", help="scenario .toml to attach")
    p.add_argument("--origin", help="LAT,LON,ALT_AMSL of the local frame (default: plan, else home)")


def run(args: argparse.Namespace) -> int:
    if not Path(args.tlog).is_file():
        raise UserError(f"tlog {args.tlog!r}: no such file")
    output = Path(args.output) if args.output else Path(args.tlog).with_suffix(".mcap")
    plan = Plan.load(args.plan) if args.plan else None
    scenario_text = Path(args.scenario).read_text() if args.scenario else None
    origin = _parse_origin(args.origin) if args.origin else None
    count = import_tlog(args.tlog, output, origin=origin, plan=plan, scenario_text=scenario_text)
    if count == 0:
        raise UserError(f"tlog {args.tlog!r}: no valid MAVLink frames found")
    print(f"wrote {output}: {count} frames")
    return 0


def _parse_origin(text: str) -> Origin:
    try:
        lat, lon, alt = (float(v) for v in text.split(","))
        return Origin(lat, lon, alt)
    except ValueError as exc:
        raise UserError(f"--origin must be LAT,LON,ALT_AMSL, got {text!r} ({exc})") from None
