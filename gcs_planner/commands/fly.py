"""Plan a scenario and fly it: upload to every vehicle, arm, start, record, check conformance.

Starts mock vehicles (sitl_mock) unless --connect names real ones or SITL. Writes
OUT/flight.mcap (open in Foxglove), OUT/flight.rrd (open with `rerun OUT/flight.rrd`),
OUT/report.png (the flight report: map, cross-track and separation over time) and
OUT/plan.json, and prints one conformance row per vehicle. Exits 1 when a vehicle fails its
mission or breaks a separation, obstacle or cross-track bound. A coalition scenario (planner
"coalition") is flown award by award instead, as `gcs-planner fly-coalition` does.
"""

from __future__ import annotations

import argparse
import math
import signal
import sys
from dataclasses import replace
from pathlib import Path

from tqdm import tqdm

from gcs_planner.autopilots import ARDUCOPTER, PX4, Conventions
from gcs_planner.commands import fly_coalition
from gcs_planner.commands._mission_cli import add_in_flight_argument
from gcs_planner.commands._viewer import check_display, live_recording
from gcs_planner.commands.fly_coalition import SPEEDUP
from gcs_planner.commands.plan import SEED
from gcs_planner.commands.progress import plan_with_progress, progress_bar, say_ignored_tables
from gcs_planner.core import lockstep
from gcs_planner.core.errors import UserError
from gcs_planner.core.validation import (
    MAX_DURATION_S,
    MAX_RADIUS_M,
    MAX_SPEED_MPS,
    InputError,
    number,
    number_flag,
    output_dir,
)
from gcs_planner.flight import FlyOptions, check_flight, check_networks, end_summary, fly, networks
from gcs_planner.flight.limits import faster_ramp, planned_vertical_mps, predicted_errors_s
from gcs_planner.flight.starts import format_homes, starts
from gcs_planner.flight.vehicles import ConnectedVehicles, mock_vehicles
from gcs_planner.geometry.scurve import WaypointNav
from gcs_planner.mavlink.transfer import Timing
from gcs_planner.model.plan import Plan
from gcs_planner.model.scenario import Scenario
from gcs_planner.planning import certify_plan, load_scenario, planner
from gcs_planner.safety.conformance import MAX_SCHEDULE_ERROR_S, format_report

WORKERS = number_flag(1, 255, whole=True)  # concurrent uploads: at most one per sysid
MOCK_LEGS = ("tuned", "scurve")  # how mock multirotors fly their waypoints (--mock-legs)


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("scenario", help="scenario file (missions/*.toml)")
    p.add_argument("--plan", help="fly this plan.json instead of planning the scenario")
    p.add_argument("-o", "--out", default="out", help="output folder [out]")
    p.add_argument(
        "--connect",
        action="append",
        default=[],
        metavar="URL",
        help="real vehicles / SITL (udpout:HOST:PORT, udpin:HOST:PORT, tcp:HOST:PORT or serial:DEV:BAUD;"
        " repeatable, any mix; for a plan over"
        " several networks, one per network in order)",
    )
    p.add_argument(
        "--speedup",
        type=SPEEDUP,
        default=None,
        help="mock vehicles paced at this rate of the wall clock [none: in lockstep with this tool, as"
        " fast as the CPU allows]; with --connect, the rate the connected vehicles' clocks run at"
        " [1: real vehicles; a SITL's or sitl-mock's --speedup]",
    )
    p.add_argument("--autopilot", choices=tuple(Conventions), default=Conventions.ARDUPILOT)
    p.add_argument("--workers", type=WORKERS, default=8, help="concurrent uploads [8]")
    add_in_flight_argument(p)
    p.add_argument("--seed", type=SEED, default=None, help="planner seed (default: the file's)")
    p.add_argument(
        "--tlog", action="store_true", help="also write OUT/flight.tlog (flight.netN.tlog for network N > 0)"
    )
    p.add_argument(
        "--homes", action="store_true", help="print each vehicle's start for SITL (--home) and exit"
    )
    p.add_argument("--no-rrd", action="store_true", help="skip the Rerun .rrd")
    p.add_argument("--live", action="store_true", help="show the Rerun views while flying (spawns a viewer)")
    p.add_argument(
        "--serve-web",
        action="store_true",
        help="stream the Rerun views while flying to Rerun's web viewer (prints the URL to open)",
    )
    p.add_argument(
        "--max-cross-track",
        type=number_flag(0, MAX_RADIUS_M, lo_open=True),
        default=15.0,
        metavar="M",
        help="cross-track bound for the conformance report [15 m]",
    )
    p.add_argument(
        "--max-schedule-error",
        type=number_flag(0, MAX_DURATION_S, lo_open=True),
        default=MAX_SCHEDULE_ERROR_S,
        metavar="S",
        help=f"bound on each vehicle's along-track time error [{MAX_SCHEDULE_ERROR_S:g} s]",
    )
    p.add_argument(
        "--allow-infeasible",
        action="store_true",
        help="fly a plan the plan checker reports infeasible (refused otherwise)",
    )
    p.add_argument(
        "--drift",
        action="append",
        default=[],
        metavar="SYSID:EAST:NORTH",
        help="mock fault: navigation drift [m/s] of one vehicle (repeatable)",
    )
    p.add_argument(
        "--mock-legs",
        choices=MOCK_LEGS,
        default="tuned",
        help="how the mock multirotors fly their waypoints: 'tuned', the mock's own kinematics at an"
        " acceleration tuned to the plan, or 'scurve', ArduCopter's S-curve legs at its stock WP_ACC /"
        " WP_JERK, as SITL flies them (--autopilot ardupilot) [tuned]",
    )
    p.add_argument(
        "--mock-param",
        action="append",
        default=[],
        metavar="NAME=VALUE",
        help="a parameter every mock vehicle starts with, as a line of SITL's --defaults file (repeatable)",
    )


