"""Coalition HIL: awards uploaded over real UDP to flying mock fixed wings; strike time and angle."""

import asyncio
from pathlib import Path

import numpy as np

from gcs_planner.coalition_hil import HilOptions, measure_strike, run_coalition_hil
from gcs_planner.scenario import load_scenario
from gcs_planner.telemetry import read_flight

SCENARIO = Path(__file__).resolve().parents[1] / "missions" / "coalition_paper.toml"


def test_measure_strike_interpolates_closest_approach_and_heading():
    t = np.arange(0.0, 20.0, 0.5)
    heading = np.radians(200.0)
    xy = np.column_stack([np.cos(heading), np.sin(heading)]) * (50.0 * (t - 10.3))[:, None]
    award = {"uav": "U1", "sysid": 1, "target": "T1", "time_s": 10.0, "angle_deg": 20.0, "entry_xy": [0, 0]}
    row = measure_strike(t, xy + [0.0, 3.0], award, (1.0, 10.0))
    assert abs(row.flown_s - 10.3) < 0.1 and abs(row.time_error_s - 0.3) < 0.1
    assert abs(row.angle_error_deg) < 1e-6 and row.passed
    late = measure_strike(t + 1.5, xy, award, (1.0, 10.0))
    assert not late.passed and abs(late.time_error_s - 1.8) < 1e-6


def test_t1_awards_are_uploaded_in_flight_and_strikes_arrive_on_time_and_angle(tmp_path):
    scenario = load_scenario(SCENARIO)
    result = asyncio.run(
        run_coalition_hil(scenario, HilOptions(out_dir=tmp_path, speedup=10.0, targets=("T1",)))
    )
    assert not result.failures, result.failures
    # the 8 strikes of T1's simultaneous attack, each within 1 s and 10 deg of its award
    assert len(result.rows) == 8 and len({r.awarded_s for r in result.rows}) == 1
    for r in result.rows:
        assert abs(r.time_error_s) <= 1.0 and abs(r.angle_error_deg) <= 10.0, r
        assert r.miss_m < 15.0, r
    assert result.passed
    # every award (8 strikes + 2 assessments) became a mission uploaded while flying, after its award
    # time and before the strike
    assert len(result.uploads) == 10 and all(u["ok"] for u in result.uploads)
    strike_s = result.rows[0].awarded_s
    for u in result.uploads:
        assert u["award_t_s"] <= u["upload_start_s"] < u["upload_end_s"] < strike_s - 10.0, u
        t, p = result.tracks[u["sysid"]]
        k = np.searchsorted(t, u["upload_end_s"])
        assert p[k, 2] > 250.0  # airborne at the upload (cruise altitudes 300-500 m)
    flight = read_flight(result.mcap_path)
    kinds = [e.get("event") for _, e in flight.events]
    assert {"tender", "bid", "award", "upload", "route_start"} <= set(kinds)
    assert kinds.count("award") == 10 and kinds.count("upload") == 10


def test_fly_coalition_command_refuses_a_scenario_without_the_coalition_planner(capsys):
    from gcs_planner.cli import main

    assert main(["fly-coalition", str(SCENARIO.parent / "straight_4uav.toml")]) == 2
    assert "[planner] name must be 'coalition'" in capsys.readouterr().err
