"""Online coalition task planning (seed 003): contract net under link limits, division-of-labour ACO,
synchronised Dubins arrivals. Registered as planner "coalition".

``plan(scenario, config, rng, progress)`` runs the event-driven simulation of the whole scenario
(model.py, sim.py) and returns a Plan holding each UAV's whole flown track (recon, tasks, loiter)
with ``Plan.events`` = the timeline (tenders, bids, awards, strikes, ...).

For live (HIL) use: ``simulate(world, rng)`` gives a SimResult whose ``events`` include one
"award" per member (time, vehicle, sysid, target, task, attack angle, entry point, awarded time)
and whose ``award_legs[(target_id, uav_id)]`` is the planned leg; ``leg_vehicle_plan`` turns a
leg into a VehiclePlan (ENU waypoints, times, speeds) that can be uploaded as a new mission while
the swarm flies.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from gcs_planner.model.plan import Plan, VehiclePlan
from gcs_planner.model.scenario import Extensions, Scenario
from gcs_planner.planning import Progress, Traits
from gcs_planner.planning.coalition.model import CoalitionParams, UavSpec, World, load_world
from gcs_planner.planning.coalition.sim import CoalitionSim, SimResult
from gcs_planner.planning.coalition.track import Leg

__all__ = [
    "TRAITS",
    "NAME", "CoalitionParams", "Config", "SimResult", "World", "leg_vehicle_plan", "load_world", "plan",
    "simulate",
]  # fmt: skip


def simulate(world: World, rng: np.random.Generator) -> SimResult:
    """Run the event simulation to world.params.t_end_s (or until nothing is left to happen)."""
    return CoalitionSim(world, rng).run()


def leg_vehicle_plan(
    leg: Leg, uav: UavSpec, waypoint_dt_s: float = 2.0, t_offset_s: float = 0.0
) -> VehiclePlan:
    """A VehiclePlan for one leg: waypoints every waypoint_dt_s of flight (and the leg's end),
    times relative to t_offset_s (e.g. the upload's mission start), constant speed, then loiter."""
    t = leg.t - t_offset_s
    keep = np.unique(
        np.r_[np.searchsorted(t, np.arange(t[0], t[-1], waypoint_dt_s), side="right") - 1, len(t) - 1]
    )
    z = np.full(len(t), uav.altitude_m)
    path = np.column_stack([leg.xy, z])
    return VehiclePlan(
        vehicle_id=uav.id,
        sysid=uav.sysid,
        vehicle_type="fixed_wing",
        waypoints=path[keep],
        times_s=t[keep],
        speeds_mps=np.full(len(keep), uav.speed_mps),
        path=path,
        path_times_s=t,
        turn_radius_m=uav.r_min_m,
        final_action="loiter",
        acceptance_radius_m=max(10.0, uav.speed_mps),
        cost={"length_m": float(np.hypot(*np.diff(leg.xy, axis=0).T).sum())},
        notes=[f"coalition {leg.kind} leg", *(f"{k}={v}" for k, v in leg.info.items())],
    )


NAME = "coalition"
# decides tasks in flight; its [coalition] table of targets and threats, its vehicles' capabilities
TRAITS = Traits(
    online=True,
    extensions=Extensions(
        tables={
            "coalition": (
                ("targets", "threats"),
                {
                    "targets": ("id", "approx", "position", "appear_s", "recon_s", "recon_angle_deg")
                    + ("recon_uav", "strike_timing", "strike_interval_s", "strike_angles_deg")
                    + ("assess_angles_deg", "assess_delay_s", "assess_duration_s", "reward", "decay_per_s"),
                    "threats": ("x", "y", "radius_m", "appear_s"),
                },
            )
        },
        vehicle_keys=("capabilities", "munitions", "heading_deg", "range_m"),
    ),
)
Config = CoalitionParams


def check_options(scenario: Scenario, config: Config) -> dict:
    """The one checker skips the scenario vehicles' turn radius, speed and climb angle: the planes
    follow the event simulation's own flight model. Obstacles, separation, band and site hold."""
    del scenario, config
    return {"kinematics": False, "max_climb_rad": math.pi / 2}


def plan(
    scenario: Scenario, config: Config, rng: np.random.Generator, progress: Progress | None = None
) -> Plan:
    """The event simulation's tracks as a Plan (the offline reference; fly-coalition flies it)."""
    world = replace(load_world(scenario), params=config)
    if progress:
        progress(0.0, "simulating coalition formation")
    result = simulate(world, rng)
    t_last = max((e["t_s"] for e in result.events), default=0.0)
    t_end = min(world.params.t_end_s, t_last + 20.0)
    vehicles = []
    for u, track in zip(world.uavs, result.tracks):
        t, xy, legs = track.history(t_end)
        leg = Leg(t, xy, np.zeros(len(t)), "whole")
        vp = leg_vehicle_plan(leg, u, waypoint_dt_s=4.0)
        vp.notes = [" ".join(sorted({lg.kind for lg in legs}))]
        st = result.states[u.index]
        vp.cost = {
            "length_m": vp.cost["length_m"],
            "strikes": float(st.strikes),
            "munitions_left": float(st.munitions),
        }
        vp.feasible = all(lg.info.get("clear", True) for lg in legs)
        vehicles.append(vp)
    if progress:
        progress(1.0, "done")
    metrics = {
        "effectiveness": result.effectiveness,
        "completion_s": result.completion_s,
        "compute_s": result.compute_s,
        "targets": {
            k: {
                "J": o.J,
                "revealed_s": o.t_revealed_s,
                "formed_s": o.t_formed_s,
                "done_s": o.t_done_s,
                "tenders": o.tenders,
                "members": list(o.members),
                "sync_error_s": o.sync_error_s,
            }
            for k, o in result.outcomes.items()
        },
    }
    return Plan(
        origin=scenario.origin, planner="coalition", vehicles=vehicles, metrics=metrics, events=result.events
    )
