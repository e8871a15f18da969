"""ArduPlane's L1 waypoint guidance, and how a plane flying it follows a list of waypoints.

ArduPlane steers along the line from the previous waypoint to the next one with the L1 law
(``AP_L1_Control::update_waypoint``) and moves to the next waypoint once within its acceptance
radius or past the current one's finish line (``Plane::verify_nav_wp``, ``Plane::set_next_WP``).
Such a plane turns late and overshoots a turn onto a new line, so a leg that ends soon after a
turn arrives off its heading. ``predict_flight`` flies a waypoint list with that law (for the
mock's L1 planes and for the planner), and ``shape_waypoints`` moves a mission's waypoints so
that the predicted flight follows the planned path (docs/coalition.md, "L1 shaping").
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from gcs_planner.model.plan import VehiclePlan

__all__ = [
    "ARDUPLANE_SITL", "L1_DAMPING", "L1Response", "TurnGain", "l1_turn_rate", "predict_flight",
    "shape_for_l1", "shape_waypoints",
]  # fmt: skip

L1_DAMPING = 0.75  # NAVL1_DAMPING default (AP_L1_Control.cpp var_info)
G_MPS2 = 9.80665
PREDICT_DT_S = 0.1  # ArduPlane navigates at 10 Hz (Plane::navigate in the scheduler table)
SHAPE_ITERATIONS = 8
SHAPE_DONE_M = 1.0  # shaping stops once the predicted RMS cross-track error is below this
SHAPE_GAIN = 0.7  # share of the predicted cross-track error moved off each waypoint per iteration
SHAPE_MAX_SHIFT_M = 80.0  # no waypoint moves further than this from the planned path
ROBUST_GAINS = (0.85, 1.15)  # shaped waypoints must not loop with the turn gain off by this factor
LOOP_FACTOR, LOOP_SLACK_M = 1.3, 30.0  # a flight this much longer than the path between two places loops
GAIN_MIN_BANK_RAD = math.radians(5.0)  # turn samples below this bank say little of the gain
GAIN_MEMORY = 0.995  # weight left on the older turn samples at each new one (~20 s at 10 Hz)
GAIN_MIN_WEIGHT = 0.5  # sum of squared coordinated rates [(rad/s)^2] (~3 s turning at 10 deg/s) to tell
GAIN_RANGE = (0.3, 1.5)  # a gain told is clipped to this
SHAPE_AFTER_S = 8.0  # an L1 plane's waypoints this soon after its mission starts stay on the path [s]


@dataclass(frozen=True)
class L1Response:
    """How a plane flies ArduPlane's L1 guidance: its NAVL1_PERIOD [s], the share of the turn rate
    the guidance demands that the airframe achieves, and the time constant [s] of its bank."""

    period_s: float
    turn_gain: float = 1.0
    roll_tau_s: float = 0.0


# ArduPlane SITL's stock plane (NAVL1_PERIOD 15, Tools/autotest/models/plane.parm): turn gain and
# bank lag fitted to its flown goals after 180 deg turns (docs/coalition.md, "L1 shaping")
ARDUPLANE_SITL = L1Response(15.0, 0.7, 0.25)


class TurnGain:
    """A plane's turn gain learnt in flight: its turn rate (course change between position
    reports, on its own clock) against the coordinated rate of its reported bank, g tan(roll) / v,
    least squares with a forgetting factor. An airframe in coordinated turns has about 1;
    ArduPlane SITL's plane 0.7-0.8 (docs/coalition.md, "L1 shaping")."""

    def __init__(self) -> None:
        self.roll_rad = 0.0
        self._last: tuple[float, float] | None = None  # time [s], course [rad] of the newest report
        self._num = self._den = 0.0

    def attitude(self, roll_rad: float) -> None:
        """The newest reported roll (right wing down positive)."""
        self.roll_rad = roll_rad

    def velocity(self, t_s: float, v_east: float, v_north: float) -> None:
        """A position report's time [s, the vehicle's clock] and ground velocity [m/s]."""
        speed, course = math.hypot(v_east, v_north), math.atan2(v_north, v_east)
        last, self._last = self._last, (t_s, course)
        dt = t_s - last[0] if last else 0.0
        if not 0.0 < dt < 1.0 or speed < 5.0 or abs(self.roll_rad) < GAIN_MIN_BANK_RAD:
            return
        rate = math.remainder(course - last[1], 2 * math.pi) / dt
        coordinated = -G_MPS2 * math.tan(self.roll_rad) / speed  # CCW; a right bank turns clockwise
        self._num = GAIN_MEMORY * self._num + rate * coordinated
        self._den = GAIN_MEMORY * self._den + coordinated * coordinated

    @property
    def value(self) -> float | None:
        """The gain, once enough banked flight has been seen; else None."""
        if self._den < GAIN_MIN_WEIGHT:
            return None
        return min(max(self._num / self._den, GAIN_RANGE[0]), GAIN_RANGE[1])