def build_parser_defaults(scenario: Path, out: str, speedup: float | None) -> argparse.Namespace:
    """The fly arguments with every default, for commands that fly a fixed scenario (demo)."""
    parser = argparse.ArgumentParser()
    add_arguments(parser)
    pace = ["--speedup", str(speedup)] if speedup is not None else []
    return parser.parse_args([str(scenario), "--out", out, *pace])


def _fly_coalition(args: argparse.Namespace) -> int:
    """A coalition scenario has no plan to upload up front: its awards are flown as they are made."""
    given = {"--plan": args.plan, "--connect": args.connect, "--drift": args.drift, "--tlog": args.tlog,
             "--mock-legs": args.mock_legs != "tuned", "--mock-param": args.mock_param}  # fmt: skip
    given["--in-flight"] = args.in_flight != Timing.window  # award uploads keep their own timing
    unsupported = [flag for flag, value in given.items() if value]
    if unsupported:
        raise UserError(
            f"{args.scenario} is a coalition scenario, flown award by award as `gcs-planner fly-coalition` "
            f"does; {', '.join(unsupported)} not supported for it"
        )
    parser = argparse.ArgumentParser()
    fly_coalition.add_arguments(parser)
    argv = [args.scenario, "--out", args.out]
    argv += ["--speedup", str(args.speedup)] if args.speedup is not None else []
    argv += ["--seed", str(args.seed)] if args.seed is not None else []
    argv += ["--homes"] if args.homes else []
    print("coalition scenario: each award is uploaded to its vehicles in flight (gcs-planner fly-coalition)")
    return fly_coalition.run(parser.parse_args(argv))


def _drift(values: list[str], sysids: list[int]) -> dict[int, tuple[float, float]]:
    """--drift SYSID:EAST:NORTH [m/s] values; each sysid must be one of the plan's ``sysids``."""
    out = {}
    for value in values:
        try:
            sysid, east, north = value.split(":")
            sysid, east, north = int(sysid), float(east), float(north)
        except ValueError:
            raise UserError(f"--drift must be SYSID:EAST:NORTH, got {value!r}") from None
        if sysid not in sysids:
            raise InputError(f"--drift {value!r}: sysid {sysid} is not one of the plan's {sorted(sysids)}")
        for v in (east, north):
            number(v, f"--drift {value!r}: speed", -MAX_SPEED_MPS, MAX_SPEED_MPS)
        out[sysid] = (east, north)
    return out


