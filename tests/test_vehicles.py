"""Vehicle sources: the mock comes through the installed entry point, connected vehicles take no
mock-only fault, and both refuse before anything is sent."""

from __future__ import annotations

import asyncio
from pathlib import Path

import pytest

from gcs_planner.core.errors import UserError
from gcs_planner.flight import FlyOptions, fly
from gcs_planner.flight.vehicles import ConnectedVehicles, mock_vehicles
from gcs_planner.planning import load_scenario, plan_scenario
from sitl_mock.plan_fleet import MockVehicles, MockVehiclesProcess

SCENARIO = Path(__file__).resolve().parents[1] / "missions" / "straight_4uav.toml"


def test_the_entry_points_name_the_mock_fleets():
    scenario = load_scenario(SCENARIO)
    plan = plan_scenario(scenario)
    assert isinstance(mock_vehicles("mock", plan.vehicles, origin=plan.origin), MockVehicles)
    assert isinstance(mock_vehicles("mock-process", plan.vehicles, origin=plan.origin), MockVehiclesProcess)
    known = r"no vehicle source 'px4-sitl' is installed \(known: \['mock', 'mock-process'\]\)"
    with pytest.raises(UserError, match=known):
        mock_vehicles("px4-sitl", plan.vehicles)


def test_drift_on_connected_vehicles_is_refused_before_anything_is_sent(tmp_path):
    scenario = load_scenario(SCENARIO)
    plan = plan_scenario(scenario)
    vehicles = ConnectedVehicles(["udpout:127.0.0.1:9"])  # nothing listens: a send would time out
    options = FlyOptions(out_dir=tmp_path / "out", drift_mps={plan.vehicles[0].sysid: (1.0, 0.0)})
    with pytest.raises(UserError, match="--drift injects a fault into mock vehicles"):
        asyncio.run(fly(scenario, plan, options, vehicles))
    assert not (tmp_path / "out").exists()
