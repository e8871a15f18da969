"""The coalition HIL report: one row per award, the flown arrival against the award.

``measure_task``: the flown arrival at the goal point (strike: stand-off entry point; assess: arc
start point) = the closest approach of the piecewise-linear flown track (time interpolated,
simulated clock), heading = that track segment's direction, both against the award (time_s;
strike heading angle_deg + 180, assessment heading the CCW tangent angle_deg + 90). An assessment
row also gives the largest radial deviation from the assessment circle over the arc's duration
(bound ``ARC_TOL_M``). Each row also gives the distance and heading between the simulated and the
flown pose at the flown leg's start (``task_rows``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import partial

import numpy as np

from gcs_planner.flight.coalition.tracks import pose_at
from gcs_planner.planning.coalition import paths
from gcs_planner.planning.coalition.track import Leg

__all__ = [
    "TaskRow",
    "add_prediction_errors",
    "format_formations",
    "format_strike_report",
    "formation_rows",
    "measure_task",
    "task_rows",
]

MEASURE_WINDOW_S = 15.0  # closest approach searched within this of the awarded time [s]
ARC_TOL_M = 50.0  # an assessment arc is flown within this of the assessment circle [m]


@dataclass
class TaskRow:
    """One award's flown arrival at its goal pose against the award, and its start-pose difference."""

    uav: str
    sysid: int
    target: str
    task: str  # "strike" | "assess"
    awarded_s: float
    flown_s: float
    awarded_heading_deg: float
    flown_heading_deg: float
    miss_m: float
    limits: tuple[float, float] = (1.0, 10.0)
    arc_dev_m: float = float("nan")  # assess: largest |distance to target - arc radius| on the arc [m]
    start_diff_m: float = float("nan")  # simulated vs flown position at the flown leg's start [m]
    start_dheading_deg: float = float("nan")  # simulated vs flown heading there [deg]

    @property
    def time_error_s(self) -> float:
        return self.flown_s - self.awarded_s

    @property
    def angle_error_deg(self) -> float:
        return float((self.flown_heading_deg - self.awarded_heading_deg + 180.0) % 360.0 - 180.0)

    @property
    def passed(self) -> bool:
        ok = abs(self.time_error_s) <= self.limits[0] and abs(self.angle_error_deg) <= self.limits[1]
        return ok and (self.task != "assess" or self.arc_dev_m <= ARC_TOL_M)


def measure_task(track_t: np.ndarray, track_xy: np.ndarray, award: dict, limits, world=None) -> TaskRow:
    """Closest approach of the flown track (scenario time, ENU) to the award's goal point: the strike
    entry point (award["entry_xy"]) or, for an assessment (``world`` needed), the arc start; plus the
    largest radial deviation over the assessment arc."""
    nan = float("nan")
    strike = award["task"] == "strike"
    t_goal = float(award["time_s"])
    if strike:
        goal = np.asarray(award["entry_xy"], dtype=float)
        awarded_heading = (award["angle_deg"] + 180.0) % 360.0
    else:
        p = world.params
        target = next(t for t in world.targets if t.id == award["target"])
        goal = paths.arc_start_pose(target.xy, math.radians(award["angle_deg"]), p.assess_radius_m)[0, :2]
        awarded_heading = (award["angle_deg"] + 90.0) % 360.0
    row = partial(TaskRow, award["uav"], award["sysid"], award["target"], award["task"], t_goal)
    sel = np.abs(track_t - t_goal) <= MEASURE_WINDOW_S
    t, pts = track_t[sel], track_xy[sel]
    if len(t) < 2:
        return row(nan, awarded_heading, nan, nan, limits)
    a, ab = pts[:-1], np.diff(pts, axis=0)
    u = np.clip(((goal - a) * ab).sum(1) / np.maximum((ab**2).sum(1), 1e-12), 0.0, 1.0)
    d = np.linalg.norm(a + u[:, None] * ab - goal, axis=1)
    k = int(np.argmin(d))
    flown_s = float(t[k] + u[k] * (t[k + 1] - t[k]))
    heading = float(np.degrees(np.arctan2(ab[k, 1], ab[k, 0])) % 360.0)
    arc_dev = nan
    if not strike:
        on_arc = (track_t >= t_goal) & (track_t <= t_goal + target.assess_duration_s)
        if on_arc.sum() >= 2:
            r = np.hypot(*(track_xy[on_arc] - np.asarray(target.xy)).T)
            arc_dev = float(np.abs(r - p.assess_radius_m).max())
    return row(flown_s, awarded_heading, heading, float(d[k]), limits, arc_dev)


