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
from gcs_planner.scenario import load_scenario
from gcs_planner.telemetry.tlog import import_tlog
from gcs_planner.validation import (
    MAX_ALT_M,
    MIN_ALT_M,
    InputError,
    atomic_write,
    number,
    output_file,
    read_text,
)


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("tlog", help="telemetry log (.tlog: 8-byte big-endian us timestamp + frame)")
    p.add_argument("-o", "--output", help="MCAP file to write [TLOG with .mcap]")
    p.add_argument("--plan", help="plan.json to attach (also sets the origin)")
    p.add_argument("--scenario", help="scenario .toml to attach")
    p.add_argument("--origin", help="LAT,LON,ALT_AMSL of the local frame (default: plan, else home)")


def run(args: argparse.Namespace) -> int:
    if not Path(args.tlog).is_file():
        raise UserError(f"tlog {args.tlog!r}: no such file")
    output = output_file(args.output or Path(args.tlog).with_suffix(".mcap"), "-o")
    if output.resolve() == Path(args.tlog).resolve():
        raise InputError(f"-o {str(output)!r} is the tlog itself")
    plan = Plan.load(args.plan) if args.plan else None
    scenario_text = None
    if args.scenario:  # attached as it is, but it must be a scenario
        scenario_text = read_text(args.scenario, "scenario")
        load_scenario(args.scenario)
    origin = _parse_origin(args.origin) if args.origin else None
    with atomic_write(output) as tmp:  # no .mcap at all unless the import succeeds
        count = import_tlog(args.tlog, tmp, origin=origin, plan=plan, scenario_text=scenario_text)
        if count == 0:
            raise UserError(f"tlog {args.tlog!r}: no valid MAVLink frames found")
    print(f"wrote {output}: {count} frames")
    return 0


def _parse_origin(text: str) -> Origin:
    try:
        lat, lon, alt = (float(v) for v in text.split(","))
    except ValueError:
        raise UserError(f"--origin must be LAT,LON,ALT_AMSL, got {text!r}") from None
    return Origin(
        number(lat, "--origin latitude", -90.0, 90.0),
        number(lon, "--origin longitude", -180.0, 180.0),
        number(alt, "--origin altitude", MIN_ALT_M, MAX_ALT_M),
    )