def _mock_params(args: argparse.Namespace) -> dict[str, float]:
    """--mock-param NAME=VALUE values, each a finite number; only for the mock fleet."""
    if args.connect and (args.mock_param or args.mock_legs != "tuned"):
        raise UserError("--mock-legs and --mock-param set up the mock fleet: not with --connect")
    if args.mock_legs == "scurve" and args.autopilot != Conventions.ARDUPILOT:
        raise UserError(f"--mock-legs scurve flies ArduCopter's legs: not with --autopilot {args.autopilot}")
    out = {}
    for value in args.mock_param:
        name, _, text = value.partition("=")
        try:
            out[name] = float(text)
        except ValueError:
            out[name] = math.nan
        if not name or not math.isfinite(out[name]):
            raise InputError(f"--mock-param must be NAME=VALUE with a finite number, got {value!r}")
    return out


def _plan_file(path: str, scenario: Scenario) -> Plan:
    """A plan file re-checked against the scenario it is flown in (its flags are the file's): its
    obstacles, separation, band and site; the planner held its kinematics when it made it."""
    plan = Plan.load(path)
    known = {v.id for v in scenario.vehicles}
    if missing := [vp.vehicle_id for vp in plan.vehicles if vp.vehicle_id not in known]:
        raise UserError(f"--plan {path!r}: vehicles {missing} are not in scenario {scenario.name!r}")
    certify_plan(plan, scenario, kinematics=False)
    return plan


def check_feasible(plan: Plan, allow: bool) -> None:
    """Refuse (UserError) a plan the plan checker found infeasible, naming the first finding;
    with ``allow`` print a warning and go on."""
    bad = [v for v in plan.vehicles if not v.feasible]
    if not bad:
        return
    found = next((n[7:] for n in bad[0].notes if n.startswith("check: ")), "see its notes")
    what = f"the plan is infeasible for {[v.vehicle_id for v in bad]} ({bad[0].vehicle_id}: {found})"
    if not allow:
        raise UserError(f"{what}; --allow-infeasible flies it anyway")
    print(f"warning: {what}; flying anyway (--allow-infeasible)")


def _climb_notes(plan: Plan) -> None:
    """One line on stderr (stdout is `sitl-mock --homes`' input): the fastest climb and descent of
    the plan's multirotors, which their autopilots' mission limits must allow (flight/limits.py),
    so that a SITL for a steeper plan is started with them raised."""
    rates = [
        (planned_vertical_mps(vp), vp.vehicle_id) for vp in plan.vehicles if vp.vehicle_type == "multirotor"
    ]
    if not rates or max(max(r) for r, _ in rates) <= 0.0:
        return
    (climb, _), up_by = max(rates, key=lambda r: r[0][0])
    (_, descent), down_by = max(rates, key=lambda r: r[0][1])
    names = " or ".join(f"{' / '.join(f.vertical_params)} ({f.name})" for f in (ARDUCOPTER, PX4))
    print(
        f"note: the plan climbs at up to {climb:.2f} m/s ({up_by}) and descends at up to {descent:.2f} m/s"
        f" ({down_by}); set {names} to at least that (fly checks them)",
        file=sys.stderr,
    )


def _ramp_note(plan: Plan, bound_s: float) -> None:
    """One line on stderr when ArduCopter's stock WP_ACC / WP_JERK would fly a multirotor later than
    ``bound_s`` (flight.limits.check_waypoint_timing), naming the values that would not."""
    copters = [vp for vp in plan.vehicles if vp.vehicle_type == "multirotor"]
    climb = max((max(planned_vertical_mps(vp)) for vp in copters), default=0.0)
    stock = WaypointNav()
    nav = replace(stock, climb_mps=max(stock.climb_mps, climb), descent_mps=max(stock.descent_mps, climb))
    late = [(predicted_errors_s(vp, nav).max(initial=0.0), vp.vehicle_id) for vp in copters]
    if not late or max(late)[0] <= bound_s:
        return
    worst_s, worst_by = max(late)
    found = faster_ramp(copters, nav, bound_s)
    what = "plan longer or slower legs"
    if found is not None:
        accel, jerk = f"{found[0]:g}", f"{found[1]:g}"
        what = (
            f"set WP_ACC {accel} and WP_JERK {jerk} (fly checks them; `fly --mock-legs scurve --mock-param"
            f" WP_ACC={accel} --mock-param WP_JERK={jerk}` flies that on mock ArduCopters)"
        )
    print(
        f"note: at ArduCopter's stock WP_ACC {stock.accel_mps2:g} / WP_JERK {stock.jerk_mps3:g} the plan's"
        f" short legs put {worst_by} {worst_s:.1f} s late (bound {bound_s:g} s); {what}",
        file=sys.stderr,
    )