def format_strike_report(rows: list[TaskRow]) -> str:
    """The report table (strikes and assessments), then the worst errors per task kind."""
    head = ("uav   sysid target task   awarded_s flown_s  dt_s   awarded_deg flown_deg dangle_deg miss_m "
            "arc_dev_m start_diff_m start_dh_deg  ok")  # fmt: skip
    lines = [head]
    for r in rows:
        lines.append(
            f"{r.uav:<5} {r.sysid:>5} {r.target:<6} {r.task:<6} {r.awarded_s:>9.2f} {r.flown_s:>7.2f} "
            f"{r.time_error_s:>+6.2f} {r.awarded_heading_deg:>11.1f} {r.flown_heading_deg:>9.1f} "
            f"{r.angle_error_deg:>+10.1f} {r.miss_m:>6.1f} {r.arc_dev_m:>9.1f} {r.start_diff_m:>12.1f} "
            f"{r.start_dheading_deg:>+12.1f}  {'yes' if r.passed else 'NO'}"
        )
    for task in ("strike", "assess"):
        sel = [r for r in rows if r.task == task]
        if sel:
            dt = np.array([abs(r.time_error_s) for r in sel])
            da = np.array([abs(r.angle_error_deg) for r in sel])
            ok = sum(r.passed for r in sel)
            lines.append(
                f"{task}: {ok}/{len(sel)} within bounds, max |dt| {np.nanmax(dt):.2f} s, "
                f"max |dangle| {np.nanmax(da):.1f} deg"
            )
    return "\n".join(lines)


def task_rows(
    world, awards: list[dict], flown: dict, flown_legs: dict[tuple[str, str], Leg], sim_tracks: dict, limits
) -> tuple[list[TaskRow], list[str]]:
    """One row per flown award (strikes first, by awarded time), and a failure for each award without
    telemetry or without an uploaded leg. flown: sysid -> (t [s, scenario], ENU [m]); sim_tracks:
    UAV id -> the simulated (t, xy)."""
    rows, failures = [], []
    for e in sorted(awards, key=lambda e: (e["task"] != "strike", e["time_s"], e["sysid"])):
        if e["sysid"] not in flown:
            failures.append(f"{e['uav']}: no telemetry")
            continue
        leg = flown_legs.get((e["target"], e["uav"]))
        if leg is None:
            failures.append(f"{e['uav']}: its {e['target']} {e['task']} award was not uploaded")
            continue
        t, positions = flown[e["sysid"]]
        row = measure_task(t, positions[:, :2], e, limits, world)
        t0 = float(leg.t[0])
        sim_pose, flown_pose = pose_at(*sim_tracks[e["uav"]], t0), pose_at(t, positions[:, :2], t0)
        row.start_diff_m = float(np.hypot(*(flown_pose[:2] - sim_pose[:2])))
        row.start_dheading_deg = float((math.degrees(flown_pose[2] - sim_pose[2]) + 180.0) % 360.0 - 180.0)
        rows.append(row)
    return rows, failures


def add_prediction_errors(uploads: list[dict], flown: dict) -> None:
    """Add to each live upload entry how far its predicted leg-start pose was from the flown one."""
    for u in uploads:
        if "live_pose" in u and u["sysid"] in flown:
            t, positions = flown[u["sysid"]]
            miss = pose_at(t, positions[:, :2], u["t0_s"])[:2] - np.asarray(u["live_pose"][:2])
            u["prediction_error_m"] = round(float(np.hypot(*miss)), 2)


def formation_rows(sim_events: list[dict], online_events: list[dict], targets) -> list[dict]:
    """The coalitions formed by the simulation and by the online run, side by side in the order they
    were formed (per target: the n-th formation of each), for the flown targets. The online run's
    re-tenders of single tasks (a lost or released member's) follow, with no simulated side."""

    def formed(events):
        return [e for e in events if e["event"] == "formed" and e["target"] in targets]

    sim = formed(sim_events)
    online = [e for e in formed(online_events) if not e.get("retender")]
    pairs = [(sim[k] if k < len(sim) else None, online[k] if k < len(online) else None)
             for k in range(max(len(sim), len(online)))]  # fmt: skip
    pairs += [(None, e) for e in formed(online_events) if e.get("retender")]
    return [{
        "target": (a or b)["target"], "retender": bool(b and b.get("retender")),
        "sim_leader": a and a["uav"], "online_leader": b and b["uav"],
        "sim_t_s": a and a["t_s"], "online_t_s": b and b["t_s"],
        "sim_members": a and a["members"], "online_members": b and b["members"],
        "same_members": bool(a and b and sorted(a["members"]) == sorted(b["members"])),
    } for a, b in pairs]  # fmt: skip


def format_formations(rows: list[dict]) -> str:
    """The formation_rows as a table: target, leaders, times, same members?"""
    lines = ["target  sim leader  online leader  sim t [s]  online t [s]  same members"]
    for r in rows:
        times = [f"{t:.2f}" if t is not None else "-" for t in (r["sim_t_s"], r["online_t_s"])]
        same = "re-tender" if r["retender"] else "yes" if r["same_members"] else "no"
        lines.append(f"{r['target']:<7} {r['sim_leader'] or '-':<11} {r['online_leader'] or '-':<14} "
                     f"{times[0]:>9}  {times[1]:>12}  {same}")  # fmt: skip
    return "\n".join(lines)
