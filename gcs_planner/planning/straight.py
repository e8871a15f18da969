"""Straight-line baseline: climb over the start, fly straight to the goal at cruise altitude.

Useful as the simplest plan that still exercises the whole chain (missions, flight, logging);
it ignores obstacles and other vehicles, and says so in each vehicle's notes.
"""

from __future__ import annotations

from typing import Annotated

import numpy as np
from msgspec import Meta

from gcs_planner.core.validation import MAX_RADIUS_M, MAX_WAYPOINTS
from gcs_planner.model.plan import Plan, VehiclePlan
from gcs_planner.model.scenario import Scenario, ScenarioError
from gcs_planner.planning import PlannerConfig, Progress, Traits

NAME = "straight"
TRAITS = Traits()  # start to goal, nothing avoided


class Config(PlannerConfig, tag=NAME):
    waypoint_spacing_m: Annotated[float, Meta(ge=1.0, le=MAX_RADIUS_M)] = 100.0  # between mission items


def plan(
    scenario: Scenario, config: Config, rng: np.random.Generator, progress: Progress | None = None
) -> Plan:
    del rng  # deterministic
    spacing_m = config.waypoint_spacing_m
    vehicles = []
    for v in scenario.vehicles:
        start, goal = np.asarray(v.start), np.asarray(v.goal)
        legs = max(1, int(np.ceil(np.linalg.norm(goal - start) / spacing_m)))
        if legs > MAX_WAYPOINTS:
            raise ScenarioError(
                f"planner.waypoint_spacing_m = {spacing_m:g} gives {v.id} {legs} legs (max {MAX_WAYPOINTS})"
            )
        waypoints = start + np.linspace(0.0, 1.0, legs + 1)[:, None] * (goal - start)
        seg = np.linalg.norm(np.diff(waypoints, axis=0), axis=1)
        times = np.concatenate([[0.0], np.cumsum(seg) / v.speed_mps])
        vehicles.append(
            VehiclePlan(
                vehicle_id=v.id,
                sysid=v.sysid,
                vehicle_type=v.type,
                waypoints=waypoints,
                times_s=times,
                speeds_mps=np.full(len(times), v.speed_mps),
                path=waypoints,
                path_times_s=times,
                turn_radius_m=v.turn_radius_m,
                cost={"length_m": float(seg.sum())},
                notes=["straight-line baseline: obstacles and other vehicles not considered"],
            )
        )
        if progress:
            progress(len(vehicles) / len(scenario.vehicles), v.id)
    return Plan(origin=scenario.origin, planner=NAME, vehicles=vehicles)