def run(args: argparse.Namespace) -> int:
    out = output_dir(args.out, "-o")
    if args.live:
        check_display("--live")
    scenario = load_scenario(args.scenario)
    if planner(scenario.planner_name).TRAITS.online:
        return _fly_coalition(args)
    plan = _plan_file(args.plan, scenario) if args.plan else plan_with_progress(scenario, args.seed)
    if args.homes:
        print(format_homes(starts(plan.vehicles, plan.origin), None))
        _climb_notes(plan)
        _ramp_note(plan, args.max_schedule_error)
        return 0
    drift = _drift(args.drift, [v.sysid for v in plan.vehicles])
    mock_params = _mock_params(args)
    check_flight(plan)  # every mission, before anything is written or sent
    check_feasible(plan, args.allow_infeasible)
    if args.connect and networks(plan) > 1:
        check_networks(plan, len(args.connect))
    say_ignored_tables(scenario)
    if args.connect:
        rate = 1.0 if args.speedup is None else args.speedup  # real vehicles: 1; SITL: its --speedup
        vehicles = ConnectedVehicles(args.connect, per_network=networks(plan) > 1, speedup=rate)
    else:
        try:
            vehicles = mock_vehicles("mock", plan.vehicles, origin=plan.origin, speedup=args.speedup,
                                     autopilot=args.autopilot, scurve_legs=args.mock_legs == "scurve",
                                     params=mock_params)  # fmt: skip
        except ValueError as exc:
            raise InputError(f"--mock-param: {exc}") from None
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise UserError(f"-o {str(out)!r}: cannot make the folder: {exc.strerror or exc}") from None
    plan.save(out / "plan.json")
    options = FlyOptions(
        out_dir=out,
        workers=args.workers,
        in_flight=args.in_flight,
        tlog=args.tlog,
        rrd=not args.no_rrd,
        max_cross_track_m=args.max_cross_track,
        max_schedule_error_s=args.max_schedule_error,
        drift_mps=drift,
        live=live_recording(args.live, args.serve_web),
    )
    bars: dict[str, object] = {}
    said: dict[int, str] = {}

    def progress(stage: str, done, total) -> None:
        if stage == "wait":  # done = sysid, total = the vehicle's reason
            if said.get(done) != total:
                said[done] = total
                tqdm.write(f"sysid {done} not ready to arm yet: {total} (waiting)", file=sys.stderr)
            return
        if stage not in bars:
            bars[stage] = progress_bar(total, {"upload": "uploading", "fly": "flying"}[stage], "vehicle")
        bars[stage].n = done
        bars[stage].refresh()

    try:
        result = lockstep.run(fly(scenario, plan, options, vehicles, progress), vehicles.lockstep)
    finally:
        for bar in bars.values():
            bar.close()
    return _report(result)


def _report(result) -> int:
    """Print the flight's outcome; the exit code: 0 PASS, 1 FAIL, 128 + signal when one ended it."""
    print(format_report(result.reports))
    if result.end_states:
        print(f"end: {end_summary(result.end_states)}")
    print(
        f"log: {result.mcap_path}  (open in Foxglove, or `gcs-planner replay {result.mcap_path} --rrd x.rrd`)"
    )
    if result.rrd_path:
        print(f"rerun: {result.rrd_path}  (open with `rerun {result.rrd_path}`)")
    if result.report_path:
        print(f"report: {result.report_path}  (map, cross-track and separation over time, conformance)")
    for tlog in result.tlog_paths:
        print(f"tlog: {tlog}  (mavlogdump.py, MAVExplorer, QGroundControl)")
    if result.interrupted:
        print(f"interrupted by {result.interrupted}: the report covers the flight until then",
              file=sys.stderr)  # fmt: skip
    verdict = "PASS" if result.passed else "FAIL"
    print(
        f"{verdict}: {sum(r.passed for r in result.reports)}/{len(result.reports)} vehicles conform"
        f" ({result.wall_time_s:.1f} s wall)"
    )
    if result.log_error:  # the flight was flown and reported; its log is incomplete
        raise UserError(f"flight log {result.mcap_path}: {result.log_error}")
    if result.interrupted:
        return 128 + signal.Signals[result.interrupted].value
    return 0 if result.passed else 1
