"""Import a flight log into an MCAP flight log: .tlog, raw MAVLink, ArduPilot DataFlash, PX4 ULog.

    gcs-planner import-log FLIGHT.bin -o FLIGHT.mcap [--plan plan.json] [--scenario s.toml]

The format is told by the file's bytes, not its name (telemetry/log_import.py). The result has
the layout of a log recorded by `fly` (LocationFix per vehicle, JSON channels with schemas,
events; raw frames where the log has frames), so `replay` and Foxglove read it the same way.
`import-tlog` is the same command.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from gcs_planner.core.errors import UserError
from gcs_planner.core.geo import Origin
from gcs_planner.core.validation import MAX_ALT_M, MIN_ALT_M, number, output_file, read_text
from gcs_planner.missions.files import load_plan_json
from gcs_planner.planning import load_scenario
from gcs_planner.telemetry.log_import import import_log


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("log", help="flight log: .tlog, raw MAVLink capture, DataFlash .bin / .log, PX4 .ulg")
    p.add_argument("-o", "--output", help="MCAP file to write [LOG with .mcap]")
    p.add_argument("--plan", help="plan.json to attach (also sets the origin)")
    p.add_argument("--scenario", help="scenario .toml to attach")
    p.add_argument("--origin", help="LAT,LON,ALT_AMSL of the local frame (default: plan, else home)")


def run(args: argparse.Namespace) -> int:
    inputs = [args.log, args.plan, args.scenario]
    output = output_file(args.output or Path(args.log).with_suffix(".mcap"), "-o", inputs)
    plan = load_plan_json(args.plan) if args.plan else None
    scenario_text = None
    if args.scenario:  # attached as it is, but it must be a scenario
        scenario_text = read_text(args.scenario, "scenario")
        load_scenario(args.scenario)
    origin = parse_origin(args.origin) if args.origin else None
    result = import_log(args.log, output, origin=origin, plan=plan, scenario_text=scenario_text)
    records = f", {sum(result.records.values())} records" if result.records else ""
    print(f"wrote {output}: {result.format}{records}, {result.frames} MAVLink frames")
    return 0


def parse_origin(text: str) -> Origin:
    try:
        lat, lon, alt = (float(v) for v in text.split(","))
    except ValueError:
        raise UserError(f"--origin must be LAT,LON,ALT_AMSL, got {text!r}") from None
    return Origin(
        number(lat, "--origin latitude", -90.0, 90.0),
        number(lon, "--origin longitude", -180.0, 180.0),
        number(alt, "--origin altitude", MIN_ALT_M, MAX_ALT_M),
    )
