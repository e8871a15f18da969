"""fly-coalition with connected vehicles (--connect): vehicles this tool does not start, on clocks of
their own, some of them beside mock ones on one link, started where --homes says, sent home after."""

import asyncio
import importlib.util
import math
from collections import Counter
from pathlib import Path

import numpy as np
import pytest

import sitl_mock
from gcs_planner.cli import main
from gcs_planner.commands.fly_coalition import connected_fleet
from gcs_planner.core import lockstep
from gcs_planner.core.errors import UserError
from gcs_planner.core.geo import Origin, enu_to_geodetic, geodetic_to_enu
from gcs_planner.flight.coalition import HilOptions
from gcs_planner.flight.coalition.live_legs import RUN_IN_S, TURN_FACTOR
from gcs_planner.flight.coalition.online_run import OnlineRun
from gcs_planner.flight.coalition.run import initial_plans, run_coalition_hil
from gcs_planner.flight.starts import CLIMB_RUN_PER_M, check_starts, starts
from gcs_planner.model.plan import VehiclePlan
from gcs_planner.planning import load_scenario
from gcs_planner.planning.coalition import load_world, simulate
from gcs_planner.telemetry import read_flight
from sitl_mock.l1 import SITL_PLANE
from sitl_mock.plan_fleet import MockVehiclesProcess

MISSIONS = Path(__file__).resolve().parents[1] / "missions"
BENCHMARKS = MISSIONS.parent / "benchmarks"
SCENARIO = MISSIONS / "coalition_paper.toml"
SITL_SCENARIO = MISSIONS / "coalition_sitl.toml"  # the paper's at the size of SITL's plane
CONNECTED = frozenset({1, 8, 11, 13})  # U1 does T1's recon and leads its tender


def test_online_run_with_some_vehicles_connected_on_clocks_of_their_own(tmp_path):
    """The connected vehicles are a second mock fleet reached over --connect, planes on ArduPlane's
    L1 law: its clock (time_boot_ms) starts apart from the tool's own mock fleet, so only frames
    timed on receipt put both on one flight clock, and every strike and assessment is still on
    time and angle. Both fleets run in lockstep with the run: the same flight however busy."""
    scenario = load_scenario(SITL_SCENARIO)
    options = HilOptions(out_dir=tmp_path, speedup=1.0, targets=("T1",), online=True)
    plans = [vp for vp in initial_plans(scenario, options, OnlineRun) if vp.sysid in CONNECTED]
    said: list[str] = []

    async def fly():  # the "connected" planes fly ArduPlane's L1 law, in lockstep with the run
        async with MockVehiclesProcess(plans, scenario.origin, l1=SITL_PLANE) as networks:
            await asyncio.sleep(30.0)  # booted half a minute before the tool's own mock fleet
            vehicles_for = connected_fleet(networks[0], CONNECTED, lockstep=True)
            return await run_coalition_hil(scenario, options, vehicles_for, OnlineRun, said.append)

    result = lockstep.run(fly(), True)
    assert not result.failures, result.failures
    stages = ("vehicles heard", "missions uploaded", "routes started")
    order = [next(i for i, line in enumerate(said) if stage in line) for stage in stages]
    assert order == sorted(order), said  # the run's stages told as they come
    assert len(result.rows) == 10 and all(r.passed for r in result.rows), result.rows
    tenders = [e for e in result.events if e["event"] == "tender" and e["target"] == "T1"]
    assert tenders and tenders[0]["uav"] == "U1", tenders[:1]  # recon on the connected U1's telemetry
    assert set(result.end_states.values()) == {"returning (RTL)"}, result.end_states
    flight = read_flight(result.mcap_path)
    assert sorted(flight.positions) == list(range(1, 33)), sorted(flight.positions)
    assert any(e["event"] == "safe_end" for _, e in flight.events)
    awards = [e for _, e in flight.events if e["event"] == "upload" and e["kind"] == "award"]
    legs = Counter((e["run_in_s"], e["turn_factor"]) for e in awards)
    straight = sum(n for (run_in, _), n in legs.items() if run_in > 0)
    wide = sum(n for (_, factor), n in legs.items() if factor == TURN_FACTOR)
    assert awards and straight >= len(awards) / 2 and wide >= len(awards) / 4, legs  # where they fit in time
    assert max(run_in for run_in, _ in legs) == RUN_IN_S, legs


