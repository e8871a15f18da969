"""Coalition HIL run: fly mock fixed wings and upload each coalition award to them in flight.

--connect URL flies real ArduPlanes or SITL instead (all, or the --connected sysids, the others
mock ones on the same link); --homes prints where each connected vehicle should start.

By default the contract net runs online (gcs_planner/flight/coalition/online_run.py): every UAV of
the scenario is a mock fixed wing, and who tenders, who bids and who wins which task, when and at
which angle is decided in flight from the vehicles' telemetry; the event simulation is run too,
as the reference its formations are printed beside. --offline takes every decision from the
simulation instead and flies only the awarded UAVs (gcs_planner/flight/coalition/run.py). Either way
each award's leg is planned from the vehicle's live telemetry (--replay-legs, offline only,
uploads the simulation's own legs, for comparison). Writes OUT/flight.mcap (tenders, bids, awards
and uploads as events) and prints each strike's and assessment's flown arrival time and heading
against its award. Exits 1 when one is more than --max-time-error late or early or
--max-angle-error off its awarded angle.
"""

from __future__ import annotations

import argparse
import signal
import sys
from pathlib import Path

from gcs_planner.commands.plan import SEED
from gcs_planner.core import lockstep
from gcs_planner.core.errors import UserError
from gcs_planner.core.validation import MAX_DURATION_S, number_flag, output_dir, sysids_flag
from gcs_planner.flight import end_summary
from gcs_planner.flight.coalition import UPLOAD_SAFETY, HilOptions, format_strike_report, run_coalition_hil
from gcs_planner.flight.coalition.online_run import OnlineRun
from gcs_planner.flight.coalition.report import format_formations
from gcs_planner.flight.coalition.run import initial_plans
from gcs_planner.flight.starts import format_homes, starts
from gcs_planner.flight.vehicles import ConnectedVehicles, MixedVehicles, mock_vehicles
from gcs_planner.planning import load_scenario
from gcs_planner.planning.coalition import load_world

SPEEDUP = number_flag(0, 1000, lo_open=True)  # mock simulation speed-up


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("scenario", help="coalition scenario (e.g. missions/coalition_paper.toml)")
    p.add_argument("-o", "--out", default="out", help="output folder [out]")
    p.add_argument(
        "--speedup",
        type=SPEEDUP,
        default=None,
        help="mock planes paced at this rate of the wall clock [none: in lockstep with this tool, as"
        " fast as the CPU allows]; with --connect, the rate the connected vehicles run at (SITL"
        " --speedup) [1]",
    )
    p.add_argument(
        "--connect",
        action="append",
        default=[],
        metavar="URL",
        help="real vehicles / SITL (udpin:HOST:PORT, udpout:HOST:PORT, tcp:HOST:PORT or serial:DEV:BAUD;"
        " repeatable, any mix)",
    )
    p.add_argument(
        "--connected",
        type=sysids_flag,
        default=None,
        metavar="SYSIDS",
        help="with --connect: the vehicles reached there (e.g. 1,5,8 or 1-3); the others are mock [all]",
    )
    p.add_argument(
        "--homes", action="store_true", help="print each connected vehicle's start (SITL --home) and exit"
    )
    p.add_argument("--seed", type=SEED, default=None, help="simulation seed (default: the file's)")
    p.add_argument("--targets", default="", help="comma-separated target ids whose awards are flown [all]")
    p.add_argument(
        "--lead",
        type=number_flag(0, MAX_DURATION_S),
        default=30.0,
        help="flight before the first award [30 s]",
    )
    p.add_argument(
        "--max-time-error", type=number_flag(0, MAX_DURATION_S), default=1.0, metavar="S", help="[1 s]"
    )
    p.add_argument(
        "--max-angle-error", type=number_flag(0, 180), default=10.0, metavar="DEG", help="[10 deg]"
    )
    p.add_argument(
        "--upload-safety",
        type=number_flag(0, 100, lo_open=True),
        default=UPLOAD_SAFETY,
        metavar="X",
        help=f"a live leg starts after X times the measured upload time (+1 s) [{UPLOAD_SAFETY:g}]",
    )
    p.add_argument(
        "--offline", action="store_true", help="take the decisions from the simulation, not online"
    )
    p.add_argument(
        "--replay-legs", action="store_true", help="with --offline: fly the simulation's legs, not live ones"
    )


