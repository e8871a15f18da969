"""Schedule keeping: hold each vehicle to its planned timing by adjusting its speed in flight.

Autopilots fly mission legs in space, not in time: they slow for corners, accelerate at their own
rate and hold no schedule, so a plan whose separation depends on timing (priority planning,
4-D deconfliction, synchronised arrivals) drifts apart in the air. The GCS closes that loop the
way a 4-D trajectory manager does: from each position report it finds how far along its planned
path the vehicle is, compares that with where the plan says it should be at this instant, and
commands a ground speed (MAV_CMD_DO_CHANGE_SPEED, param1 = 1 ground speed) that removes the
along-track error over ``horizon_s``, or over the vehicle's own response time where that is longer
(``add(response_s=...)``): ArduCopter re-plans a leg's speed on a jerk-limited S-curve that takes
3-4 s to settle, and a keeper that asks again before then overshoots into an oscillation
(docs/sitl-mock.md, "ArduCopter's S-curve legs").

Choices: no command while a route's start ramp lasts (``settle_s`` after its planned start): the
route starts early by its ramp's loss (flight.ops.accel_lead_s), so on the ramp the vehicle is
first ahead of the plan and then behind it by design; correcting that made ArduCopter overshoot
into a slow-down that its next leg kept to its end (docs/real-autopilots.md). Progress is the
arc length of the nearest planned-path point, searched only ahead of the last progress (paths may
cross themselves); the commanded speed is clamped to [``min_factor``, ``max_factor``] x the
planned speed there, and to the vehicle's own speed range where it has one (``limit``: ArduPlane
refuses an airspeed outside it and keeps the old one); a new command is sent only when it differs
from the last by more than ``deadband_mps`` (set-points are periodic, so a lost one is replaced
by the next rather than retried).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from gcs_planner.model.plan import VehiclePlan

__all__ = ["ScheduleKeeper"]

LOOKAHEAD_SAMPLES = 60  # path samples searched ahead of the last progress


@dataclass
class _Route:
    path: np.ndarray
    times_s: np.ndarray
    arc_m: np.ndarray
    speed_mps: np.ndarray
    quiet_until_s: float  # route time before which no command is sent (the start ramp)
    horizon_s: float  # the along-track error is removed over this [s]
    index: int = 0
    last_command_mps: float = float("nan")


@dataclass
class ScheduleKeeper:
    """Speed set-points that keep vehicles on their planned timing (see module docstring)."""

    horizon_s: float = 2.0
    min_factor: float = 0.5
    max_factor: float = 1.3
    deadband_mps: float = 0.2
    routes: dict[int, _Route] = field(default_factory=dict)
    ranges: dict[int, tuple[float, float]] = field(default_factory=dict)  # sysid: (lo, hi) [m/s]

    def limit(self, sysid: int, lo_mps: float, hi_mps: float) -> None:
        """Keep the vehicle's commands within [lo_mps, hi_mps] (its autopilot's speed range)."""
        self.ranges[sysid] = (lo_mps, hi_mps)

    def add(self, vp: VehiclePlan, settle_s: float = 0.0, response_s: float = 0.0) -> None:
        """Keep ``vp`` to its timing, from ``settle_s`` after its planned start (its start ramp),
        removing an error over ``horizon_s`` or ``response_s`` (how long the vehicle takes to
        reach a commanded speed), whichever is longer."""
        seg = np.linalg.norm(np.diff(vp.path, axis=0), axis=1)
        arc = np.concatenate([[0.0], np.cumsum(seg)])
        dt = np.diff(vp.path_times_s)
        speed = np.divide(seg, dt, out=np.zeros_like(seg), where=dt > 1e-9)
        speeds = np.concatenate([speed, speed[-1:]])
        quiet_until_s = float(vp.times_s[0]) + settle_s
        self.routes[vp.sysid] = _Route(
            vp.path, vp.path_times_s, arc, speeds, quiet_until_s, max(self.horizon_s, response_s)
        )

    def along_track_error_m(self, sysid: int, t_s: float, position: np.ndarray) -> float:
        """Planned minus flown arc length [m] at route time ``t_s`` (positive: behind schedule)."""
        route = self.routes[sysid]
        flown_arc = self._progress_m(route, np.asarray(position, dtype=float))
        return float(np.interp(t_s, route.times_s, route.arc_m)) - flown_arc

    @staticmethod
    def _progress_m(route: _Route, position: np.ndarray) -> float:
        """Arc length [m] of the position's projection on the path, searched ahead of the last one."""
        hi = min(route.index + LOOKAHEAD_SAMPLES, len(route.path) - 1)
        if hi <= route.index:
            return float(route.arc_m[-1])
        a, b = route.path[route.index : hi], route.path[route.index + 1 : hi + 1]
        ab = b - a
        u = np.clip(((position - a) * ab).sum(axis=1) / np.maximum((ab**2).sum(axis=1), 1e-12), 0.0, 1.0)
        d = np.linalg.norm(a + u[:, None] * ab - position, axis=1)
        k = int(np.argmin(d))
        route.index += k
        return float(
            route.arc_m[route.index] + u[k] * (route.arc_m[route.index + 1] - route.arc_m[route.index])
        )

    def speed_command(self, sysid: int, t_s: float, position: np.ndarray) -> float | None:
        """Ground speed [m/s] to command now, or None when the last command still stands."""
        route = self.routes[sysid]
        error_m = self.along_track_error_m(sysid, t_s, position)  # (keeps the progress search moving)
        if t_s < route.quiet_until_s:
            return None
        nominal = float(route.speed_mps[route.index])
        if nominal <= 0.0:
            return None
        command = float(
            np.clip(nominal + error_m / route.horizon_s, self.min_factor * nominal, self.max_factor * nominal)
        )
        if sysid in self.ranges:
            command = float(np.clip(command, *self.ranges[sysid]))
        if abs(command - route.last_command_mps) <= self.deadband_mps:
            return None
        route.last_command_mps = command
        return command