def test_homes_put_each_connected_plane_one_climb_run_behind_its_first_waypoint(capsys):
    assert main(["fly-coalition", str(SCENARIO), "--targets", "T1", "--connect", "udpin:127.0.0.1:14550",
                 "--connected", "1,8-9", "--homes"]) == 0  # fmt: skip
    lines = capsys.readouterr().out.splitlines()
    assert [line.split()[1] for line in lines] == ["1", "8", "9"]
    scenario = load_scenario(SCENARIO)
    options = HilOptions(targets=("T1",), online=True)
    plans = {vp.sysid: vp for vp in initial_plans(scenario, options, OnlineRun)}
    for line in lines:
        lat, lon, alt, heading = map(float, line.split("--home ")[1].split()[0].split(","))
        vp = plans[int(line.split()[1])]
        x, y, z = geodetic_to_enu(lat, lon, alt, scenario.origin)
        wp0, wp1 = vp.waypoints[0], vp.waypoints[1]
        assert abs(z) < 0.5  # on the ground at the scenario's origin altitude
        assert math.hypot(wp0[0] - x, wp0[1] - y) == pytest.approx(wp0[2] * CLIMB_RUN_PER_M, rel=1e-3)
        along = np.degrees(np.arctan2(wp1[0] - wp0[0], wp1[1] - wp0[1])) % 360.0
        towards = np.degrees(np.arctan2(wp0[0] - x, wp0[1] - y)) % 360.0
        assert abs(math.remainder(heading - along, 360.0)) < 1.0
        assert abs(math.remainder(towards - along, 360.0)) < 0.1  # the climb runs along the lead-in


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--connected", "1"], "--connected names vehicles reached over --connect"),
        (["--connect", "udpin:127.0.0.1:14550", "--connected", "1,77"], "--connected: sysid [77] not in"),
        (["--connect", "udpin:127.0.0.1:14550", "--connected", "3-1"], "ranges run upwards"),
        (["--connect", "udpin:127.0.0.1:14550", "--connected", "0"], "sysids are 1..255"),
    ],
)
def test_connected_vehicles_badly_named_are_refused_in_one_line(argv, message, capsys, tmp_path):
    assert main(["fly-coalition", str(SCENARIO), "-o", str(tmp_path / "out"), *argv]) == 2
    err = capsys.readouterr().err
    assert message in err and len(err.strip().splitlines()) == 1, err
    assert not (tmp_path / "out").exists() or not any((tmp_path / "out").iterdir())


CMAC = Origin(-35.363261, 149.165230, 584.0)  # ArduPilot SITL's default home (Tools/autotest/locations.txt)


@pytest.mark.parametrize(
    ("scenario", "home", "fragments"),
    [
        # a stock plane (AIRSPEED_MAX 30 m/s) cannot fly the paper's 50 m/s UAVs; the line says
        # what to fly on a stock SITL plane instead
        (
            SCENARIO,
            None,
            [
                "(sysid 1): AIRSPEED_MAX is 30 m/s, but the flight needs up to 60 m/s",
                "missions/coalition_sitl.toml",
            ],
        ),
        # a SITL started without --home is at CMAC, not one climb run behind its first waypoint
        (SITL_SCENARIO, CMAC, ["sysid 1 (U1) is 8,", "km from its start", "--homes"]),
    ],
    ids=["too-slow", "away-from-start"],
)
def test_a_connected_plane_that_cannot_fly_the_run_is_refused_before_anything_is_sent(
    scenario, home, fragments, capsys, tmp_path
):
    """One line naming the vehicle and what is wrong, exit 2, and the plane is left disarmed
    without a mission."""
    home = home or load_scenario(scenario).origin
    with sitl_mock.MockFleet(count=1, profile="ardupilot", vehicle_type="fixed_wing", speedup=20.0,
                             home=home) as fleet:  # fmt: skip
        ((host, port),) = fleet.addresses
        argv = ["fly-coalition", str(scenario), "--targets", "T1", "--connect", f"udpout:{host}:{port}",
                "--connected", "1", "--speedup", "20", "-o", str(tmp_path)]  # fmt: skip
        assert main(argv) == 2
        plane = fleet.vehicles[0]
        assert not plane.armed and len(plane.mission_server.items()) <= 1  # at most the home item
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and all(f in err[0] for f in fragments), err


def test_a_start_within_the_bound_passes_and_one_beyond_it_is_named():
    (start,) = starts([_plan()], Origin(31.5, 105.0, 500.0))
    near = enu_to_geodetic(0.0, -0.9 * start.bound_m, 0.0, start.home)[:2]
    far = enu_to_geodetic(0.0, -1.1 * start.bound_m, 0.0, start.home)[:2]
    check_starts([start], {1: near, 2: far}, "hint")  # sysid 2 has no start: not checked
    with pytest.raises(UserError, match=rf"sysid 1 \(V1\) is {1.1 * start.bound_m:.1f} m from its start .*"
                       rf"\(bound {start.bound_m:.0f} m\) \(hint\)"):  # fmt: skip
        check_starts([start], {1: far}, "hint")
    with pytest.raises(UserError, match=r"sysid 1 \(V1\) reports no position"):
        check_starts([start], {}, "hint")


def _plan() -> VehiclePlan:
    waypoints = np.array([[0.0, 0.0, 100.0], [0.0, 500.0, 100.0]])
    return VehiclePlan("V1", 1, waypoints, [0.0, 25.0], [0.0, 20.0], waypoints, [0.0, 25.0], "fixed_wing")


def test_the_sitl_scenario_is_its_generators_output_and_forms_every_coalition_of_the_paper():
    """missions/coalition_sitl.toml is what its generator makes of coalition_paper.toml, and its
    simulation awards the same number of tasks of every target as the paper scenario's."""
    spec = importlib.util.spec_from_file_location("generator", BENCHMARKS / "make_coalition_sitl.py")
    generator = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(generator)
    assert generator.convert(SCENARIO.read_text()) == SITL_SCENARIO.read_text()
    counts = []
    for path in (SCENARIO, SITL_SCENARIO):
        result = simulate(load_world(load_scenario(path)), np.random.default_rng(3))
        counts.append(Counter(e["target"] for e in result.events if e["event"] == "award"))
    assert set(counts[0]) == {"T1", "T2", "T3"} and counts[0] == counts[1], counts
