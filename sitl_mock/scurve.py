"""The mock's copy of ArduCopter's S-curve leg (ArduPilot AP_Math/SCurve.cpp, master 64a9c787).

One straight leg, origin to destination, is planned as 23 time segments of jerk (constant, or
rising / falling on a raised cosine): 1 initial, 7 accelerating, 7 of speed change, 1 cruise and
7 braking. The leg starts and ends at rest; `advance_target_along_track` blends it with the legs
before and after at a waypoint the vehicle passes through. Ported function by function, in the
C++'s names and order, so that it can be read against the source; arcs (ARC_WAYPOINT), a speed at
the origin (spline legs) and the destination-speed reduction are not ported: the mock flies
straight NAV_WAYPOINT legs only. Frame: ENU, z up (the C++ is NED: its signs are flipped here).

This module is the mock's witness of the client's own model (gcs_planner.geometry.scurve, a sampled
approximation written for the pre-flight check); neither imports the other.
"""

from __future__ import annotations

import logging
import math
from enum import Enum

import numpy as np

__all__ = ["SCurve", "kinematic_limit"]

log = logging.getLogger(__name__)

SEG_INIT, SEG_ACCEL_MAX, SEG_ACCEL_END, SEG_SPEED_CHANGE_END, SEG_CONST, SEG_DECEL_END = 0, 4, 7, 14, 15, 22
SEGMENTS_MAX = 23


class SegmentType(Enum):
    CONSTANT_JERK = 0
    POSITIVE_JERK = 1
    NEGATIVE_JERK = 2


class _Segment:
    __slots__ = ("end_accel", "end_pos", "end_time", "end_vel", "jerk_ref", "seg_type")

    def __init__(self) -> None:
        self.set(0.0, SegmentType.CONSTANT_JERK, 0.0, 0.0, 0.0, 0.0)

    def set(
        self,
        end_time: float,
        seg_type: SegmentType,
        jerk_ref: float,
        end_accel: float,
        end_vel: float,
        end_pos: float,
    ) -> None:
        self.end_time, self.seg_type, self.jerk_ref = end_time, seg_type, jerk_ref
        self.end_accel, self.end_vel, self.end_pos = end_accel, end_vel, end_pos

    def copy_from(self, other: _Segment) -> None:
        self.set(
            other.end_time, other.seg_type, other.jerk_ref, other.end_accel, other.end_vel, other.end_pos
        )

    def hold(self, at: _Segment, accel: float = 0.0) -> None:
        """A constant-jerk segment of no length at ``at``'s end (the C++'s "empty" segments)."""
        self.set(at.end_time, SegmentType.CONSTANT_JERK, 0.0, accel, at.end_vel, at.end_pos)


def kinematic_limit(
    length_xy: float, length_z: float, max_xy: float, max_up: float, max_down: float
) -> float:
    """The largest magnitude along (length_xy, length_z) whose parts keep the horizontal and the
    vertical (up for length_z > 0) limits (AP_Math/control.cpp ``kinematic_limit``)."""
    if max_xy == 0 or max_up == 0 or max_down == 0:
        return 0.0
    max_xy, max_up, max_down = abs(max_xy), abs(max_up), abs(max_down)
    length = math.hypot(length_xy, length_z)
    if length <= 0:
        return 0.0
    xy, z = length_xy / length, length_z / length
    if xy == 0:
        return max_up if z > 0 else max_down
    if z == 0:
        return max_xy
    limit_z = max_up if z > 0 else max_down
    if abs(z / xy) < limit_z / max_xy:
        return max_xy / xy
    return abs(limit_z / z)