def mock_fleet_process(plans, origin, speedup):
    """The coalition run's vehicles: mock fixed wings (sitl_mock.plan_fleet), in lockstep without
    a ``speedup``, else in their own process paced at it."""
    return mock_vehicles("mock-process", plans, origin=origin, speedup=speedup)


def connected_fleet(urls: list[str], connected: frozenset[int] | None, lockstep: bool = False):
    """The run's vehicles when some (``connected``; None: all) are reached at ``urls``: those
    connected, the others mock fixed wings, all on one link. ``lockstep``: the connected ones run
    in the flight's loop (a test's mock fleet), and so do the mock ones, else in their own process."""

    def vehicles_for(plans, origin, speedup):
        reached = ConnectedVehicles(urls, speedup=speedup, lockstep=lockstep)
        mock = [vp for vp in plans if connected is not None and vp.sysid not in connected]
        if not mock:
            return reached
        fleet = mock_fleet_process(mock, origin, None if lockstep else speedup)
        return MixedVehicles(fleet, reached, {vp.sysid for vp in mock})

    return vehicles_for


def _check_connected(args: argparse.Namespace, sysids: set[int]) -> None:
    if args.connected is not None and not args.connect:
        raise UserError("--connected names vehicles reached over --connect: give --connect URL too")
    unknown = sorted((args.connected or set()) - sysids)
    if unknown:
        raise UserError(f"--connected: sysid {unknown} not in the scenario (its sysids: {sorted(sysids)})")


def run(args: argparse.Namespace) -> int:
    if args.speedup is None and args.connect:
        args.speedup = 1.0
    if args.speedup is not None and args.speedup <= 0:
        raise UserError(f"--speedup must be > 0, got {args.speedup}")
    if args.upload_safety <= 0:
        raise UserError(f"--upload-safety must be > 0, got {args.upload_safety}")
    if args.replay_legs and not args.offline:
        raise UserError("--replay-legs flies the simulation's own legs: it needs --offline")
    output_dir(args.out, "-o")
    scenario = load_scenario(args.scenario)
    if scenario.planner.get("name") != "coalition":
        raise UserError(
            f"{args.scenario}: [planner] name must be 'coalition', got {scenario.planner.get('name')!r}"
        )
    _check_connected(args, {u.sysid for u in load_world(scenario).uavs})
    targets = tuple(t for t in args.targets.split(",") if t) or None
    options = HilOptions(
        out_dir=Path(args.out),
        speedup=args.speedup,
        seed=args.seed,
        targets=targets,
        lead_s=args.lead,
        max_time_error_s=args.max_time_error,
        max_angle_error_deg=args.max_angle_error,
        upload_safety=args.upload_safety,
        replay_legs=args.replay_legs,
        online=not args.offline,
    )
    runner = None if args.offline else OnlineRun
    if args.homes:
        print(format_homes(starts(initial_plans(scenario, options, runner), scenario.origin), args.connected))
        return 0
    vehicles_for = connected_fleet(args.connect, args.connected) if args.connect else mock_fleet_process
    try:
        result = lockstep.run(
            run_coalition_hil(scenario, options, vehicles_for, runner, say=_say), args.speedup is None
        )
    except TimeoutError as exc:  # the mock fleet's process did not start
        raise UserError(str(exc)) from None
    if result.interrupted:
        print(f"interrupted by {result.interrupted}: the report covers the run until then", file=sys.stderr)
    print(format_strike_report(result.rows))
    ok = sum(u["ok"] for u in result.uploads)
    print(f"{ok}/{len(result.uploads)} missions (award + idle) uploaded in flight; log {result.mcap_path}; "
          f"{result.wall_time_s:.1f} s wall")  # fmt: skip
    if options.online:
        print(format_formations(result.formations))
        cpu = max(result.tender_cpu_s, default=0.0)
        print(f"{len(result.tender_cpu_s)} formations in flight, CPU up to {cpu * 1000:.1f} ms each")
    if result.end_states:
        print(f"end: {end_summary(result.end_states)}")
    for f in result.failures:
        print(f"failure: {f}")
    if result.interrupted:
        return 128 + signal.Signals[result.interrupted].value
    return 0 if result.passed else 1


def _say(line: str) -> None:
    print(line, file=sys.stderr, flush=True)
