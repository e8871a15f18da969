"""The whole chain: plan -> upload over UDP -> mock fleet flies -> MCAP/.rrd -> conformance."""

from pathlib import Path

import pytest

from gcs_planner.core import lockstep
from gcs_planner.flight import FlyOptions, fly
from gcs_planner.planning import load_scenario, plan_scenario
from gcs_planner.telemetry import read_flight
from sitl_mock.plan_fleet import MockVehicles

SCENARIO = Path(__file__).resolve().parents[1] / "missions" / "straight_4uav.toml"


@pytest.fixture(scope="module")
def scenario_and_plan():
    scenario = load_scenario(SCENARIO)
    return scenario, plan_scenario(scenario)


def _fly(scenario, plan, out, speedup=None, progress=None, **kw):
    """Fly against mock vehicles, in lockstep unless paced at ``speedup``."""
    vehicles = MockVehicles(plan.vehicles, plan.origin, speedup)
    return lockstep.run(
        fly(scenario, plan, FlyOptions(out_dir=out, **kw), vehicles, progress), vehicles.lockstep
    )


def test_fly_passes_and_log_holds_every_vehicle_plan_and_metadata(scenario_and_plan, tmp_path):
    """... and the live Rerun views stream while flying (read back with Rerun's own reader)."""
    import rerun as rr
    from rerun.chunk import RrdReader

    scenario, plan = scenario_and_plan
    rec = rr.RecordingStream("gcs-planner-test")
    live_rrd = tmp_path / "live.rrd"
    rec.save(live_rrd)  # a file sink: bytes reach it as the views are logged
    sizes: list[int] = []

    def progress(stage, done, total):  # called while flying, as vehicles finish
        if stage == "fly":
            rec.flush()
            sizes.append(live_rrd.stat().st_size)

    result = _fly(scenario, plan, tmp_path, tlog=True, live=rec, progress=progress)
    rec.disconnect()
    assert sizes and sizes[0] > 10_000  # the views were streamed before the flight ended
    entities = {chunk.entity_path for chunk in RrdReader(live_rrd).stream()}
    assert {f"/map/track/{v.sysid}" for v in plan.vehicles} <= entities
    assert result.passed, [r.failures for r in result.reports]
    assert all(r.completed and r.cross_track_max_m < 5.0 for r in result.reports)
    flight = read_flight(result.mcap_path)
    assert set(flight.positions) == {v.sysid for v in plan.vehicles}
    assert all(len(t) > 20 for t in flight.positions.values())
    assert flight.plan is not None and [v.sysid for v in flight.plan.vehicles] == [1, 2, 3, 4]
    assert flight.origin == plan.origin and flight.scenario_text == SCENARIO.read_text()
    assert {e["sysid"] for _, e in flight.events if e.get("event") == "route_start"} == {1, 2, 3, 4}
    assert result.rrd_path.stat().st_size > 1000 and result.tlog_paths[0].stat().st_size > 1000
    assert result.report_path == tmp_path / "report.png" and result.report_path.stat().st_size > 20_000


def test_fly_fails_when_a_vehicle_drifts(scenario_and_plan, tmp_path, monkeypatch):
    """The southern lane drifts south, away from the others: it alone fails (a drift into a
    neighbour's lane would also fail the neighbour on separation, by as much as the timing).
    Uploaded with two items in flight (FlyOptions.in_flight, what `fly --in-flight 2` sets)."""
    from gcs_planner.flight import runner

    windows = []

    async def upload_fleet(*args, timing, **kw):
        windows.append(timing.window)
        return await real(*args, timing=timing, **kw)

    real = runner.upload_fleet
    monkeypatch.setattr(runner, "upload_fleet", upload_fleet)
    scenario, plan = scenario_and_plan
    result = _fly(
        scenario, plan, tmp_path, rrd=False, drift_mps={1: (0.0, -1.5)}, max_cross_track_m=10.0, in_flight=2
    )
    assert windows == [2] and not result.passed
    by_sysid = {r.sysid: r for r in result.reports}
    assert any("cross-track" in f for f in by_sysid[1].failures), [r.failures for r in result.reports]
    assert all(by_sysid[s].passed for s in (2, 3, 4)), [r.failures for r in result.reports]


@pytest.mark.slow
def test_deconflicted_10_uav_plan_flies_clear_of_each_other_and_the_manned_aircraft(tmp_path):
    scenario = load_scenario(SCENARIO.parent / "deconflict_10uav_manned.toml")
    plan = plan_scenario(scenario)
    assert plan.feasible
    result = _fly(scenario, plan, tmp_path, rrd=False)
    assert result.passed, [r.failures for r in result.reports]
    assert all(r.min_traffic_distance_m >= 10.0 for r in result.reports)
    assert all(r.min_separation_m >= 8.0 for r in result.reports)


@pytest.mark.slow
def test_40_uav_priority_swarm_plan_flies_with_no_separation_breach(tmp_path):
    scenario = load_scenario(SCENARIO.parent / "swarm40_cylinders.toml")
    plan = plan_scenario(scenario)
    result = _fly(scenario, plan, tmp_path, rrd=False)
    assert result.passed, [(r.sysid, r.failures) for r in result.reports if r.failures]
    assert all(r.completed for r in result.reports) and len(result.reports) == 40
    assert min(r.min_separation_m for r in result.reports) >= 8.0


def test_fly_flies_a_coalition_scenario_award_by_award(tmp_path, monkeypatch, capsys):
    """`gcs-planner fly` on the coalition scenario runs the coalition HIL (in lockstep by default),
    and says which of fly's options do not apply to it."""
    from gcs_planner import cli
    from gcs_planner.commands import fly_coalition

    seen = []
    monkeypatch.setattr(fly_coalition, "run", lambda args: seen.append(args) or 0)
    scenario = str(SCENARIO.parent / "coalition_paper.toml")
    assert cli.main(["fly", scenario, "-o", str(tmp_path), "--seed", "7"]) == 0
    assert (seen[0].scenario, seen[0].out, seen[0].speedup, seen[0].seed) == (
        scenario,
        str(tmp_path),
        None,
        7,
    )
    assert cli.main(["fly", scenario, "--speedup", "10"]) == 0 and seen[1].speedup == 10.0
    assert (
        cli.main(["fly", scenario, "--plan", "p.json", "--tlog", "--in-flight", "2"]) == 2 and len(seen) == 2
    )
    assert "--plan, --tlog, --in-flight not supported" in capsys.readouterr().err