class SCurve:
    """One leg's S-curve: its segments, the time reached along it, and its track."""

    def __init__(self) -> None:
        self.segment = [_Segment() for _ in range(SEGMENTS_MAX)]
        self.init()

    def init(self) -> None:
        self.snap_max = self.jerk_max = self.accel_max = self.accel_z_max = self.vel_max = 0.0
        self.time = 0.0
        self.num_segs = SEG_INIT
        self.num_segs = self._add_segment(self.num_segs, 0.0, SegmentType.CONSTANT_JERK, 0.0, 0.0, 0.0, 0.0)
        self.seg_delta = np.zeros(3)
        self.seg_length = 0.0

    # --- planning -----------------------------------------------------------------------------
    def calculate_track(
        self,
        origin: np.ndarray,
        destination: np.ndarray,
        speed_xy: float,
        speed_up: float,
        speed_down: float,
        accel_xy: float,
        accel_z: float,
        snap_maximum: float,
        jerk_maximum: float,
    ) -> None:
        """The straight leg from ``origin`` to ``destination`` within these limits."""
        self.init()
        self.seg_delta = np.asarray(destination, dtype=float) - np.asarray(origin, dtype=float)
        self.seg_length = float(np.linalg.norm(self.seg_delta))
        if self.seg_length == 0.0:
            self.seg_delta = np.zeros(3)
            return
        self.snap_max, self.jerk_max = snap_maximum, jerk_maximum
        length_xy = math.hypot(self.seg_delta[0], self.seg_delta[1])
        self.vel_max = kinematic_limit(
            length_xy, self.seg_delta[2], abs(speed_xy), abs(speed_up), abs(speed_down)
        )
        self.accel_max = kinematic_limit(
            length_xy, self.seg_delta[2], abs(accel_xy), abs(accel_z), abs(accel_z)
        )
        self.accel_z_max = abs(accel_z)
        if min(self.snap_max, self.jerk_max, self.accel_max, self.vel_max) <= 0:
            log.warning(
                "SCurve.calculate_track: a zero limit leaves the leg of zero length, as SCurve.cpp does"
            )
            return
        self.add_segments(self.seg_length)
        if not self.valid():
            log.warning("SCurve.calculate_track: invalid path; the leg is dropped, as SCurve.cpp does")
            self.init()

    def set_speed_max(self, speed_xy: float, speed_up: float, speed_down: float) -> None:
        """Re-plan the rest of the leg for a new speed (a DO_CHANGE_SPEED in flight)."""
        seg = self.segment
        if self.num_segs != SEGMENTS_MAX:
            return
        length_xy = math.hypot(self.seg_delta[0], self.seg_delta[1])
        track_speed_max = kinematic_limit(
            length_xy, self.seg_delta[2], abs(speed_xy), abs(speed_up), abs(speed_down)
        )
        if math.isclose(self.vel_max, track_speed_max, abs_tol=1e-6) or track_speed_max == 0:
            return
        self.vel_max = track_speed_max
        if self.time >= seg[SEG_CONST].end_time:
            return
        p_end = seg[SEG_DECEL_END].end_pos
        v_end = min(self.vel_max, seg[SEG_DECEL_END].end_vel)
        if self.time == 0:  # not started: plan the leg again (its ends are at rest here)
            self.num_segs = self._add_segment(SEG_INIT, 0.0, SegmentType.CONSTANT_JERK, 0.0, 0.0, 0.0, 0.0)
            self.add_segments(p_end)
            return
        self._start_from_now()
        self._cut_acceleration(p_end)
        self._change_speed()
        self._brake(p_end, v_end)
        if not self.valid():
            log.warning("SCurve.set_speed_max: invalid path; the leg is dropped, as SCurve.cpp does")
            self.init()

    def _start_from_now(self) -> None:
        """Make room for a speed change: one under way becomes the acceleration, and while cruising
        the acceleration and speed change end here and now."""
        seg = self.segment
        if seg[SEG_ACCEL_END].end_time <= self.time <= seg[SEG_SPEED_CHANGE_END].end_time:
            seg[SEG_INIT].hold(seg[SEG_ACCEL_END], seg[SEG_ACCEL_END].end_accel)
            for i in range(SEG_INIT + 1, SEG_ACCEL_END + 1):
                seg[i].copy_from(seg[i + 7])
            for i in range(SEG_ACCEL_END + 1, SEG_SPEED_CHANGE_END + 1):
                seg[i].hold(seg[SEG_ACCEL_END])
        elif seg[SEG_SPEED_CHANGE_END].end_time < self.time <= seg[SEG_CONST].end_time:
            seg[SEG_INIT].hold(seg[SEG_SPEED_CHANGE_END])
            _, _, vt, pt = self.get_jerk_accel_vel_pos_at_time(self.time)
            for i in range(SEG_INIT + 1, SEG_SPEED_CHANGE_END + 1):
                seg[i].set(self.time, SegmentType.CONSTANT_JERK, 0.0, 0.0, vt, pt)

    def _cut_acceleration(self, p_end: float) -> None:
        """Still in the constant acceleration towards a higher speed: end the ramp as near the new
        speed as it can, and plan the braking from there."""
        seg = self.segment
        if not (
            self.time <= seg[SEG_ACCEL_MAX].end_time
            and seg[SEG_ACCEL_MAX].end_time - seg[SEG_ACCEL_MAX - 1].end_time > 0
            and self.vel_max < seg[SEG_ACCEL_END].end_vel
            and seg[SEG_ACCEL_MAX].end_accel > 0
        ):
            return
        v_min = seg[SEG_ACCEL_END].end_vel - seg[SEG_ACCEL_MAX].end_accel * (
            seg[SEG_ACCEL_MAX].end_time - max(self.time, seg[SEG_ACCEL_MAX - 1].end_time)
        )
        speed = max(v_min, self.vel_max)
        jm, tj, t2, t4, t6 = self.calculate_path(
            self.snap_max, self.jerk_max, seg[SEG_INIT].end_vel, self.accel_max, speed, p_end * 0.5
        )
        i = self._add_segments_jerk(SEG_INIT + 1, tj, jm, t2)
        i = self._add_segment_const_jerk(i, t4, 0.0)
        self._add_segments_jerk(i, tj, -jm, t6)
        seg[SEG_ACCEL_END].end_accel = 0.0
        for i in range(SEG_ACCEL_END + 1, SEG_CONST + 1):
            seg[i].hold(seg[SEG_ACCEL_END])
        jm, tj, t2, t4, t6 = self.calculate_path(
            self.snap_max, self.jerk_max, 0.0, self.accel_max, speed, p_end * 0.5
        )
        i = self._add_segments_jerk(SEG_CONST + 1, tj, -jm, t6)
        i = self._add_segment_const_jerk(i, t4, 0.0)
        self._add_segments_jerk(i, tj, jm, t2)
        seg[SEG_DECEL_END].end_accel = 0.0
        seg[SEG_DECEL_END].end_vel = max(0.0, seg[SEG_DECEL_END].end_vel)
        self._stretch_cruise(p_end)

    def _change_speed(self) -> None:
        """The speed change segments (8-14) from the acceleration's end speed to the new one, where
        the cruise is long enough for them."""
        seg = self.segment
        for i in range(SEG_ACCEL_END + 1, SEG_SPEED_CHANGE_END + 1):
            seg[i].hold(seg[SEG_ACCEL_END])
        v_accel_end = seg[SEG_ACCEL_END].end_vel
        if math.isclose(self.vel_max, v_accel_end, abs_tol=1e-6):
            return
        length = seg[SEG_CONST].end_pos - seg[SEG_ACCEL_END].end_pos
        jm = tj = t2 = t4 = t6 = 0.0
        # SCurve.cpp writes powf(x, 1/3), an integer 1/3 = 0: the first term is always 1 s
        jerk_time = min(1.0, self.jerk_max * math.pi / (2 * self.snap_max))
        if self.vel_max < v_accel_end and jerk_time * 12.0 < length / v_accel_end:
            jm, tj, t6, t4, t2 = self.calculate_path(
                self.snap_max, self.jerk_max, self.vel_max, self.accel_max, v_accel_end, length * 0.5
            )
            jm = -jm
        elif self.vel_max > v_accel_end and length / (jerk_time * 12.0) > v_accel_end:
            vm = min(self.vel_max, length / (jerk_time * 12.0))
            jm, tj, t2, t4, t6 = self.calculate_path(
                self.snap_max, self.jerk_max, v_accel_end, self.accel_max, vm, length * 0.5
            )
        if jm != 0 and min(t2, t4, t6) >= 0:
            i = self._add_segments_jerk(SEG_ACCEL_END + 1, tj, jm, t2)
            i = self._add_segment_const_jerk(i, t4, 0.0)
            self._add_segments_jerk(i, tj, -jm, t6)
            seg[SEG_SPEED_CHANGE_END].end_accel = 0.0

    def _brake(self, p_end: float, v_end: float) -> None:
        """The braking segments from the new cruise speed to ``v_end`` at ``p_end``."""
        seg = self.segment
        v_end = min(v_end, seg[SEG_SPEED_CHANGE_END].end_vel)
        i = self._add_segment_const_jerk(SEG_CONST, 0.0, 0.0)
        if v_end < seg[SEG_SPEED_CHANGE_END].end_vel:
            jm, tj, t2, t4, t6 = self.calculate_path(
                self.snap_max, self.jerk_max, v_end, self.accel_max, seg[SEG_CONST].end_vel,
                p_end - seg[SEG_CONST].end_pos,
            )  # fmt: skip
            i = self._add_segments_jerk(i, tj, -jm, t6)
            i = self._add_segment_const_jerk(i, t4, 0.0)
            self._add_segments_jerk(i, tj, jm, t2)
        else:
            for i in range(SEG_CONST + 1, SEG_DECEL_END + 1):
                seg[i].hold(seg[SEG_CONST])
        seg[SEG_DECEL_END].end_accel = 0.0
        seg[SEG_DECEL_END].end_vel = max(0.0, seg[SEG_DECEL_END].end_vel)
        self._stretch_cruise(p_end)

    def _stretch_cruise(self, p_end: float) -> None:
        """Lengthen the cruise so that the leg ends at ``p_end`` ("add to constant velocity segment")."""
        seg = self.segment
        dp = max(0.0, p_end - seg[SEG_DECEL_END].end_pos)
        t15 = dp / seg[SEG_CONST].end_vel
        for i in range(SEG_CONST, SEG_DECEL_END + 1):
            seg[i].end_time += t15
            seg[i].end_pos += dp

    def add_segments(self, length: float) -> None:
        """The 22 segments of a leg of ``length`` from rest to rest: accelerate over half of it."""
        if length == 0:
            return
        jm, tj, t2, t4, t6 = self.calculate_path(
            self.snap_max, self.jerk_max, 0.0, self.accel_max, self.vel_max, length * 0.5
        )
        i = self._add_segments_jerk(self.num_segs, tj, jm, t2)
        i = self._add_segment_const_jerk(i, t4, 0.0)
        i = self._add_segments_jerk(i, tj, -jm, t6)
        self.segment[SEG_ACCEL_END].end_accel = 0.0
        for _ in range(7):
            i = self._add_segment_const_jerk(i, 0.0, 0.0)
        seg = self.segment[SEG_SPEED_CHANGE_END]
        t15 = max(0.0, (length - 2.0 * seg.end_pos) / seg.end_vel)
        i = self._add_segment_const_jerk(i, t15, 0.0)
        i = self._add_segments_jerk(i, tj, -jm, t6)
        i = self._add_segment_const_jerk(i, t4, 0.0)
        self.num_segs = self._add_segments_jerk(i, tj, jm, t2)
        self.segment[SEG_DECEL_END].end_accel = 0.0
        self.segment[SEG_DECEL_END].end_vel = 0.0

    @staticmethod
    def calculate_path(
        sm: float, jm: float, v0: float, am: float, vm: float, length: float
    ) -> tuple[float, float, float, float, float]:
        """(Jm, tj, t2, t4, t6): the jerk and the durations of the S-curve from ``v0`` towards ``vm``
        over ``length`` with snap ``sm`` (raised-cosine edges), jerk ``jm``, acceleration ``am``."""
        if min(sm, jm, am, vm, length) <= 0:  # SCurve.cpp flags an internal error and returns zeros
            return 0.0, 0.0, 0.0, 0.0, 0.0
        if v0 >= vm:
            return 0.0, 0.0, 0.0, 0.0, 0.0
        tj = jm * math.pi / (2 * sm)
        at = min(am, (vm - v0) / (2.0 * tj), (length + 4.0 * v0 * tj) / (4.0 * tj * tj))
        if abs(at) < jm * tj:
            if v0 == 0:
                tj = min(
                    tj,
                    (length * math.pi / (8.0 * sm)) ** 0.25,
                    (vm * math.pi / (4.0 * sm)) ** (1.0 / 3.0),
                    math.sqrt(max(0.0, am * math.pi / (2.0 * sm))),
                )
                jm = 2.0 * sm * tj / math.pi
                am = jm * tj
            else:
                am = at
                jm = am / tj
            if vm <= v0 + 2.0 * am * tj or length <= 4.0 * v0 * tj + 4.0 * am * tj * tj:
                t2 = t4 = t6 = 0.0  # solution 0
            else:
                t2, t4, t6 = 0.0, max(_t4(jm, v0, am, vm, length, tj), 0.0), 0.0  # solution 2
        else:
            if vm < v0 + am * tj + am * am / jm or length < (
                (am**3 + am * jm * (v0 * 2.0 + am * tj * 2.0)) / (jm * jm) + v0 * tj * 2.0 + am * tj * tj
            ):
                am = min(am, _am_solution_5(jm, v0, vm, length, tj))  # solution 5: no constant speed
                t2 = am / jm - tj
                t4, t6 = 0.0, t2
            else:
                t2 = am / jm - tj  # solution 7
                t4, t6 = max(_t4(jm, v0, am, vm, length, tj), 0.0), t2
        if not all(math.isfinite(x) and x >= 0 for x in (jm, tj, t2, t4, t6)):
            return 0.0, tj, 0.0, 0.0, 0.0  # as SCurve.cpp: no jerk, no segments
        return jm, tj, t2, t4, t6

    def _add_segments_jerk(self, index: int, tj: float, jm: float, tcj: float) -> int:
        index = self._add_segment_incr_jerk(index, tj, jm)
        index = self._add_segment_const_jerk(index, tcj, jm)
        return self._add_segment_decr_jerk(index, tj, jm)

    def _add_segment_const_jerk(self, index: int, tj: float, j0: float) -> int:
        return self._add_profile(index, tj, j0, SegmentType.CONSTANT_JERK)

    def _add_segment_incr_jerk(self, index: int, tj: float, jm: float) -> int:
        return self._add_profile(index, tj, jm, SegmentType.POSITIVE_JERK)

    def _add_segment_decr_jerk(self, index: int, tj: float, jm: float) -> int:
        return self._add_profile(index, tj, jm, SegmentType.NEGATIVE_JERK)

    def _add_profile(self, index: int, tj: float, jm: float, kind: SegmentType) -> int:
        """Segment ``index``: ``tj`` of jerk ``kind`` from where the one before ends (its end values
        are the profile's at ``tj``, which are SCurve.cpp's add_segment_* formulas); none long,
        a copy of that end (constant jerk, the raised-cosine ones' jerk 0)."""
        p = self.segment[index - 1]
        if tj <= 0:
            jerk = jm if kind == SegmentType.CONSTANT_JERK else 0.0
            return self._add_segment(
                index, p.end_time, SegmentType.CONSTANT_JERK, jerk, p.end_accel, p.end_vel, p.end_pos
            )
        _, a, v, pos = _PROFILES[kind](tj, tj, jm, p.end_accel, p.end_vel, p.end_pos)
        return self._add_segment(index, p.end_time + tj, kind, jm, a, v, pos)

    def _add_segment(
        self,
        index: int,
        end_time: float,
        seg_type: SegmentType,
        jerk_ref: float,
        end_accel: float,
        end_vel: float,
        end_pos: float,
    ) -> int:
        self.segment[index].set(end_time, seg_type, jerk_ref, end_accel, end_vel, end_pos)
        return index + 1

    def valid(self) -> bool:
        if self.num_segs != SEGMENTS_MAX:
            return False
        for i, s in enumerate(self.segment):
            values = (s.jerk_ref, s.end_time, s.end_accel, s.end_vel, s.end_pos)
            if not all(math.isfinite(v) for v in values) or s.end_vel < -1e-6:
                return False
            if i and (
                s.end_time < self.segment[i - 1].end_time - 1e-6
                or s.end_pos < self.segment[i - 1].end_pos - 1e-6
            ):
                return False
        return abs(self.segment[-1].end_accel) < 1e-6

    # --- flying it ----------------------------------------------------------------------------
    def advance_target_along_track(
        self,
        prev_leg: SCurve,
        next_leg: SCurve,
        wp_radius: float,
        accel_corner: float,
        fast_waypoint: bool,
        dt: float,
        target: list[np.ndarray],
    ) -> bool:
        """Move ``dt`` along this leg (and the tail of ``prev_leg``, and ``next_leg`` once the turn has
        begun), adding to ``target`` = [pos (this leg's origin on entry), vel, accel]. True once
        this leg is finished, or half way through the turn onto ``next_leg``."""
        prev_leg.move_to_pos_vel_accel(dt, target)
        self.move_from_pos_vel_accel(dt, target)
        s_finished = self.finished()
        time_to_destination = self.get_time_remaining()
        if (
            fast_waypoint
            and next_leg.time == 0
            and self.time >= self.time_decel_start()
            and time_to_destination <= next_leg.time_accel_end()
        ):
            turn = [-self.seg_delta.copy(), np.zeros(3), np.zeros(3)]
            self.move_from_time_pos_vel_accel(self.time + time_to_destination * 0.5, turn)
            next_leg.move_from_time_pos_vel_accel(time_to_destination * 0.5, turn)
            speed_min = min(self.vel_max, next_leg.vel_max)
            accel_z_lim = min(self.accel_z_max, next_leg.accel_z_max)
            if (
                np.linalg.norm(turn[0]) < wp_radius
                and np.linalg.norm(turn[1]) < speed_min
                and math.hypot(turn[2][0], turn[2][1]) < accel_corner
                and abs(turn[2][2]) < accel_z_lim
            ):
                next_leg.move_from_pos_vel_accel(dt, target)
        elif next_leg.time != 0:
            next_leg.move_from_pos_vel_accel(dt, target)
            if next_leg.time >= self.get_time_remaining():
                s_finished = True
        return s_finished

    def finished(self) -> bool:
        return self.time >= self.time_end()

    def move_from_pos_vel_accel(self, dt: float, target: list[np.ndarray]) -> None:
        self.time = min(self.time + dt, self.time_end())
        self.move_from_time_pos_vel_accel(self.time, target)

    def move_to_pos_vel_accel(self, dt: float, target: list[np.ndarray]) -> None:
        self.move_from_pos_vel_accel(dt, target)
        target[0] -= self.seg_delta

    def move_from_time_pos_vel_accel(self, time_now: float, target: list[np.ndarray]) -> None:
        _, a, v, p = self.get_jerk_accel_vel_pos_at_time(time_now)
        if self.seg_length == 0:
            return
        unit = self.seg_delta / self.seg_length
        target[0] += unit * p
        target[1] += unit * v
        target[2] += unit * a

    def time_end(self) -> float:
        return self.segment[SEG_DECEL_END].end_time if self.num_segs == SEGMENTS_MAX else 0.0

    def get_time_remaining(self) -> float:
        return self.segment[SEG_DECEL_END].end_time - self.time if self.num_segs == SEGMENTS_MAX else 0.0

    def time_accel_end(self) -> float:
        return self.segment[SEG_ACCEL_END].end_time if self.num_segs == SEGMENTS_MAX else 0.0

    def time_decel_start(self) -> float:
        return self.segment[SEG_CONST].end_time if self.num_segs == SEGMENTS_MAX else 0.0

    def get_jerk_accel_vel_pos_at_time(self, time_now: float) -> tuple[float, float, float, float]:
        """(jerk, acceleration, speed, distance) along the leg at ``time_now``."""
        if self.num_segs != SEGMENTS_MAX:
            return 0.0, 0.0, 0.0, 0.0
        seg = self.segment
        pnt = next((i for i in range(self.num_segs) if time_now < seg[i].end_time), self.num_segs)
        if pnt == 0 or pnt == self.num_segs:
            s = seg[0] if pnt == 0 else seg[pnt - 1]
            kind, jm, tj, t0, a0, v0, p0 = (
                SegmentType.CONSTANT_JERK,
                0.0,
                0.0,
                s.end_time,
                s.end_accel,
                s.end_vel,
                s.end_pos,
            )
        else:
            s, p = seg[pnt], seg[pnt - 1]
            kind, jm, tj = s.seg_type, s.jerk_ref, s.end_time - p.end_time
            t0, a0, v0, p0 = p.end_time, p.end_accel, p.end_vel, p.end_pos
        t = time_now - t0
        if kind != SegmentType.CONSTANT_JERK and tj <= 0:
            return 0.0, a0, v0, max(0.0, p0)
        j, a, v, pos = _PROFILES[kind](t, tj, jm, a0, v0, p0)
        return j, a, v, max(0.0, pos)


