"""The flight report: one PNG per `fly` with what the conformance table only counts.

Panels: the map (flown tracks solid, planned paths dashed over them, obstacles, manned traffic,
where each vehicle's cross-track error peaked), cross-track error over time per vehicle against
the bound (on the route, from leaving its first point to reaching its last, as conformance.py
judges it; a symmetric-log axis, so sub-metre traces and the bound both show), the smallest
distance to any other vehicle over time against the separation, and the conformance table (a
failing row in red). A fleet past ``TABLE_ROWS`` gets the failing and worst rows and a line naming
every other vehicle; past ``LEGEND_MAX`` its tracks are labelled by sysid instead of a legend.
Written with matplotlib's Agg backend (no display).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

from gcs_planner.core.fleet_ids import id_runs
from gcs_planner.core.validation import atomic_write
from gcs_planner.model.plan import Plan
from gcs_planner.model.scenario import Scenario
from gcs_planner.safety.conformance import (
    Track,
    VehicleReport,
    point_to_polyline_m,
    route_acceptance_m,
    route_window,
)
from gcs_planner.telemetry.colors import vehicle_color

__all__ = ["table_rows", "write_flight_report"]

SEPARATION_STEP_S = 0.5
TABLE_ROWS = 16  # rows the table shows; the rest are named in one line below it
LEGEND_MAX = 12  # vehicles a legend can name; past it each track is labelled by its sysid


def write_flight_report(
    path: str | Path,
    plan: Plan,
    tracks: dict[int, Track],
    reports: list[VehicleReport],
    scenario: Scenario | None = None,
    max_cross_track_m: float | None = None,
) -> Path:
    """Draw the report to ``path`` (PNG) and return it; written whole or not at all (an OSError is
    a UserError naming the path, which the CLI prints as its one line)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig = plt.figure(figsize=(15, 10), layout="constrained")
    grid = fig.add_gridspec(3, 2, width_ratios=(1.1, 1), height_ratios=(1, 1, 0.9))
    ax_map = fig.add_subplot(grid[0:2, 0])
    ax_xt = fig.add_subplot(grid[0, 1])
    ax_sep = fig.add_subplot(grid[1, 1])
    ax_table = fig.add_subplot(grid[2, :])
    route_t0 = min((t.times_s[0] for t in tracks.values() if len(t.times_s)), default=0.0)
    _map(ax_map, plan, tracks, scenario)
    _cross_track(ax_xt, plan, tracks, route_t0, max_cross_track_m)
    _separation(ax_sep, plan, tracks, route_t0, scenario)
    _table(ax_table, reports)
    passed = sum(r.passed for r in reports)
    fig.suptitle(f"{plan.planner} plan flown: {passed}/{len(reports)} vehicles conform", fontsize=14)
    path = Path(path)
    try:
        with atomic_write(path) as tmp:  # a full disk: one line (UserError), no partial report.png
            fig.savefig(tmp, dpi=90)
    finally:
        plt.close(fig)
    return path


def _color(sysid: int) -> tuple[float, float, float]:
    r, g, b = vehicle_color(sysid)[:3]
    return r / 255, g / 255, b / 255


def _map(ax, plan: Plan, tracks: dict[int, Track], scenario: Scenario | None) -> None:
    import matplotlib.patches as patches

    if scenario is not None:
        for c in scenario.cylinders:
            ax.add_patch(patches.Circle((c.x, c.y), c.radius_m, color="0.6", alpha=0.5))
            if c.buffer_m:
                ax.add_patch(
                    patches.Circle((c.x, c.y), c.radius_m + c.buffer_m, fill=False, ls=":", color="0.5")
                )
        for h in scenario.hemispheres:
            ax.add_patch(patches.Circle((h.x, h.y), h.radius_m, color="tab:red", alpha=0.15))
    many = len(plan.vehicles) > LEGEND_MAX
    for vp in plan.vehicles:
        color = _color(vp.sysid)
        ax.plot(vp.path[:, 0], vp.path[:, 1], "--", color=color, lw=0.8, alpha=0.9, zorder=3)
        track = tracks.get(vp.sysid)
        if track is None or not len(track.times_s):
            continue
        ax.plot(track.positions[:, 0], track.positions[:, 1], "-", color=color, lw=1.6, alpha=0.7,
                label=vp.vehicle_id)  # fmt: skip
        if many:
            ax.annotate(str(vp.sysid), track.positions[-1, :2], fontsize=6, color=color)
        on_route = track.positions[route_window(track, vp.path, route_acceptance_m(vp))]
        if len(on_route):
            worst = int(np.argmax(point_to_polyline_m(on_route, vp.path)))
            ax.plot(*on_route[worst, :2], "x", color=color, ms=9, mew=2)
    if scenario is not None:
        _manned(ax, scenario, max((float(v.path_times_s[-1]) for v in plan.vehicles), default=0.0))
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("east [m]")
    ax.set_ylabel("north [m]")
    ax.set_title("flown (solid), planned (dashed); x = largest cross-track error")
    if not many:
        ax.legend(loc="best", fontsize=8, ncols=2)
    ax.grid(alpha=0.3)


def _manned(ax, scenario: Scenario, duration_s: float) -> None:
    """Each [[manned]] aircraft's straight track over the flight, arrow at its end."""
    for k, m in enumerate(scenario.raw.get("manned", [])):
        if "position_m" not in m or "velocity_mps" not in m:
            continue
        p0 = np.asarray(m["position_m"], dtype=float)[:2]
        p1 = p0 + duration_s * np.asarray(m["velocity_mps"], dtype=float)[:2]
        ax.annotate("", p1, p0, arrowprops={"arrowstyle": "->", "color": "black", "ls": ":"})
        ax.annotate(f"manned {m.get('id', k)}", p0, fontsize=7)


