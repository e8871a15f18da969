"""ArduCopter's waypoint navigation for one mock copter (ArduPilot AC_WPNav.cpp, master 64a9c787).

What AC_WPNav does with the legs of sitl_mock.scurve: `init` where the copter hovers
(``wp_and_spline_init_m``: jerk and snap from WP_JERK and ATC_INPUT_TC), `set_destination`
(``set_wp_destination_NED_m``: the leg preloaded by `set_destination_next` becomes this one, its
motion so far kept), `set_speed` (``set_speed_NE_ms``: this leg and the next re-planned) and
`update` (``advance_wp_target_along_track``: the position target after ``dt``, its time slowed
while the copter trails it; a fast waypoint is reached half way through its turn, the last one at
its end within WP_RADIUS_M). `acceleration` is AC_PosControl's demand to follow that target; the
airframe's response to it is sitl_mock.flight's. Limits are read from the vehicle's parameters
when a leg is planned, so a PARAM_SET of WP_ACC changes the next leg, as on the autopilot;
WP_JERK and ATC_INPUT_TC apply from the next `init`.
"""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np

from sitl_mock.scurve import SCurve

__all__ = ["STOCK_PARAMS", "WaypointNav"]

# ArduCopter 4.8's stock values (AC_WPNav.cpp, AC_AttitudeControl.cpp): served by an S-curve copter
STOCK_PARAMS = {
    "WP_ACC": 2.5,
    "WP_JERK": 1.0,
    "WP_ACC_Z": 1.0,
    "WP_ACC_CNR": 0.0,
    "WP_RADIUS_M": 2.0,
    "ATC_INPUT_TC": 0.15,
    "ATC_ACCEL_R_MAX": 110000.0,
    "ATC_ACCEL_P_MAX": 110000.0,
    "ATC_ANGLE_MAX": 30.0,
    "PSC_NE_POS_P": 1.0,
    "PSC_NE_VEL_P": 2.0,
}
WP_SPD_MIN = 0.01  # [m/s]
WP_RADIUS_M_MIN = 0.05  # [m]
G_MPS2 = 9.80665