def _incr_jerk(
    t: float, tj: float, jm: float, a0: float, v0: float, p0: float
) -> tuple[float, float, float, float]:
    alpha, beta = jm * 0.5, math.pi / tj
    return (
        alpha * (1.0 - math.cos(beta * t)),
        a0 + alpha * t - alpha / beta * math.sin(beta * t),
        v0 + a0 * t + alpha * 0.5 * t * t + alpha / beta**2 * math.cos(beta * t) - alpha / beta**2,
        p0
        + v0 * t
        + 0.5 * a0 * t * t
        - alpha / beta**2 * t
        + alpha * t**3 / 6.0
        + alpha / beta**3 * math.sin(beta * t),
    )


def _decr_jerk(
    t: float, tj: float, jm: float, a0: float, v0: float, p0: float
) -> tuple[float, float, float, float]:
    alpha, beta = jm * 0.5, math.pi / tj
    at = alpha * tj
    vt = alpha * (tj * tj * 0.5 - 2.0 / beta**2)
    pt = alpha * (-tj / beta**2 + tj**3 / 6.0)
    u = t + tj
    return (
        alpha * (1.0 - math.cos(beta * u)),
        a0 - at + alpha * u - alpha / beta * math.sin(beta * u),
        v0
        - vt
        + (a0 - at) * t
        + 0.5 * alpha * u * u
        + alpha / beta**2 * math.cos(beta * u)
        - alpha / beta**2,
        p0
        - pt
        + (v0 - vt) * t
        + 0.5 * (a0 - at) * t * t
        - alpha / beta**2 * u
        + alpha / 6.0 * u**3
        + alpha / beta**3 * math.sin(beta * u),
    )