def l1_turn_rate(pos: np.ndarray, a: np.ndarray, b: np.ndarray, ground: np.ndarray, period_s) -> np.ndarray:
    """ArduPlane's L1 waypoint guidance (AP_L1_Control::update_waypoint, without its integrator
    and indecision guard) as a turn rate [rad/s, counter-clockwise] along the line a -> b, for
    rows of vehicles (ENU positions, ground velocities); the controller's NE cross products are
    ENU ones with the sign turned."""
    gs = np.maximum(np.hypot(ground[:, 0], ground[:, 1]), 0.1)
    l1_dist = np.maximum(0.3183099 * L1_DAMPING * period_s * gs, 0.1)
    ab = b[:, :2] - a[:, :2]
    ab_len = np.hypot(ab[:, 0], ab[:, 1])
    ab = np.where((ab_len > 1e-6)[:, None], ab / np.maximum(ab_len, 1e-6)[:, None], ground / gs[:, None])
    a_air = pos[:, :2] - a[:, :2]

    def cross(u: np.ndarray, w: np.ndarray) -> np.ndarray:
        return u[:, 0] * w[:, 1] - u[:, 1] * w[:, 0]

    def dot(u: np.ndarray, w: np.ndarray) -> np.ndarray:
        return u[:, 0] * w[:, 0] + u[:, 1] * w[:, 1]

    def towards(point: np.ndarray) -> np.ndarray:  # Nu of flying straight at ``point``
        to = point[:, :2] - pos[:, :2]
        to = to / np.maximum(np.hypot(to[:, 0], to[:, 1]), 1e-6)[:, None]
        return np.arctan2(cross(ground, to), dot(ground, to))

    sine_nu1 = np.clip(cross(a_air, ab) / l1_dist, -0.7071, 0.7071)
    nu = np.arcsin(sine_nu1) + np.arctan2(cross(ground, ab), dot(ground, ab))
    a_dist, along = np.hypot(a_air[:, 0], a_air[:, 1]), dot(a_air, ab)
    nu = np.where((a_dist > l1_dist) & (along / np.maximum(a_dist, 1.0) < -0.7071), towards(a), nu)
    nu = np.where(along > ab_len + 3.0 * gs, towards(b), nu)
    nu = np.clip(nu, -np.pi / 2, np.pi / 2)
    return 4.0 * L1_DAMPING**2 * gs / l1_dist * np.sin(nu)


def predict_flight(
    pose,
    speed_mps,
    waypoints: np.ndarray,
    response: L1Response,
    accept_m: float,
    max_bank_rad: float,
    dt_s: float = PREDICT_DT_S,
) -> tuple[np.ndarray, np.ndarray]:
    """The track of a plane at pose (x, y, heading [rad]) flying ``waypoints`` (N, 2) [m] in order
    at ground speed ``speed_mps`` [m/s] (one, or one per waypoint: the speed flown to it) with L1
    guidance, as ``response`` says: samples every dt_s [s] of (x, y, heading), and for each
    waypoint the sample index at which it was reached (within accept_m, or past its finish line).
    The first line starts at the plane. The bank follows the guidance's demand (up to
    max_bank_rad) with the response's lag, and turns the plane at its gain."""
    x, y, psi = (float(v) for v in pose[:3])
    wps = np.asarray(waypoints, dtype=float)[:, :2]
    ax, ay = x, y
    speeds = np.broadcast_to(np.asarray(speed_mps, dtype=float), (len(wps),))
    tan_bank, k = 0.0, 0
    out, reached = [(x, y, psi)], np.full(len(wps), -1)
    steps = int(math.ceil(_path_length(pose, wps) * 1.5 / (float(speeds.min()) * dt_s))) + 50
    max_tan = math.tan(max_bank_rad)
    lag = min(1.0, dt_s / response.roll_tau_s) if response.roll_tau_s > 0 else 1.0
    gain, period_s = response.turn_gain, response.period_s
    for _ in range(steps):
        bx, by = wps[k]
        dx, dy = bx - x, by - y
        if dx * dx + dy * dy <= accept_m * accept_m or dx * (bx - ax) + dy * (by - ay) < 0.0:
            reached[k] = len(out) - 1
            k += 1
            if k == len(wps):
                break
            ax, ay = bx, by
            if (x - wps[k, 0]) * (wps[k, 0] - ax) + (y - wps[k, 1]) * (wps[k, 1] - ay) > 0.0:
                ax, ay = x, y  # already past the next one's finish line: from here (Plane::set_next_WP)
            continue
        v = float(speeds[k])
        demand = max(-max_tan, min(max_tan, _l1_rate(x, y, psi, ax, ay, bx, by, v, period_s) * v / G_MPS2))
        tan_bank += lag * (demand - tan_bank)
        psi += gain * G_MPS2 * tan_bank / v * dt_s
        x += v * math.cos(psi) * dt_s
        y += v * math.sin(psi) * dt_s
        out.append((x, y, psi))
    return np.asarray(out), reached


