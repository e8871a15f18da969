"""The Plan: what every planner returns and what the MAVLink adaptor turns into missions.

All positions are local ENU metres about ``Plan.origin`` (see gcs_planner.core.geo), times are
seconds from the mission start, speeds m/s. A plan serialises to plain JSON (plan.json).
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from gcs_planner.core.geo import Origin
from gcs_planner.core.validation import InputError, load_json, read_text, unique, write_text_atomic

__all__ = ["LAND_GLIDE_DEG", "Plan", "VehiclePlan", "land_point"]

LAND_GLIDE_DEG = 5.0  # a fixed wing's final approach: its glide slope [deg]


@dataclass
class VehiclePlan:
    """One vehicle's planned flight.

    waypoints: (N, 3) ENU [m] the vehicle must pass, start first; becomes mission waypoints.
    times_s: (N,) planned arrival time at each waypoint [s from mission start].
    speeds_mps: (N,) ground speed on the leg that ends at each waypoint [m/s] (entry 0 unused).
    path: (M, 3) the smoothed (e.g. Dubins) path sampled densely [m]; what the vehicle should fly.
    path_times_s: (M,) time at each path sample [s].
    takeoff_delay_s: hold on the ground this long after the fleet start (delayed take-off).
    final_action: "land", "rtl" or "loiter" after the last waypoint.
    acceptance_radius_m: waypoint acceptance radius given to the autopilot.
    cost: named cost terms of the planner; feasible: the one plan checker's verdict, set by
    plan_scenario (gcs_planner.safety.separation.certify), whose findings are ``check:`` notes.
    altitude_frame: how the mission gives altitudes: "relative" to home (home at the origin's
    altitude: the default), or "amsl" (z + the origin's altitude), for plans over a site's terrain,
    where each vehicle's home is on its own ground (gcs_planner.missions.items).
    """

    vehicle_id: str
    sysid: int
    waypoints: np.ndarray
    times_s: np.ndarray
    speeds_mps: np.ndarray
    path: np.ndarray
    path_times_s: np.ndarray
    vehicle_type: str = "multirotor"
    turn_radius_m: float = 0.0
    takeoff_delay_s: float = 0.0
    final_action: str = "land"
    acceptance_radius_m: float = 2.0
    cost: dict[str, float] = field(default_factory=dict)
    feasible: bool = True
    notes: list[str] = field(default_factory=list)
    altitude_frame: str = "relative"

    def __post_init__(self) -> None:
        self.waypoints = np.asarray(self.waypoints, dtype=float).reshape(-1, 3)
        self.times_s = np.asarray(self.times_s, dtype=float).reshape(-1)
        self.speeds_mps = np.asarray(self.speeds_mps, dtype=float).reshape(-1)
        self.path = np.asarray(self.path, dtype=float).reshape(-1, 3)
        self.path_times_s = np.asarray(self.path_times_s, dtype=float).reshape(-1)
        n = len(self.waypoints)
        if len(self.times_s) != n or len(self.speeds_mps) != n:
            raise ValueError(
                f"vehicle {self.vehicle_id}: waypoints ({n}), times_s ({len(self.times_s)}) and"
                f" speeds_mps ({len(self.speeds_mps)}) must have the same length"
            )
        if len(self.path) != len(self.path_times_s):
            raise ValueError(
                f"vehicle {self.vehicle_id}: path ({len(self.path)}) and path_times_s"
                f" ({len(self.path_times_s)}) must have the same length"
            )

    @property
    def first_leg_speed_mps(self) -> float:
        """The speed it leaves its start at [m/s] (the first leg's; a one-point plan's own)."""
        return float(self.speeds_mps[1] if len(self.speeds_mps) > 1 else self.speeds_mps[0])

    def to_dict(self) -> dict:
        frame = {} if self.altitude_frame == "relative" else {"altitude_frame": self.altitude_frame}
        return {
            "vehicle_id": self.vehicle_id,
            "sysid": self.sysid,
            "vehicle_type": self.vehicle_type,
            "turn_radius_m": self.turn_radius_m,
            "takeoff_delay_s": self.takeoff_delay_s,
            "final_action": self.final_action,
            "acceptance_radius_m": self.acceptance_radius_m,
            "waypoints": self.waypoints.round(4).tolist(),
            "times_s": self.times_s.round(4).tolist(),
            "speeds_mps": self.speeds_mps.round(4).tolist(),
            "path": self.path.round(4).tolist(),
            "path_times_s": self.path_times_s.round(4).tolist(),
            "cost": self.cost,
            "feasible": self.feasible,
            "notes": self.notes,
            **frame,
        }

    @classmethod
    def from_dict(cls, d: dict) -> VehiclePlan:
        """One entry of plan.json's ``vehicles``, every field checked (plan_checks)."""
        from gcs_planner.model.plan_checks import vehicle_fields

        return cls(**vehicle_fields(d))


@dataclass
class Plan:
    """A planner's output for the whole fleet."""

    origin: Origin
    planner: str
    vehicles: list[VehiclePlan]
    metrics: dict = field(default_factory=dict)
    events: list[dict] = field(default_factory=list)

    @property
    def feasible(self) -> bool:
        return all(v.feasible for v in self.vehicles)

    def vehicle(self, vehicle_id: str) -> VehiclePlan:
        for v in self.vehicles:
            if v.vehicle_id == vehicle_id:
                return v
        raise KeyError(f"no vehicle {vehicle_id!r} in plan")

    def to_dict(self) -> dict:
        return {
            "origin": {
                "lat_deg": self.origin.lat_deg,
                "lon_deg": self.origin.lon_deg,
                "alt_m": self.origin.alt_m,
            },
            "planner": self.planner,
            "metrics": self.metrics,
            "events": self.events,
            "vehicles": [v.to_dict() for v in self.vehicles],
        }

    @classmethod
    def from_dict(cls, d: dict) -> Plan:
        """plan.json's content -> Plan; InputError (one line) for any bad field (plan_checks)."""
        from gcs_planner.model.plan_checks import plan_fields

        origin, planner, rows, metrics, events = plan_fields(d)
        vehicles = []
        for i, row in enumerate(rows):
            try:
                vehicles.append(VehiclePlan.from_dict(row))
            except InputError as exc:
                raise InputError(f"vehicles[{i}]: {exc}") from None
        unique([v.vehicle_id for v in vehicles], "vehicle_id")
        unique([v.sysid for v in vehicles if v.sysid], "sysid")
        return cls(origin=origin, planner=planner, vehicles=vehicles, metrics=metrics, events=events)

    def to_json(self) -> str:
        return json.dumps(self.to_dict(), separators=(",", ":"))

    def save(self, path: str | Path) -> None:
        """Write plan.json atomically (a failed write leaves the old file, or none)."""
        write_text_atomic(path, self.to_json())

    @classmethod
    def load(cls, path: str | Path) -> Plan:
        """Read and check plan.json; every problem is one InputError line naming the file."""
        data = load_json(read_text(path, "plan"), str(path))
        try:
            return cls.from_dict(data)
        except InputError as exc:
            raise InputError(f"{path}: {exc}") from None


def land_point(vp: VehiclePlan) -> np.ndarray:
    """Where a vehicle whose final action is "land" touches down (ENU [m], on the ground): under
    its last waypoint for a multirotor; for a fixed wing, ahead of it along the last leg by the
    run of a LAND_GLIDE_DEG glide from the waypoint's altitude, so that the approach is one a
    plane can fly (ArduPlane descends on the line from the previous waypoint to the land point and
    flares near the ground; a land point under the last waypoint made SITL planes flare at 60 m
    and touch down 500-600 m further on)."""
    last = vp.waypoints[-1]
    if vp.vehicle_type != "fixed_wing" or len(vp.waypoints) < 2:
        return np.array([last[0], last[1], 0.0])
    leg = last[:2] - vp.waypoints[-2][:2]
    length = float(np.hypot(*leg))
    heading = leg / length if length > 1e-9 else np.array([1.0, 0.0])
    run = max(float(last[2]), 0.0) / np.tan(np.radians(LAND_GLIDE_DEG))
    return np.array([*(last[:2] + run * heading), 0.0])