def _cross_track(ax, plan: Plan, tracks, route_t0: float, bound: float | None) -> None:
    for vp in plan.vehicles:
        track = tracks.get(vp.sysid)
        if track is None or not len(track.times_s):
            continue
        window = route_window(track, vp.path, route_acceptance_m(vp))
        error = point_to_polyline_m(track.positions[window], vp.path)
        ax.plot(track.times_s[window] - route_t0, error, color=_color(vp.sysid), lw=1.2, label=vp.vehicle_id)
    if bound is not None:
        ax.axhline(bound, color="tab:red", ls="--", lw=1, label=f"bound {bound:g} m")
    ax.set_yscale("symlog", linthresh=1.0)
    ax.set_ylim(bottom=0.0)
    ax.set_xlabel("time [s]")
    ax.set_ylabel("cross-track [m]")
    ax.set_title("cross-track: distance from the planned path on the route (3-D)")
    ax.grid(alpha=0.3)


def _separation(ax, plan: Plan, tracks, route_t0: float, scenario: Scenario | None) -> None:
    """Each vehicle's distance to its nearest neighbour on a common time grid (tracks interpolated)."""
    flown = {s: t for s, t in tracks.items() if len(t.times_s) > 1}
    if len(flown) < 2:
        ax.text(0.5, 0.5, "one vehicle: no separation", ha="center", va="center", transform=ax.transAxes)
        return
    t0 = max(t.times_s[0] for t in flown.values())
    t1 = min(t.times_s[-1] for t in flown.values())
    grid = np.arange(t0, t1, SEPARATION_STEP_S) if t1 > t0 else np.array([t0])
    sysids = sorted(flown)
    pos = np.stack(
        [[np.interp(grid, flown[s].times_s, flown[s].positions[:, k]) for k in range(3)] for s in sysids]
    ).transpose(0, 2, 1)  # fmt: skip  (vehicle, time, xyz)
    nearest = np.empty((len(sysids), len(grid)))
    for k in range(len(grid)):  # a k-d tree per instant: 500 vehicles need no 500 x 500 matrices
        nearest[:, k] = cKDTree(pos[:, k]).query(pos[:, k], k=2)[0][:, 1]
    bounds = {v.sysid: v for v in plan.vehicles}
    for i, s in enumerate(sysids):
        ax.plot(
            grid - route_t0,
            nearest[i],
            color=_color(s),
            lw=1.2,
            label=bounds[s].vehicle_id if s in bounds else s,
        )
    if scenario is not None and scenario.vehicles:
        bound = max(v.separation_m for v in scenario.vehicles)
        ax.axhline(bound, color="tab:red", ls="--", lw=1, label=f"separation {bound:g} m")
    ax.set_xlabel("time [s]")
    ax.set_ylabel("nearest vehicle [m]")
    ax.set_yscale("log")
    ax.set_title("separation: distance to the nearest other vehicle")
    ax.grid(alpha=0.3, which="both")


def table_rows(reports: list[VehicleReport]) -> tuple[list[VehicleReport], str]:
    """The rows the table shows (every failing one first, then the largest cross-track errors,
    ``TABLE_ROWS`` at most, in sysid order) and a line naming every vehicle left out."""
    ranked = sorted(reports, key=lambda r: (r.passed, -r.cross_track_max_m))
    shown = sorted(ranked[:TABLE_ROWS], key=lambda r: r.sysid)
    rest = ranked[TABLE_ROWS:]
    if not rest:
        return shown, ""
    passing = [r.sysid for r in rest if r.passed]
    failing = [r.sysid for r in rest if not r.passed]
    parts = [f"also conforming: sysid {id_runs(passing)}"] if passing else []
    parts += [f"also failing: sysid {id_runs(failing)}"] if failing else []
    return shown, f"{len(rest)} more vehicles ({'; '.join(parts)})"


def _table(ax, reports: list[VehicleReport]) -> None:
    ax.axis("off")
    header = [
        "vehicle",
        "sysid",
        "done",
        "xt max m",
        "xt mean m",
        "min sep m",
        "obstacle m",
        "time s",
        "result",
    ]
    shown, more = table_rows(reports)
    rows = [
        [r.vehicle_id, r.sysid, "yes" if r.completed else "no", f"{r.cross_track_max_m:.2f}",
         f"{r.cross_track_mean_m:.2f}", f"{r.min_separation_m:.1f}", f"{r.min_obstacle_clearance_m:.1f}",
         f"{r.flight_time_s:.1f}", "PASS" if r.passed else "; ".join(r.failures)[:60]]
        for r in shown
    ]  # fmt: skip
    if not rows:
        return
    below = 0.1 if more else 0.0  # room for the line naming the rest
    table = ax.table(cellText=rows, colLabels=header, cellLoc="center", bbox=(0.0, below, 1.0, 1.0 - below))
    table.auto_set_font_size(False)
    table.set_fontsize(8)
    for i, r in enumerate(shown, start=1):
        if not r.passed:
            for j in range(len(header)):
                table[i, j].set_facecolor("#f8d0d0")
    if more:
        ax.text(0.5, 0.0, more, ha="center", va="bottom", fontsize=7, wrap=True, transform=ax.transAxes)