def shape_waypoints(
    pose,
    speed_mps,
    waypoints: np.ndarray,
    path_xy: np.ndarray,
    response: L1Response,
    accept_m: float,
    max_bank_rad: float,
    keep_first: int = 0,
) -> np.ndarray:
    """Waypoints moved across the planned path ``path_xy`` (dense, in flight order) so that the
    L1 flight ``predict_flight`` gives passes each original waypoint's place on the path: each
    iteration moves every waypoint but the first keep_first by SHAPE_GAIN x the predicted
    cross-track error where the flight crosses that place's normal (iterative learning control
    against the model). The iterate with the smallest RMS error is kept, but none whose flight
    loops (turns half a turn more or less than the path, is much longer than the path between
    two places, or is not at the last waypoint in 1.5 x the path's time) under the response or
    under the response with its turn gain x ROBUST_GAINS; after a looping iterate the next goes
    half way back to the best. It stops early once the error is below SHAPE_DONE_M."""
    places = np.asarray(waypoints, dtype=float)[:, :2]
    path_xy = np.asarray(path_xy, dtype=float)[:, :2]
    normals, path_s, path_turn = _path_places(path_xy, places)
    others = [replace(response, turn_gain=f * response.turn_gain) for f in ROBUST_GAINS]

    def flight(model: L1Response) -> tuple[float, np.ndarray]:  # RMS error (inf: loops), errors
        flown, reached = predict_flight(pose, speed_mps, wps, model, accept_m, max_bank_rad)
        errors, flown_s = _crossings(flown[:, :2], places, normals)
        if reached[-1] < 0 or abs(flown[-1, 2] - flown[0, 2] - path_turn) > math.pi:
            return math.inf, errors
        return _score(errors, flown_s, path_s), errors

    wps, best, best_score = places.copy(), places.copy(), math.inf
    for _ in range(SHAPE_ITERATIONS):
        score, err = flight(response)
        if score < best_score and any(math.isinf(flight(model)[0]) for model in others):
            score = math.inf
        if score < best_score:
            best, best_score = wps.copy(), score
        if best_score < SHAPE_DONE_M:
            break
        if not math.isfinite(score):
            wps = 0.5 * (best + wps)
            continue
        shift = np.nan_to_num(err) * SHAPE_GAIN
        shift[:keep_first] = 0.0
        offset = np.einsum("ij,ij->i", wps - places, normals) - shift
        wps = places + np.clip(offset, -SHAPE_MAX_SHIFT_M, SHAPE_MAX_SHIFT_M)[:, None] * normals
    return best


def _l1_rate(x, y, psi, ax, ay, bx, by, v: float, period_s: float) -> float:
    """``l1_turn_rate`` for one plane in floats (the predictor's inner loop)."""
    gx, gy = v * math.cos(psi), v * math.sin(psi)
    l1_dist = max(0.3183099 * L1_DAMPING * period_s * v, 0.1)
    abx, aby = bx - ax, by - ay
    ab_len = math.hypot(abx, aby)
    if ab_len > 1e-6:
        abx, aby = abx / ab_len, aby / ab_len
    else:
        abx, aby = gx / v, gy / v
    px, py = x - ax, y - ay
    a_dist, along = math.hypot(px, py), px * abx + py * aby
    if a_dist > l1_dist and along / max(a_dist, 1.0) < -0.7071:
        nu = _towards(gx, gy, ax - x, ay - y)
    elif along > ab_len + 3.0 * v:
        nu = _towards(gx, gy, bx - x, by - y)
    else:
        sine_nu1 = max(-0.7071, min(0.7071, (px * aby - py * abx) / l1_dist))
        nu = math.asin(sine_nu1) + math.atan2(gx * aby - gy * abx, gx * abx + gy * aby)
    nu = max(-math.pi / 2, min(math.pi / 2, nu))
    return 4.0 * L1_DAMPING**2 * v / l1_dist * math.sin(nu)


def _towards(gx: float, gy: float, tx: float, ty: float) -> float:
    return math.atan2(gx * ty - gy * tx, gx * tx + gy * ty)


