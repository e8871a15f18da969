"""Kinematic flight models, stepped for every vehicle of a fleet at once with numpy.

State lives in arrays indexed by vehicle (`Kinematics`); one `step(dt_s)` advances all vehicles,
multirotors and fixed wings together, and `arrived()` tells which vehicles reached what their
guidance was waiting for, so the per-vehicle Python logic runs only on events.

Frame: local ENU [m] about the fleet origin (x east, y north, z up = altitude above the origin);
heading ``psi`` [rad] counter-clockwise from east (project convention). Fully deterministic:
fixed step, no randomness.

Models (choices where the brief leaves them open):
- Multirotor: a velocity command towards the target, capped by the commanded speed, by
  ``sqrt(2 a d)`` when it must stop at the target (so it brakes within the acceleration limit),
  and by ``KP_POS * d`` near it; velocity changes limited to ``accel_mps2`` per second,
  horizontal speed to ``max_speed_mps``, climb/sink to their limits. Yaw follows the velocity.
  Pass-through waypoints: the vehicle slows to a corner speed ``sqrt(a r / tan(theta / 2))``
  (theta = turn to the next leg, r = acceptance radius; the navigator computes it), so the turn
  under the acceleration limit stays close to the corner, like ArduCopter's corner speed limit.
- Multirotor in TRACK (``wpnav`` rows: ArduCopter's S-curve legs, sitl_mock.wpnav): the
  position controller's demand towards the row's target, the acceleration lagging it by
  ``RESPONSE_TAU_S`` (docs/sitl-mock.md, "ArduCopter's S-curve legs").
- Fixed wing: constant airspeed (the commanded speed, clamped to [min, max]); heading rate
  limited to ``g tan(max_bank) / v``, which bounds the turn radius below by ``v^2 / (g tan
  max_bank)``; climb/sink rate limited, horizontal speed ``sqrt(v^2 - vz^2)``. Between
  waypoints it turns towards the target (pursuit, the planner's own model), or, with an ``l1``
  response, tracks the line from the previous waypoint as ArduPlane's L1 controller does
  (sitl_mock.l1, the mock's own copy of ``AP_L1_Control::update_waypoint``, the previous waypoint
  as the line's start, ``Plane::set_next_WP``), its bank lagging the demand and its turn at the
  airframe's gain (``l1.SITL_PLANE``: fitted to ArduPlane SITL's plane). The L1
  plane flies arcs wide and overshoots a turn onto a new line, as ArduPlane SITL does
  (docs/coalition.md). Loiter is a
  clockwise circle (ArduPilot's default direction): turn-rate feed-forward ``v / R`` plus a
  lateral correction ``atan(K_CIRCLE (d - R) / R)``. Landing spirals down on the loiter circle
  at ``land_speed_mps``.
- Wind [m/s] is added to the ground velocity and not compensated by the guidance's heading, so
  it bends the track while the closed loop still reaches each target. ``drift_mps`` integrates
  into an offset between the navigated and the reported position: a navigation drift the
  vehicle does not see, the fault conformance checks must catch.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum

import numpy as np

from sitl_mock.geodesy import wrap_pi
from sitl_mock.l1 import L1Plane, l1_lateral_accel
from sitl_mock.wpnav import WaypointNav

__all__ = ["AIRFRAMES", "Airframe", "Arrival", "Guidance", "Kinematics", "climb_run_m"]

G_MPS2 = 9.80665
KP_POS = 1.0  # [1/s] position -> velocity gain near a stop point
KP_ALT = 1.0  # [1/s] altitude error -> climb rate gain
KP_PSI = 1.5  # [1/s] heading error -> turn rate gain (saturates at the bank limit)
K_CIRCLE = 2.0  # loiter circle radial correction gain [-]
GROUND_TOL_M = 0.05  # touchdown when within this height of the ground
ALT_TOL_M = 0.5  # takeoff reaches its altitude within this tolerance
LINE_MIN_H_M = 1.0  # below this horizontal distance to the target a leg is flown as a vertical move
RESPONSE_TAU_S = 0.8  # TRACK: the airframe's acceleration lags the demand (fitted to ArduCopter SITL)


@dataclass(frozen=True)
class Airframe:
    """Limits of one vehicle type (SI units)."""

    kind: str
    cruise_speed_mps: float
    max_speed_mps: float
    min_speed_mps: float
    accel_mps2: float
    max_bank_rad: float
    climb_rate_mps: float
    sink_rate_mps: float
    land_speed_mps: float
    accept_radius_m: float
    loiter_radius_m: float
    l1: L1Plane | None = None  # fixed wing: None = pursuit; else ArduPlane's L1 guidance, flown so

    @property
    def min_turn_radius_m(self) -> float:
        """Tightest turn at cruise speed [m] (fixed wing; 0 for a multirotor)."""
        if self.kind != "fixed_wing":
            return 0.0
        return self.cruise_speed_mps**2 / (G_MPS2 * np.tan(self.max_bank_rad))


# Defaults near ArduPilot's: WPNAV_SPEED 10 m/s, WPNAV_ACCEL 2.5 m/s^2, WPNAV_RADIUS 2 m,
# LAND_SPEED 0.5 m/s (copter); AIRSPEED_CRUISE 22, ROLL_LIMIT 45 deg, TECS_CLMB_MAX 5 m/s (plane).
AIRFRAMES: dict[str, Airframe] = {
    "multirotor": Airframe(
        kind="multirotor",
        cruise_speed_mps=10.0,
        max_speed_mps=15.0,
        min_speed_mps=0.0,
        accel_mps2=2.5,
        max_bank_rad=np.radians(30.0),
        climb_rate_mps=2.5,
        sink_rate_mps=1.5,
        land_speed_mps=1.0,
        accept_radius_m=2.0,
        loiter_radius_m=0.0,
    ),
    "fixed_wing": Airframe(
        kind="fixed_wing",
        cruise_speed_mps=20.0,
        max_speed_mps=30.0,
        min_speed_mps=12.0,
        accel_mps2=2.0,
        max_bank_rad=np.radians(45.0),
        climb_rate_mps=5.0,
        sink_rate_mps=4.0,
        land_speed_mps=2.0,
        accept_radius_m=30.0,
        loiter_radius_m=60.0,
    ),
}


class Guidance(IntEnum):
    """What the guidance of one vehicle does this step."""

    IDLE = 0  # on the ground, no motion
    GOTO = 1  # fly to the target and stop there (fixed wing: like PASS)
    PASS = 2  # fly to the target at commanded speed (pass-through)
    HOLD = 3  # hold at the target: hover, or circle at loiter radius
    CLIMB = 4  # take off: climb to the target altitude (fixed wing: on the current heading)
    LAND = 5  # go to the target's horizontal position, then descend to the ground
    TRACK = 6  # fly the row's waypoint navigation (sitl_mock.wpnav: ArduCopter's S-curve legs)


class Arrival(IntEnum):
    """Which condition ends the current guidance target."""

    NONE = 0
    RADIUS_3D = 1  # within the acceptance radius in 3-D
    RADIUS_2D = 2  # within the acceptance radius horizontally, or (fixed wing) past the target
    ALTITUDE = 3  # reached the target altitude (takeoff)
    LANDED = 4  # on the ground
    TRACKED = 5  # the row's waypoint navigation says its destination is reached


_IDLE, _GOTO, _PASS, _HOLD, _CLIMB, _LAND, _TRACK = (int(g) for g in Guidance)
_A_NONE, _A_3D, _A_2D, _A_ALT, _A_LANDED, _A_TRACKED = (int(a) for a in Arrival)


class Kinematics:
    """Kinematic state of ``n`` vehicles as arrays (row i = vehicle i)."""

    def __init__(self, airframes: list[Airframe], ground_enu_m: np.ndarray) -> None:
        n = len(airframes)
        self.n = n
        self.is_fw = np.array([a.kind == "fixed_wing" for a in airframes], dtype=bool)
        self.max_speed = np.array([a.max_speed_mps for a in airframes])
        self.min_speed = np.array([a.min_speed_mps for a in airframes])
        self.accel = np.array([a.accel_mps2 for a in airframes])
        self.tan_bank = np.tan([a.max_bank_rad for a in airframes])
        self.climb = np.array([a.climb_rate_mps for a in airframes])
        self.sink = np.array([a.sink_rate_mps for a in airframes])
        self.land_speed = np.array([a.land_speed_mps for a in airframes])
        self.l1_period = np.array([a.l1.period_s if a.l1 else 0.0 for a in airframes])
        self.l1_gain = np.array([a.l1.turn_gain if a.l1 else 1.0 for a in airframes])
        self.roll_tau = np.array([a.l1.roll_tau_s if a.l1 else 0.0 for a in airframes])
        self.l1_bank = np.zeros(n)  # L1 planes: tan of the bank, lagging the guidance's demand
        self.pos = np.array(ground_enu_m, dtype=float).reshape(n, 3).copy()
        self.ground_z = self.pos[:, 2].copy()
        self.vel = np.zeros((n, 3))
        self.psi = np.full(n, np.pi / 2)  # facing north
        self.roll = np.zeros(n)
        self.pitch = np.zeros(n)
        self.turn_rate = np.zeros(n)
        self.speed_cmd = np.array([a.cruise_speed_mps for a in airframes])
        self.mode = np.zeros(n, dtype=np.int8)
        self.target = self.pos.copy()
        self.leg_from = self.pos.copy()
        self.accept_r = np.array([a.accept_radius_m for a in airframes])
        self.corner_speed = np.full(n, np.inf)  # PASS: speed to slow to by the target [m/s]
        self.loiter_r = np.array([max(a.loiter_radius_m, 1.0) for a in airframes])
        self.arrival = np.zeros(n, dtype=np.int8)
        self.wind = np.zeros((n, 3))
        self.drift = np.zeros((n, 3))
        self.offset = np.zeros((n, 3))
        self.wpnav: dict[int, WaypointNav] = {}  # rows that fly ArduCopter's S-curve legs in TRACK
        self.tracked = np.zeros(n, dtype=bool)  # TRACK: the row's destination is reached
        self.track_accel = np.zeros((n, 3))  # TRACK: the airframe's acceleration [m/s^2]

    # --- commands (per vehicle, from the mission logic) ---------------------------------------
    def command(
        self,
        i: int,
        mode: Guidance,
        target_m: np.ndarray | None = None,
        arrival: Arrival = Arrival.NONE,
        accept_radius_m: float | None = None,
        corner_speed_mps: float = np.inf,
    ) -> None:
        """Set vehicle i's guidance; the leg starts at its current position.

        corner_speed_mps: in PASS mode a multirotor slows to this speed by the target, so it can
        round the corner to the next leg within its acceleration limit.
        """
        following = self.mode[i] in (_GOTO, _PASS) and mode in (_GOTO, _PASS)
        target = self.pos[i] if target_m is None else target_m
        # an L1 plane tracks the line from the waypoint it was flying to, or from where it is when
        # it is already past the new waypoint's finish line on that line (Plane::set_next_WP)
        line_from = self.target[i]
        past = np.dot(self.pos[i, :2] - target[:2], target[:2] - line_from[:2]) > 0.0
        self.leg_from[i] = line_from if following and self.l1_period[i] > 0 and not past else self.pos[i]
        self.mode[i] = mode
        self.target[i] = target
        self.arrival[i] = arrival
        self.tracked[i] = False
        if mode != _TRACK:
            self.track_accel[i] = 0.0
        self.corner_speed[i] = corner_speed_mps
        if accept_radius_m is not None:
            self.accept_r[i] = accept_radius_m

    def set_speed(self, i: int, speed_mps: float) -> None:
        """Vehicle i's commanded horizontal speed (a DO_CHANGE_SPEED), also to its waypoint navigation."""
        self.speed_cmd[i] = speed_mps
        if i in self.wpnav:
            self.wpnav[i].set_speed(speed_mps)

    def place(self, i: int, pos_m: np.ndarray) -> None:
        """Put vehicle i at rest on the ground at ``pos_m`` (reboot, reset)."""
        self.pos[i] = pos_m
        self.pos[i, 2] = self.ground_z[i]
        self.vel[i] = 0.0
        self.roll[i] = self.pitch[i] = self.turn_rate[i] = 0.0
        self.offset[i] = 0.0
        self.command(i, Guidance.IDLE)

    # --- queries -------------------------------------------------------------------------------
    def reported_pos(self) -> np.ndarray:
        """Positions as the vehicles report them [m], including injected navigation drift."""
        return self.pos + self.offset

    def ground_vel(self) -> np.ndarray:
        """Velocity over ground [m/s] (air velocity plus wind while airborne)."""
        return self.vel + self.wind * self.airborne()[:, None]

    def airborne(self) -> np.ndarray:
        return self.pos[:, 2] > self.ground_z + GROUND_TOL_M

    def arrived(self) -> np.ndarray:
        """Boolean mask of vehicles whose arrival condition holds now."""
        a = self.arrival
        if not a.any():
            return np.zeros(self.n, dtype=bool)
        d = self.target - self.pos
        dist_h2 = d[:, 0] ** 2 + d[:, 1] ** 2
        r2 = self.accept_r**2
        lx = self.target[:, 0] - self.leg_from[:, 0]
        ly = self.target[:, 1] - self.leg_from[:, 1]
        passed = self.is_fw & (d[:, 0] * lx + d[:, 1] * ly < 0.0)
        z = self.pos[:, 2]
        return (
            ((a == _A_3D) & (dist_h2 + d[:, 2] ** 2 <= r2))
            | ((a == _A_2D) & ((dist_h2 <= r2) | passed))
            | ((a == _A_ALT) & (z >= self.target[:, 2] - ALT_TOL_M))
            | ((a == _A_LANDED) & (z <= self.ground_z + GROUND_TOL_M))
            | ((a == _A_TRACKED) & self.tracked)
        )

    # --- dynamics -----------------------------------------------------------------------------
    def step(self, dt_s: float) -> None:
        """Advance every vehicle by ``dt_s`` seconds."""
        active = self.mode != _IDLE
        tracking = self.mode == _TRACK
        mr = active & ~self.is_fw & ~tracking
        fw = active & self.is_fw
        if mr.any():
            self._step_multirotor(_rows(mr), dt_s)
        if fw.any():
            self._step_fixed_wing(_rows(fw), dt_s)
        if not active.all():
            idle = ~active
            self.vel[idle] = 0.0
            self.turn_rate[idle] = 0.0
        air = (self.pos[:, 2] > self.ground_z + GROUND_TOL_M)[:, None]
        for i in np.flatnonzero(tracking):
            self._step_tracking(int(i), dt_s, bool(air[i, 0]))
        self.pos += (self.vel + self.wind * air) * dt_s
        if self.drift.any():
            self.offset += self.drift * air * dt_s
        below = self.pos[:, 2] < self.ground_z
        if below.any():
            self.pos[below, 2] = self.ground_z[below]
            self.vel[below, 2] = np.maximum(self.vel[below, 2], 0.0)

    def _step_multirotor(self, m: np.ndarray | slice, dt_s: float) -> None:
        mode = self.mode[m]
        d = self.target[m] - self.pos[m]
        dx, dy = d[:, 0], d[:, 1]
        dist_h = np.sqrt(dx * dx + dy * dy)
        accel = self.accel[m]
        speed = np.minimum(self.speed_cmd[m], self.max_speed[m])
        brake = np.minimum(np.sqrt(2.0 * accel * dist_h), KP_POS * dist_h)
        corner = np.sqrt(self.corner_speed[m] ** 2 + 2.0 * accel * np.maximum(dist_h - self.accept_r[m], 0.0))
        speed = np.where(mode == _PASS, np.minimum(speed, corner), np.minimum(speed, brake))
        speed[mode == _CLIMB] = 0.0
        # Along a leg the vehicle holds the straight 3-D line (ArduCopter's WPNAV): climb in
        # proportion to horizontal progress, slowing horizontally when the slope needs more
        # than the climb/sink limit, and correct towards the line's altitude.
        leg = self.target[m] - self.leg_from[m]
        leg_h = np.sqrt(leg[:, 0] ** 2 + leg[:, 1] ** 2)
        on_leg = ((mode == _GOTO) | (mode == _PASS)) & (dist_h > LINE_MIN_H_M)
        slope = d[:, 2] / np.maximum(dist_h, 1e-9)
        vz_ff = speed * slope
        vz_limit = np.where(vz_ff > 0, self.climb[m], self.sink[m])
        speed = np.where(on_leg, speed * np.minimum(1.0, vz_limit / np.maximum(np.abs(vz_ff), 1e-9)), speed)
        progress = np.clip(1.0 - dist_h / np.maximum(leg_h, 1e-9), 0.0, 1.0)
        z_line = self.leg_from[m][:, 2] + progress * leg[:, 2]
        z_err = np.where(on_leg, z_line - self.pos[m][:, 2], d[:, 2])
        vz = np.clip(np.where(on_leg, speed * slope, 0.0) + KP_ALT * z_err, -self.sink[m], self.climb[m])
        scale = speed / np.maximum(dist_h, 1e-9)
        landing = mode == _LAND
        if landing.any():
            vz = np.where(landing, np.where(dist_h > self.accept_r[m], 0.0, -self.land_speed[m]), vz)
        vel = self.vel[m]
        dv = np.column_stack([dx * scale, dy * scale, vz]) - vel
        max_dv = accel * dt_s
        dv_h = np.sqrt(dv[:, 0] ** 2 + dv[:, 1] ** 2)
        dv[:, :2] *= np.minimum(1.0, max_dv / np.maximum(dv_h, 1e-9))[:, None]
        np.clip(dv[:, 2], -max_dv, max_dv, out=dv[:, 2])
        vel = vel + dv
        v_h = np.sqrt(vel[:, 0] ** 2 + vel[:, 1] ** 2)
        vel[:, :2] *= np.minimum(1.0, self.max_speed[m] / np.maximum(v_h, 1e-9))[:, None]
        self.vel[m] = vel
        old_psi = self.psi[m]
        psi = np.where(v_h > 0.3, np.arctan2(vel[:, 1], vel[:, 0]), old_psi)
        c, s = np.cos(psi), np.sin(psi)
        fwd = (dv[:, 0] * c + dv[:, 1] * s) / dt_s
        left = (dv[:, 1] * c - dv[:, 0] * s) / dt_s
        self.pitch[m] = -np.arctan(fwd / G_MPS2)
        self.roll[m] = -np.arctan(left / G_MPS2)
        self.turn_rate[m] = wrap_pi(psi - old_psi) / dt_s
        self.psi[m] = psi

    def _step_tracking(self, i: int, dt_s: float, airborne: bool) -> None:
        """Row i follows its waypoint navigation's target: the position controller's acceleration
        demand, reached with the lag of the airframe's response (RESPONSE_TAU_S)."""
        nav = self.wpnav[i]
        wind = self.wind[i] * airborne
        ground = self.vel[i] + wind
        nav.update(dt_s, self.pos[i], ground)
        self.tracked[i] = nav.reached_destination
        accel = self.track_accel[i]
        accel += (nav.acceleration(self.pos[i], ground) - accel) * min(1.0, dt_s / RESPONSE_TAU_S)
        vel = ground + accel * dt_s - wind
        old_psi = self.psi[i]
        psi = np.arctan2(vel[1], vel[0]) if np.hypot(vel[0], vel[1]) > 0.3 else old_psi
        fwd = accel[0] * np.cos(psi) + accel[1] * np.sin(psi)
        left = accel[1] * np.cos(psi) - accel[0] * np.sin(psi)
        self.vel[i] = vel
        self.pitch[i], self.roll[i] = -np.arctan(fwd / G_MPS2), -np.arctan(left / G_MPS2)
        self.turn_rate[i] = wrap_pi(psi - old_psi) / dt_s
        self.psi[i] = psi

    def _step_fixed_wing(self, m: np.ndarray | slice, dt_s: float) -> None:
        pos, tgt, mode = self.pos[m], self.target[m], self.mode[m]
        v = np.clip(self.speed_cmd[m], self.min_speed[m], self.max_speed[m])
        dx, dy = tgt[:, 0] - pos[:, 0], tgt[:, 1] - pos[:, 1]
        psi = self.psi[m]
        psi_des = np.arctan2(dy, dx)
        circling = (mode == _HOLD) | (mode == _LAND)
        if circling.any():
            r = self.loiter_r[m]
            radial = np.sqrt(dx * dx + dy * dy)
            circle = psi_des + np.pi / 2 - np.arctan(K_CIRCLE * (radial - r) / r)  # clockwise orbit
            psi_des = np.where(circling, circle, psi_des)
        psi_des = np.where(mode == _CLIMB, psi, psi_des)
        max_rate = G_MPS2 * self.tan_bank[m] / v
        rate = KP_PSI * wrap_pi(psi_des - psi)
        l1 = (self.l1_period[m] > 0) & ((mode == _GOTO) | (mode == _PASS))
        if circling.any():
            rate = rate - circling * v / self.loiter_r[m]  # feed-forward of the clockwise orbit
        rate = np.clip(rate, -max_rate, max_rate)
        if l1.any():
            rate = np.where(l1, self._l1_rate(m, l1, pos, tgt, psi, v, dt_s), rate)
        psi = wrap_pi(psi + rate * dt_s)
        landing = mode == _LAND
        target_z = np.where(landing, self.ground_z[m], tgt[:, 2])
        vz = np.clip(KP_ALT * (target_z - pos[:, 2]), -self.sink[m], self.climb[m])
        if landing.any():
            vz = np.where(landing, np.maximum(vz, -self.land_speed[m]), vz)
        vz = np.clip(vz, -0.9 * v, 0.9 * v)
        v_h = np.sqrt(v * v - vz * vz)
        self.vel[m] = np.column_stack([v_h * np.cos(psi), v_h * np.sin(psi), vz])
        self.turn_rate[m] = rate
        self.roll[m] = -np.arctan(rate * v / (G_MPS2 * self.l1_gain[m]))  # the bank that turns it so
        self.pitch[m] = np.arcsin(vz / v)
        self.psi[m] = psi

    def _l1_rate(self, m, l1: np.ndarray, pos, tgt, psi, v, dt_s: float) -> np.ndarray:
        """Turn rate of the rows on L1 guidance (mask l1 within rows m): the guidance's demand as a
        bank within the limit, lagging by the airframe's time constant, turning at its gain."""
        ground = np.column_stack([v * np.cos(psi), v * np.sin(psi)]) + self.wind[m][:, :2]
        tan_max = self.tan_bank[m]
        north_east = np.array([1, 0])  # ENU (x east, y north) -> the controller's NE
        lateral = l1_lateral_accel(pos[:, north_east], self.leg_from[m][:, north_east], tgt[:, north_east],
                                   ground[:, north_east], self.l1_period[m])  # fmt: skip
        demand = np.clip(-lateral / G_MPS2, -tan_max, tan_max)  # tan(bank); + right is - counter-clockwise
        tau = self.roll_tau[m]
        lag = np.where(tau > 0, np.minimum(1.0, dt_s / np.maximum(tau, 1e-9)), 1.0)
        bank = self.l1_bank[m]
        bank = np.where(l1, bank + lag * (demand - bank), 0.0)
        self.l1_bank[m] = bank
        return self.l1_gain[m] * G_MPS2 * bank / v


def _rows(mask: np.ndarray) -> np.ndarray | slice:
    """Index for the rows in ``mask``: a slice (views, no copies) when it selects every row."""
    return slice(None) if mask.all() else mask


def climb_run_m(speed_mps: float, climb_mps: float, alt_m: float, dt_s: float = 0.05) -> float:
    """Ground run [m] of the mock fixed wing's take-off climb (north, at cruise speed, vz = KP_ALT x
    error clipped to the climb rate and 0.9 v), so that its home can be placed that far south of
    where the route starts."""
    z, run = 0.0, 0.0
    while z < alt_m - ALT_TOL_M:
        vz = min(KP_ALT * (alt_m - z), climb_mps, 0.9 * speed_mps)
        z += vz * dt_s
        run += float(np.sqrt(speed_mps**2 - vz**2)) * dt_s
    return run
