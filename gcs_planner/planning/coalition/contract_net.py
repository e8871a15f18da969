"""Contract-net messages and rules (section 3.2, eqs. 19-25): tender, bid, award, eligibility, timing.

Timing (eqs. 20-21): delta_max = 3 dt_d + t_TA + delta_t, t_e^s = t_0 + delta_max. The leader
closes the bid book at t_close = t_0 + 2 dt_d + delta_t (= t_e^s - dt_d - t_TA) so that the
formation compute (budget t_TA) and the award message (dt_d) finish by t_e^s; a bid arriving
after t_close (hence any bid after t_e^s) is ignored. Members start their task paths at t_e^s
from the pose they predicted in their bid.

Eligibility of a receiver (choices where the paper is loose):
- idle: no unfinished task and not locked to another tender (the paper's examples list busy
  UAVs as potential members; we do not);
- capability: it can take at least one task of the tender (munitions > 0 for strikes, E payload
  for assessments) with range left for the ETA path;
- stays in range: its own kinematics and the leader's (sent in the tender) are propagated over
  [t_0, t_e^s] at 0.1 s and the distance must stay <= r_n throughout.
Conflicting tenders: a leader whose own tender is open and who receives a tender with a larger
reward cancels its own, stores it, bids on the other, and re-tenders when it is idle again.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

from gcs_planner.planning.coalition.model import CoalitionParams, Target
from gcs_planner.planning.coalition.paths import free_heading_lengths
from gcs_planner.planning.coalition.track import Loiter

__all__ = ["Award", "Bid", "Tender", "bid_for", "stays_in_range", "tender_times"]


class Poses(Protocol):
    """A UAV's poses over time: a planned Track, or live telemetry propagated (the online engine)."""

    def state_at(self, t_s) -> np.ndarray: ...


@dataclass
class Tender:
    """Eq. 19 plus the leader's state (its loiter, so bidders can propagate it) and the task reward."""

    key: int
    leader: int
    target: Target
    t0_s: float
    t_close_s: float
    t_es_s: float
    leader_loiter: Loiter
    reward: float
    n_strikes: int
    n_assess: int
    bids: list[Bid] = field(default_factory=list)
    cancelled: bool = False


@dataclass(frozen=True)
class Bid:
    """Eq. 22: who, which target, speed, heading and position predicted at t_e^s, capability, range, ETA."""

    uav: int
    tender_key: int
    speed_mps: float
    pose_at_tes: tuple[float, float, float]
    munitions: int
    can_assess: bool
    range_left_m: float
    eta_s: float
    t_sent_s: float


@dataclass(frozen=True)
class Award:
    """Eq. 25: coalition members, target, this member's task, execution angle alpha and time lambda."""

    leader: int
    uav: int
    tender_key: int
    target_id: str
    members: tuple[int, ...]
    task: str  # "strike" | "assess"
    angle_rad: float
    time_s: float  # lambda_j: strike time at the entry pose, or assessment start


def tender_times(t0_s: float, params: CoalitionParams) -> tuple[float, float]:
    """(t_close, t_e^s) for a tender issued at t0_s."""
    t_es = t0_s + params.delta_max_s
    return t_es - params.delay_s - params.t_ta_s, t_es


def stays_in_range(own: Poses, leader: Loiter, t0_s: float, t1_s: float, range_m: float) -> bool:
    """Propagate both UAVs over [t0, t1] (0.1 s steps): always within range_m of each other?"""
    t = np.linspace(t0_s, t1_s, max(2, int(np.ceil((t1_s - t0_s) / 0.1)) + 1))
    a, b = own.state_at(t), leader.state(t)
    return bool(np.all(np.hypot(a[:, 0] - b[:, 0], a[:, 1] - b[:, 1]) <= range_m))


def bid_for(
    uav: int,
    track: Poses,
    speed_mps: float,
    r_min_m: float,
    munitions: int,
    can_assess: bool,
    range_left_m: float,
    tender: Tender,
    t_now_s: float,
    params: CoalitionParams,
    check_range: bool = True,
) -> tuple[Bid | None, str]:
    """The bid of an idle UAV for a tender, or None with the reason it is not a potential member."""
    if not ((tender.n_strikes and munitions > 0) or (tender.n_assess and can_assess)):
        return None, "no matching capability"
    if check_range and not stays_in_range(
        track, tender.leader_loiter, tender.t0_s, tender.t_es_s, params.link_range_m
    ):
        return None, "predicted out of range before t_e^s"
    pose = track.state_at(tender.t_es_s)[0]
    dist = float(free_heading_lengths(pose[None], np.asarray(tender.target.xy), r_min_m)[0])  # eq. 23
    if dist >= range_left_m - speed_mps * (tender.t_es_s - t_now_s):
        return None, "not enough range"
    return (
        Bid(
            uav=uav,
            tender_key=tender.key,
            speed_mps=speed_mps,
            pose_at_tes=tuple(float(v) for v in pose),
            munitions=munitions,
            can_assess=can_assess,
            range_left_m=range_left_m - speed_mps * (tender.t_es_s - t_now_s),
            eta_s=tender.t_es_s + dist / speed_mps,
            t_sent_s=t_now_s,
        ),
        "",
    )