def _path_length(pose, wps: np.ndarray) -> float:
    pts = np.vstack([np.asarray(pose[:2], dtype=float), wps])
    return float(np.hypot(*np.diff(pts, axis=0).T).sum())


def _path_places(path_xy: np.ndarray, points: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """Left unit normals of the path at the path sample nearest each point, that sample's
    distance along the path [m], and the path's turn [rad, CCW] up to the last point's sample."""
    tangent = np.gradient(path_xy, axis=0)
    tangent /= np.maximum(np.hypot(*tangent.T), 1e-9)[:, None]
    nearest = np.argmin(((points[:, None, :] - path_xy[None, :, :]) ** 2).sum(-1), axis=1)
    t = tangent[nearest]
    s = np.r_[0.0, np.cumsum(np.hypot(*np.diff(path_xy, axis=0).T))]
    heading = np.unwrap(np.arctan2(tangent[:, 1], tangent[:, 0]))
    return np.column_stack([-t[:, 1], t[:, 0]]), s[nearest], float(heading[nearest[-1]] - heading[0])


def _crossings(flown: np.ndarray, points: np.ndarray, normals: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Where the flown track crosses each point's normal line, in order (the first crossing
    after the previous point's, within SHAPE_MAX_SHIFT_M x 2 of the point): the signed distance
    along the normal (left +) and the flown distance there [m]; NaN where it does not cross."""
    err, at = np.full(len(points), np.nan), np.full(len(points), np.nan)
    flown_s = np.r_[0.0, np.cumsum(np.hypot(*np.diff(flown, axis=0).T))]
    tangents = np.column_stack([normals[:, 1], -normals[:, 0]])
    start = 0
    for i, (p, n, t) in enumerate(zip(points, normals, tangents)):
        rel = flown[start:] - p
        along, across = rel @ t, rel @ n
        j = np.nonzero((along[:-1] <= 0.0) & (along[1:] > 0.0))[0]
        f = along[j] / np.minimum(along[j] - along[j + 1], -1e-12)  # in [0, 1)
        cross = across[j] + f * (across[j + 1] - across[j])
        near = np.nonzero(np.abs(cross) < 2 * SHAPE_MAX_SHIFT_M)[0]
        if len(near):
            k = int(near[0])
            start += int(j[k])
            err[i], at[i] = cross[k], flown_s[start] + f[k] * (flown_s[start + 1] - flown_s[start])
    return err, at


def _score(err: np.ndarray, flown_s: np.ndarray, path_s: np.ndarray) -> float:
    """RMS cross-track error at the places crossed; infinite when the flight loops: between two
    places crossed it flies more than LOOP_FACTOR x the path's length there + LOOP_SLACK_M."""
    ok = np.isfinite(err)
    if not ok.any():
        return math.inf
    if np.any(np.diff(flown_s[ok]) > LOOP_FACTOR * np.diff(path_s[ok]) + LOOP_SLACK_M):
        return math.inf
    return float(np.sqrt(np.mean(err[ok] ** 2)))


def shape_for_l1(vp: VehiclePlan, response: L1Response, max_bank_rad: float, from_s: float) -> VehiclePlan:
    """The mission with its waypoints after route time from_s (where the vehicle starts flying
    it) moved so that a plane flying ArduPlane's L1 guidance as ``response`` says, on the path
    at from_s, follows the path from there (``l1_guidance.shape_waypoints``): such a plane flies
    a turn wide and is still converging on the line after it, where a leg's goal pose lies.
    The waypoints before from_s + SHAPE_AFTER_S (and the first two after from_s) stay on the
    path: the plane starts the mission towards one of them, later when the upload is slow, on a
    line from its last mission's waypoint (``Plane::set_next_WP``), which the prediction does
    not know; started towards a waypoint off its track it can circle it for good."""
    path = vp.path[:, :2]
    k = int(np.searchsorted(vp.path_times_s, from_s).clip(1, len(path) - 1))
    pose = (*path[k - 1], math.atan2(*(path[k] - path[k - 1])[::-1]))
    after = np.nonzero(vp.times_s > vp.path_times_s[k - 1])[0]
    waypoints = vp.waypoints.copy()
    if len(after):
        keep = max(int(np.count_nonzero(vp.times_s[after] <= from_s + SHAPE_AFTER_S)), 2)
        waypoints[after, :2] = shape_waypoints(
            pose, vp.speeds_mps[after], vp.waypoints[after, :2], path[k - 1 :], response,
            vp.acceptance_radius_m, max_bank_rad, keep,
        )  # fmt: skip
    return replace(vp, waypoints=waypoints)
