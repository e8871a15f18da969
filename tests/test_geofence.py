"""Each vehicle's fence is what its own plan keeps out of: a fenced vehicle flying its plan never
breaches (a 2-D exclusion circle over a tower the plan overflies stopped the demo's uav1)."""

from __future__ import annotations

import copy
from pathlib import Path

import numpy as np
import pytest

from gcs_planner.cli import main
from gcs_planner.missions.files import load_mission_file
from gcs_planner.planning import load_scenario, plan_scenario
from gcs_planner.safety.geofence import breaches, overflown, vehicle_geofence

MISSIONS = Path(__file__).resolve().parents[1] / "missions"


@pytest.fixture(scope="module")
def demo():
    scenario = load_scenario(MISSIONS / "swarm_small.toml")
    return scenario, plan_scenario(scenario)


def test_no_vehicle_breaches_its_own_fence_where_one_fence_for_all_did(demo):
    scenario, plan = demo
    for vp in plan.vehicles:
        assert breaches(vehicle_geofence(scenario, vp), vp) == [], vp.vehicle_id
    everyone = vehicle_geofence(scenario)  # every obstacle fenced, as before
    breached = {vp.vehicle_id: breaches(everyone, vp) for vp in plan.vehicles}
    over = {vp.vehicle_id: overflown(scenario, vp) for vp in plan.vehicles}
    assert any(breached.values()), breached  # the demo's uav1 flies over a tower's footprint
    assert {v for v, b in breached.items() if b} == {v for v, o in over.items() if o}
    for vp in plan.vehicles:  # what a vehicle overflies it clears vertically (the plan's 3-D check)
        for name in (n for n in over[vp.vehicle_id] if n.startswith("cylinder")):
            tower = scenario.cylinders[int(name.split()[1])]
            inside = (
                np.hypot(vp.path[:, 0] - tower.x, vp.path[:, 1] - tower.y) < tower.radius_m + tower.buffer_m
            )
            assert inside.any() and vp.path[inside, 2].min() > tower.z_max_m, (vp.vehicle_id, name)


def test_the_fence_ceiling_is_the_top_bound_above_home_and_a_climb_over_it_breaches(demo):
    scenario, plan = demo
    assert "z" not in scenario.bounds and vehicle_geofence(scenario, plan.vehicles[0]).ceiling_m is None
    scenario = copy.deepcopy(scenario)
    top = max(float(vp.path[:, 2].max()) for vp in plan.vehicles) + 1.0
    scenario.bounds["z"] = (0.0, top)
    for vp in plan.vehicles:
        fence = vehicle_geofence(scenario, vp)
        assert fence.ceiling_m == top and breaches(fence, vp) == []  # off a site, home = the origin's ground
        high = copy.deepcopy(vp)
        high.path[len(high.path) // 2, 2] = top + 5.0
        assert breaches(fence, high) == [
            f"climbs to {top + 5:.1f} m above home, over the fence ceiling {top:.1f} m"
        ]


def test_export_writes_each_vehicle_its_own_fence_and_refuses_a_plan_out_of_bounds(demo, tmp_path, capsys):
    scenario, plan = demo
    plan.save(tmp_path / "plan.json")
    out = tmp_path / "out"
    argv = [
        "export",
        str(tmp_path / "plan.json"),
        "--scenario",
        str(MISSIONS / "swarm_small.toml"),
        "-o",
        str(out),
    ]
    assert main(argv) == 0
    printed = capsys.readouterr().out
    for vp in plan.vehicles:
        mf = load_mission_file(out / f"{vp.vehicle_id}.plan")
        circles = [it for it in mf.fence if it.command == 5004]  # NAV_FENCE_CIRCLE_EXCLUSION
        assert len(circles) == len(vehicle_geofence(scenario, vp).exclusions)
        assert len(circles) + len(overflown(scenario, vp)) == len(scenario.cylinders) + len(
            scenario.hemispheres
        )
    assert "flies over cylinder" in printed
    text = (MISSIONS / "swarm_small.toml").read_text()
    assert "x = [-100.0, 600.0]" in text
    small = tmp_path / "small.toml"
    small.write_text(text.replace("x = [-100.0, 600.0]", "x = [-100.0, 300.0]"))  # the goals lie beyond
    assert (
        main(["export", str(tmp_path / "plan.json"), "--scenario", str(small), "-o", str(tmp_path / "o2")])
        == 2
    )
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "leaves the inclusion fence" in err[0], err
    assert not (tmp_path / "o2").exists() or not any((tmp_path / "o2").iterdir())
    assert "fence ceiling" not in printed  # no [bounds] z, no ceiling
    capped = tmp_path / "capped.toml"
    capped.write_text(text.replace("x = [-100.0, 600.0]", "x = [-100.0, 600.0]\nz = [0.0, 150.0]"))
    assert (
        main(["export", str(tmp_path / "plan.json"), "--scenario", str(capped), "-o", str(tmp_path / "o3")])
        == 0
    )
    printed = capsys.readouterr().out
    assert printed.count(
        "fence ceiling 150 m above home: not in the file, the parameter FENCE_ALT_MAX"
    ) == len(plan.vehicles)