class WaypointNav:
    """The position target of one copter flying waypoints in AUTO."""

    def __init__(self, params: Mapping[str, float]) -> None:
        self.params = params  # the vehicle's own, read live
        self.init(np.zeros(3), 0.0)

    def init(self, stopping_point: np.ndarray, speed_mps: float) -> None:
        """Start from rest at ``stopping_point`` at horizontal speed ``speed_mps``."""
        p = self.params
        self.speed_xy = max(speed_mps, WP_SPD_MIN)
        jerk = p["WP_JERK"] if p["WP_JERK"] > 0 else p["WP_ACC"]
        self.jerk_max = jerk  # ATC_RATE_R_MAX / _P_MAX are 0 (unlimited) by default: WP_JERK stands
        snap = jerk * math.pi / (2.0 * max(p["ATC_INPUT_TC"], 0.1))
        accel_rp_radss = math.radians(min(p["ATC_ACCEL_R_MAX"], p["ATC_ACCEL_P_MAX"]) * 0.01)
        if accel_rp_radss > 0:
            snap = min(snap, accel_rp_radss * G_MPS2)
        self.snap_max = 0.5 * snap
        self.prev_leg, self.this_leg, self.next_leg = SCurve(), SCurve(), SCurve()
        self.reached_destination, self.fast_waypoint = True, False
        self.origin = self.destination = np.asarray(stopping_point, dtype=float).copy()
        self.track_dt_scalar = 1.0
        self.target = [self.origin.copy(), np.zeros(3), np.zeros(3)]  # position, velocity, acceleration

    def set_destination(self, destination: np.ndarray) -> None:
        """Fly from the last destination to ``destination``."""
        self.prev_leg = self.this_leg
        self.origin, self.destination = self.destination, np.asarray(destination, dtype=float).copy()
        if self.fast_waypoint and not self.next_leg.finished():
            self.this_leg = self.next_leg
        else:
            self.this_leg = self._leg(self.origin, self.destination)
        self.next_leg = SCurve()
        self.fast_waypoint = self.reached_destination = False

    def set_destination_next(self, destination: np.ndarray) -> None:
        """Preload the leg after this one: the copter passes this destination without stopping."""
        self.next_leg = self._leg(self.destination, np.asarray(destination, dtype=float))
        self.fast_waypoint = True

    def set_speed(self, speed_mps: float) -> None:
        """A new horizontal speed: this leg and the next are re-planned from where they are."""
        if speed_mps < WP_SPD_MIN:
            return
        self.speed_xy = speed_mps
        up, down = self.params["WP_SPD_UP"], self.params["WP_SPD_DN"]
        self.this_leg.set_speed_max(speed_mps, up, down)
        self.next_leg.set_speed_max(speed_mps, up, down)

    def update(self, dt_s: float, position: np.ndarray, velocity: np.ndarray) -> tuple[np.ndarray, ...]:
        """(position, velocity, acceleration) of the target ``dt_s`` later, for a copter now at
        ``position`` with ground ``velocity``: the target's time runs slower while the copter
        trails it (``_track_dt_scalar``, filtered over WP_ACC / WP_JERK); sets reached_destination."""
        p = self.params
        scalar = 1.0
        speed = float(np.linalg.norm(self.target[1]))
        if speed > 0:
            along = self.target[1] / speed
            behind_m = float(np.dot(self.target[0] - position, along))
            scalar = 0.05 + (float(np.dot(velocity, along)) - p["PSC_NE_POS_P"] * behind_m) / speed
            scalar = min(max(scalar, 0.0), 1.0)
        tc = p["WP_ACC"] / p["WP_JERK"] if p["WP_JERK"] > 0 else 1.0
        self.track_dt_scalar += (scalar - self.track_dt_scalar) * (dt_s / tc)
        target = [self.origin.copy(), np.zeros(3), np.zeros(3)]
        radius = max(p["WP_RADIUS_M"], WP_RADIUS_M_MIN)
        finished = self.this_leg.advance_target_along_track(
            self.prev_leg, self.next_leg, radius, self._corner_accel(), self.fast_waypoint,
            self.track_dt_scalar * dt_s, target,
        )  # fmt: skip
        self.target = target
        if finished and (self.fast_waypoint or np.linalg.norm(position - self.destination) <= radius):
            self.reached_destination = True  # a fast waypoint half way through its turn
        return target[0], target[1], target[2]

    def acceleration(self, position: np.ndarray, velocity: np.ndarray) -> np.ndarray:
        """The position controller's demand for the copter to follow its target (AC_PosControl:
        the target's acceleration, plus PSC_NE_VEL_P x the velocity error, the velocity demand
        being the target's plus PSC_NE_POS_P x the position error), within the lean ANGLE_MAX allows."""
        p = self.params
        pos, vel, accel = self.target
        demand = accel + p["PSC_NE_VEL_P"] * (vel + p["PSC_NE_POS_P"] * (pos - position) - velocity)
        limit = G_MPS2 * math.tan(math.radians(p["ATC_ANGLE_MAX"]))
        horizontal = math.hypot(demand[0], demand[1])
        if horizontal > limit:
            demand[:2] *= limit / horizontal
        return demand

    def _corner_accel(self) -> float:
        cnr = self.params["WP_ACC_CNR"]
        return cnr if cnr > 0 else 2.0 * self.params["WP_ACC"]

    def _leg(self, origin: np.ndarray, destination: np.ndarray) -> SCurve:
        p = self.params
        leg = SCurve()
        leg.calculate_track(
            origin,
            destination,
            self.speed_xy,
            p["WP_SPD_UP"],
            p["WP_SPD_DN"],
            p["WP_ACC"],
            p["WP_ACC_Z"],
            self.snap_max,
            self.jerk_max,
        )
        return leg
