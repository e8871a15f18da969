from pathlib import Path

import numpy as np
import pytest

from gcs_planner.cli import main
from gcs_planner.model.plan import Plan
from gcs_planner.model.scenario import ScenarioError
from gcs_planner.planning import load_scenario, plan_scenario

MISSIONS = Path(__file__).resolve().parents[1] / "missions"


def test_demo_scenario_plans_and_round_trips_through_json(tmp_path):
    scenario = load_scenario(MISSIONS / "straight_4uav.toml")
    plan = plan_scenario(scenario)
    plan.save(tmp_path / "plan.json")
    back = Plan.load(tmp_path / "plan.json")
    assert [v.sysid for v in back.vehicles] == [v.sysid for v in scenario.vehicles]
    for a, b in zip(plan.vehicles, back.vehicles, strict=True):
        np.testing.assert_allclose(a.path, b.path, atol=1e-4)
        np.testing.assert_allclose(a.times_s, b.times_s, atol=1e-4)
    assert back.origin == scenario.origin


@pytest.mark.parametrize(
    "bad,needle",
    [
        ('[origin]\nlat_deg = 91\nlon_deg = 0\n[planner]\nname="straight"\n', "lat_deg"),
        (
            '[origin]\nlat_deg = 1\nlon_deg = 0\n[planner]\nname="straight"\n'
            "[[vehicles]]\nsysid = 300\nstart=[0,0,0]\ngoal=[1,1,1]\n",
            "sysid",
        ),
        (
            '[origin]\nlat_deg = 1\nlon_deg = 0\n[planner]\nname="straight"\n'
            "[[vehicles]]\nsysid = 1\nstart=[0,0]\ngoal=[1,1,1]\n",
            "start",
        ),
        ("[origin]\nlat_deg = 1\nlon_deg = 0\n", "planner"),
    ],
)
def test_bad_scenario_names_field(tmp_path, bad, needle):
    f = tmp_path / "bad.toml"
    f.write_text(bad)
    with pytest.raises(ScenarioError, match=needle):
        load_scenario(f)


def test_cli_user_error_is_one_line_and_exit_2(tmp_path, capsys):
    assert main(["plan", str(tmp_path / "missing.toml")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "missing.toml" in err[0]


def test_plan_convergence_png_written_or_refused_clearly(tmp_path, capsys):
    png = tmp_path / "conv.png"
    small = MISSIONS / "swarm_small.toml"
    assert main(["plan", str(small), "-o", str(tmp_path / "p.json"), "--convergence", str(png)]) == 0
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    straight = MISSIONS / "straight_4uav.toml"
    assert main(["plan", str(straight), "-o", str(tmp_path / "s.json"), "--convergence", str(png)]) == 2
    assert "no convergence history" in capsys.readouterr().err
