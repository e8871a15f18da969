"""Per-UAV kinematics (eq. 2) as a flown track: sampled path legs, then a loiter circle forever.

A UAV always flies at constant speed and altitude. Between tasks it loiters on a circle (an idle
UAV "flying" in the paper); during a task it follows a planned, sampled Dubins leg. Propagating
the kinematics (bids' stay-in-range prediction, predicted pose at t_e^s) is evaluating
``state_at`` in the future: the leg if one is planned, else the analytic loiter. Heading control
dynamics (W_phi) are not modelled: legs are curvature-limited already.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

__all__ = ["Leg", "Loiter", "Track"]


@dataclass(frozen=True)
class Loiter:
    """Circle of radius_m about centre, direction +1 CCW / -1 CW, at phase0 [rad] at time t0_s."""

    centre: tuple[float, float]
    radius_m: float
    direction: float
    t0_s: float
    phase0_rad: float
    speed_mps: float

    def state(self, t_s: np.ndarray) -> np.ndarray:
        """(len(t), 3) of x, y, heading [rad] at times t_s."""
        t_s = np.atleast_1d(np.asarray(t_s, dtype=float))
        th = self.phase0_rad + self.direction * self.speed_mps * (t_s - self.t0_s) / self.radius_m
        x = self.centre[0] + self.radius_m * np.cos(th)
        y = self.centre[1] + self.radius_m * np.sin(th)
        return np.column_stack([x, y, th + self.direction * np.pi / 2])

    @classmethod
    def through(cls, x, y, heading, t_s, radius_m, speed_mps, direction=1.0) -> Loiter:
        """The loiter circle that passes through pose (x, y, heading) at t_s, turning `direction`."""
        cx = x - direction * radius_m * np.sin(heading)
        cy = y + direction * radius_m * np.cos(heading)
        return cls(
            (float(cx), float(cy)), radius_m, direction, t_s, float(np.arctan2(y - cy, x - cx)), speed_mps
        )


@dataclass
class Leg:
    """A flown or planned piece: times [s], positions [m], headings [rad], and what it is for."""

    t: np.ndarray
    xy: np.ndarray
    heading: np.ndarray
    kind: str  # "loiter", "recon", "strike", "assess", "transit"
    info: dict = field(default_factory=dict)


@dataclass
class Track:
    """History of legs plus the future: the active leg (if any) and the loiter after it."""

    legs: list[Leg]
    loiter: Loiter
    loiter_since_s: float = 0.0

    def state_at(self, t_s) -> np.ndarray:
        """(len(t), 3) x, y, heading at future (or present) times; vectorised over t."""
        t = np.atleast_1d(np.asarray(t_s, dtype=float))
        out = self.loiter.state(t)
        if self.legs:
            leg = self.legs[-1]
            inside = (t >= leg.t[0]) & (t <= leg.t[-1])
            if inside.any():
                ti = t[inside]
                out[inside, 0] = np.interp(ti, leg.t, leg.xy[:, 0])
                out[inside, 1] = np.interp(ti, leg.t, leg.xy[:, 1])
                out[inside, 2] = np.interp(ti, leg.t, np.unwrap(leg.heading))
        return out

    def start_leg(self, leg: Leg, loiter: Loiter, sample_dt_s: float = 1.0) -> None:
        """Fly `leg` from its first time on (cutting whatever was planned after), then `loiter`."""
        t0 = float(leg.t[0])
        if self.legs and self.legs[-1].t[-1] > t0:
            last = self.legs[-1]
            keep = last.t < t0
            if keep.sum() < 2:
                self.legs.pop()
            else:
                self.legs[-1] = Leg(last.t[keep], last.xy[keep], last.heading[keep], last.kind, last.info)
        gap_start = self.legs[-1].t[-1] if self.legs else self.loiter_since_s
        if t0 - gap_start > 1e-6:
            # materialise the loiter flown since the last leg so the history is continuous
            n = max(2, int(np.ceil((t0 - gap_start) / sample_dt_s)) + 1)
            ts = np.linspace(gap_start, t0, n)
            s = self.loiter.state(ts)
            self.legs.append(Leg(ts, s[:, :2], s[:, 2], "loiter"))
        self.legs.append(leg)
        self.loiter = loiter
        self.loiter_since_s = float(leg.t[-1])

    def history(self, t_end_s: float, sample_dt_s: float = 1.0) -> tuple[np.ndarray, np.ndarray, list[Leg]]:
        """Whole flown track up to t_end_s: times (M,), xy (M, 2), and the legs (loiter tail added)."""
        legs = [leg for leg in self.legs if leg.t[0] < t_end_s]
        start = legs[-1].t[-1] if legs else self.loiter_since_s
        if t_end_s > start:
            n = max(2, int(np.ceil((t_end_s - start) / sample_dt_s)) + 1)
            ts = np.linspace(start, t_end_s, n)
            s = self.loiter.state(ts)
            legs = [*legs, Leg(ts, s[:, :2], s[:, 2], "loiter")]
        t = np.concatenate([leg.t for leg in legs])
        xy = np.concatenate([leg.xy for leg in legs])
        keep = np.r_[True, np.diff(t) > 1e-9]
        keep &= t <= t_end_s + 1e-9
        return t[keep], xy[keep], legs