def _const_jerk(
    t: float, tj: float, jm: float, a0: float, v0: float, p0: float
) -> tuple[float, float, float, float]:
    return jm, a0 + jm * t, v0 + a0 * t + 0.5 * jm * t * t, p0 + v0 * t + 0.5 * a0 * t * t + jm * t**3 / 6.0


_PROFILES = {
    SegmentType.CONSTANT_JERK: _const_jerk,
    SegmentType.POSITIVE_JERK: _incr_jerk,
    SegmentType.NEGATIVE_JERK: _decr_jerk,
}  # (t, tj, jm, a0, v0, p0) -> (jerk, acceleration, speed, distance) t into a segment


def _t4(jm: float, v0: float, am: float, vm: float, length: float, tj: float) -> float:
    """The constant-acceleration time of solutions 2 and 7 (SCurve::calculate_path's t4_out)."""
    root = math.sqrt(
        max(
            0.0,
            am**4 / 4.0
            + jm * jm * v0 * v0
            + am * am * jm * jm * tj * tj / 4.0
            + am * jm * jm * length * 2.0
            - am * am * jm * v0
            + am**3 * jm * tj / 2.0
            - am * jm * jm * v0 * tj,
        )
    )
    base = -1.5 * am * am - jm * v0 - 1.5 * am * jm * tj
    return min(
        -(v0 - vm + am * tj + am * am / jm) / am, max((base + root) / (am * jm), (base - root) / (am * jm))
    )


def _am_solution_5(jm: float, v0: float, vm: float, length: float, tj: float) -> float:
    """The acceleration of solution 5 (no constant-speed part in the ramp), as SCurve::calculate_path
    writes it: the smaller of the speed's and the length's roots."""
    root_v = math.sqrt(max(0.0, (v0 * -4.0 + vm * 4.0 + jm * tj * tj) / jm))
    by_speed = max(jm * (tj + root_v) * -0.5, jm * (tj - root_v) * -0.5)
    q = jm * jm * tj * tj / 9.0 - jm * v0 * 2.0 / 3.0
    r = (
        jm * jm * length * 0.5
        - jm**3 * tj**3 * 8.0 / 27.0
        + jm * tj * (jm * jm * tj * tj + jm * v0 * 2.0) / 3.0
        - jm * jm * v0 * tj
    )
    s = math.sqrt(max(0.0, r * r - q**3))
    cube = (s + r) ** (1.0 / 3.0) if s + r >= 0 else math.nan  # powf of a negative base is NaN
    by_length = jm * tj * (-2.0 / 3.0) + q / cube + cube
    return min(by_speed, by_length)
