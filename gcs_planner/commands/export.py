"""Export plan.json as QGroundControl .plan or Mission Planner WPL files, one per vehicle.

Each vehicle's plan becomes the mission items that `upload` would send (see
gcs_planner.missions.items). With --scenario, the .plan files also carry the scenario's geofence
(bounds, obstacles) and rally points. Prints one table row per file written.
"""

from __future__ import annotations

import argparse

from gcs_planner.autopilots import Conventions, quirks_named
from gcs_planner.commands._mission_cli import print_losses
from gcs_planner.core.errors import UserError
from gcs_planner.core.validation import atomic_write, file_stem, not_an_input, output_dir, unique
from gcs_planner.missions.files import load_plan_json, plan_mission_file, save_mission_file, select_vehicles
from gcs_planner.missions.items import AUTOPILOTS, scenario_fence_items, scenario_rally_items
from gcs_planner.planning import load_scenario
from gcs_planner.safety.geofence import check_fence, overflown, vehicle_geofence

SUFFIX = {"qgc": ".plan", "wpl": ".waypoints"}


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("plan", help="plan.json written by `gcs-planner plan`")
    p.add_argument("--format", choices=sorted(SUFFIX), default="qgc", help="qgc (.plan JSON) or wpl [qgc]")
    p.add_argument("--vehicle", action="append", help="vehicle id to export (repeatable; default: all)")
    p.add_argument(
        "--autopilot", choices=AUTOPILOTS, default=Conventions.ARDUPILOT, help="item conventions [ardupilot]"
    )
    p.add_argument("--scenario", help="scenario file: add its fence and rally points (.plan only)")
    p.add_argument("-o", "--output-dir", default=".", help="directory for <vehicle><suffix> files [.]")


def run(args: argparse.Namespace) -> int:
    out_dir = output_dir(args.output_dir, "-o")
    plan = load_plan_json(args.plan)
    vehicles = select_vehicles(plan, args.vehicle)
    scenario = None
    if args.scenario:
        if args.format != "qgc":
            raise UserError("--scenario (fence and rally points) needs --format qgc; WPL holds one list")
        scenario = load_scenario(args.scenario)
    files = []  # every vehicle's file is built (and validated) before the first is written
    for vp in vehicles:
        mf = plan_mission_file(vp, plan.origin, args.autopilot)
        if scenario is not None:  # each vehicle's fence is what its own plan keeps out of
            check_fence(scenario, vp)
            mf.fence, mf.rally = scenario_fence_items(scenario, vp), scenario_rally_items(scenario, vp)
        stem = file_stem(vp.vehicle_id, "vehicle id")  # ../../x or /abs/x must not leave -o
        files.append((vp, mf, out_dir / f"{stem}{SUFFIX[args.format]}"))
    unique([path.name for _, _, path in files], "output file")
    for _, _, path in files:
        not_an_input(path, [args.plan, args.scenario], "output file")
    try:
        out_dir.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise UserError(f"-o {str(out_dir)!r}: cannot make the folder: {exc.strerror or exc}") from None
    print(f"{'vehicle':<10} {'sysid':>5} {'items':>6} {'fence':>6} {'rally':>6}  file")
    for vp, mf, path in files:
        with atomic_write(path) as tmp:
            losses = save_mission_file(tmp, mf)
        n = len(mf.items(args.autopilot))
        print(f"{vp.vehicle_id:<10} {vp.sysid:>5} {n:>6} {len(mf.fence):>6} {len(mf.rally):>6}  {path}")
        if scenario is not None and (over := overflown(scenario, vp)):
            print(
                f"  {vp.vehicle_id} flies over {', '.join(over)}: not in its fence (a MAVLink fence is 2-D)"
            )
        if scenario is not None and (ceiling := vehicle_geofence(scenario, vp).ceiling_m) is not None:
            param = quirks_named(args.autopilot, vp.vehicle_type == "fixed_wing").fence_alt_param
            print(f"  {vp.vehicle_id} fence ceiling {ceiling:g} m above home: not in the file, the parameter"
                  f" {param} (upload --scenario sets it)")  # fmt: skip
        print_losses(losses)
    return 0
