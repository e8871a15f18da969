"""SIGTERM (a service manager, a CI runner) and SIGHUP end a flight as Ctrl-C does: every vehicle is
sent home, the log runs on until they have landed, and the report is still written."""

from __future__ import annotations

import os
import signal
from pathlib import Path

import pytest

from gcs_planner.core import lockstep
from gcs_planner.flight import FlyOptions, fly
from gcs_planner.planning import load_scenario, plan_scenario
from gcs_planner.telemetry import read_flight

sitl_mock = pytest.importorskip("sitl_mock")
from sitl_mock.plan_fleet import MockVehicles  # noqa: E402

SCENARIO = Path(__file__).resolve().parents[1] / "missions" / "straight_4uav.toml"


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGHUP])
def test_a_signal_mid_flight_brings_the_fleet_home_and_still_reports(sig, tmp_path):
    scenario = load_scenario(SCENARIO)
    plan = plan_scenario(scenario)
    sent = []

    def progress(stage: str, done, total) -> None:
        if stage == "fly" and not sent:  # the routes are flying
            sent.append(sig)
            os.kill(os.getpid(), sig)

    options = FlyOptions(out_dir=tmp_path, rrd=False)
    vehicles = MockVehicles(plan.vehicles, plan.origin)
    result = lockstep.run(fly(scenario, plan, options, vehicles, progress), lockstep=True)
    assert sent and result.interrupted == sig.name and not result.passed
    assert set(result.end_states.values()) == {"landed (disarmed)"}, result.end_states
    assert result.report_path is not None and result.report_path.stat().st_size > 0
    assert all("mission not completed" in r.failures for r in result.reports)
    events = [e for _, e in read_flight(result.mcap_path).events]
    wait = next(e for e in events if e["event"] == "end_wait")
    assert wait["still_armed"] == []
    assert any(e["event"] == "safe_end" for e in events)
    assert signal.getsignal(sig) in (signal.SIG_DFL, signal.default_int_handler)  # handlers removed


def test_a_forged_completion_from_the_vehicles_address_does_not_end_the_flight(tmp_path):
    """Reliability: MISSION_ITEM_REACHED(last) + MISSION_CURRENT(COMPLETE) sent from each vehicle's own
    address as its routes start. Completion counts only where the track shows the vehicle at its
    mission's end: the flight goes on and every route is flown in full, on time."""
    from pymavlink.dialects.v20 import ardupilotmega as mavlink

    from gcs_planner.autopilots import quirks_named
    from gcs_planner.flight.ops import build_missions

    scenario = load_scenario(SCENARIO)
    plan = plan_scenario(scenario)
    vehicles = MockVehicles(plan.vehicles, plan.origin)
    missions = build_missions(plan, {v.sysid: quirks_named("ardupilot") for v in plan.vehicles})
    last = {s: len(m) - 1 for s, m in missions.items()}
    forged, calls = [], []

    def progress(stage: str, done, total) -> None:
        calls.append(stage)
        if calls.count("fly") == 10 and not forged:  # 10 schedule-keeping periods (5 s) into the routes
            (fleet,) = vehicles.fleets
            for v in fleet.vehicles:
                seq = last[v.sysid]
                reached = mavlink.MAVLink_mission_item_reached_message(seq)
                complete = mavlink.MAVLink_mission_current_message(seq, seq, 5, 1)  # MISSION_STATE_COMPLETE
                fleet.call(lambda v=v, a=reached, b=complete: (v.link.send(a), v.link.send(b)))
            forged.append(True)

    result = lockstep.run(
        fly(scenario, plan, FlyOptions(out_dir=tmp_path, rrd=False), vehicles, progress), True
    )
    assert forged and result.passed, [(r.sysid, r.failures) for r in result.reports]
    for r in result.reports:
        assert r.flight_time_s == pytest.approx(r.planned_time_s, rel=0.1), (r.sysid, r.flight_time_s)


def test_impossible_positions_are_flagged_and_never_pass(tmp_path):
    """Reliability: a vehicle that reports latitude 91 deg (a valid int32) mid-flight: the reports
    are left out of its track and its row fails naming them, never a NaN that passes."""
    from pymavlink.dialects.v20 import ardupilotmega as mavlink

    scenario = load_scenario(SCENARIO)
    plan = plan_scenario(scenario)
    vehicles = MockVehicles(plan.vehicles, plan.origin)
    calls = []

    def progress(stage: str, done, total) -> None:
        calls.append(stage)
        if calls.count("fly") == 6:
            (fleet,) = vehicles.fleets
            v = fleet.vehicle(2)
            for lat in (910_000_000, -(2**31)):
                bad = mavlink.MAVLink_global_position_int_message(0, lat, 85_455_940, 500_000, 0, 0, 0, 0, 0)
                fleet.call(lambda b=bad: v.link.send(b))

    result = lockstep.run(
        fly(scenario, plan, FlyOptions(out_dir=tmp_path, rrd=False), vehicles, progress), True
    )
    by_sysid = {r.sysid: r for r in result.reports}
    assert "2 impossible positions reported (ignored)" in by_sysid[2].failures, by_sysid[2].failures
    assert all(by_sysid[s].passed for s in (1, 3, 4)) and not result.passed


def test_a_signal_mid_coalition_run_brings_the_planes_home_as_fly_does(tmp_path):
    """fly-coalition is the other front end of the one flight runner: a SIGTERM as its routes start
    sends every plane home and the run is reported, interrupted; its log carries the clock rate."""
    from gcs_planner.flight.coalition import HilOptions
    from gcs_planner.flight.coalition.run import run_coalition_hil
    from sitl_mock.plan_fleet import MockVehiclesProcess

    scenario = load_scenario(SCENARIO.parent / "coalition_paper.toml")
    said = []

    def say(line: str) -> None:
        said.append(line)
        if "routes started" in line:
            os.kill(os.getpid(), signal.SIGTERM)

    options = HilOptions(out_dir=tmp_path, targets=("T1",))
    result = lockstep.run(run_coalition_hil(scenario, options, MockVehiclesProcess, say=say), True)
    assert result.interrupted == "SIGTERM" and not result.passed, said
    assert set(result.end_states.values()) == {"returning (RTL)"}, result.end_states  # planes circle home
    flight = read_flight(result.mcap_path)
    assert any(e["event"] == "safe_end" for _, e in flight.events)
    assert flight.metadata["gcs_planner"]["clock_rate"] == "1.0"  # lockstep: flight time on the log's clock


def test_fly_coalition_exits_128_plus_the_signal_after_its_safe_end(tmp_path):
    """The command line: SIGTERM once the routes have started -> the planes are sent home, the
    report is printed, and the exit status says which signal ended the run (143), as fly's does."""
    import subprocess
    import sys

    from child_process import child

    scenario = SCENARIO.parent / "coalition_paper.toml"
    argv = [sys.executable, "-m", "gcs_planner.cli", "fly-coalition", str(scenario), "--targets", "T1"]
    argv += ["-o", str(tmp_path)]
    with child(argv, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True) as proc:
        for line in proc.stderr:
            if "routes started" in line:
                proc.send_signal(signal.SIGTERM)
                break
        out, err = proc.communicate(timeout=120)
    assert proc.returncode == 128 + signal.SIGTERM, err
    assert "interrupted by SIGTERM" in err and "end: sysid" in out, (out, err)
