"""A sweep's per-parameter curves as one PNG: each metric's mean and spread against each grid key."""

from __future__ import annotations

from pathlib import Path

from gcs_planner.analysis.sweep import Study, marginals
from gcs_planner.core.validation import atomic_write


def write_plots(study: Study, results: Path, path: Path) -> Path | None:
    """One row per numeric metric, one column per grid key: mean +- standard deviation over the runs
    with each value of the key (the other keys and the seeds pooled). None when there is nothing to
    draw (no grid, no numeric metric)."""
    keys = sorted(study.grid)
    if not keys:
        return None
    curves = marginals(study, results)
    numeric = [m for (m, _key), points in curves.items() if any(count for *_, count in points)]
    metrics = list(dict.fromkeys(numeric))  # a metric with no number (a JSON history) is not drawn
    if not metrics:
        return None
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(
        len(metrics), len(keys), figsize=(3.2 * len(keys), 2.4 * len(metrics)), squeeze=False
    )
    for row, m in enumerate(metrics):
        for col, key in enumerate(keys):
            ax = axes[row][col]
            labels, means, stds, _ = zip(*curves[m, key], strict=True)
            x = range(len(labels))
            ax.errorbar(x, means, yerr=stds, marker="o", capsize=3)
            ax.set_xticks(list(x), labels)
            ax.set_xlabel(key)
            if col == 0:
                ax.set_ylabel(m)
    fig.suptitle(f"{study.name}: mean +- std over runs")
    fig.tight_layout()
    try:
        with atomic_write(path) as tmp:  # a full disk: one line (UserError), no partial PNG
            fig.savefig(tmp, dpi=90)
    finally:
        plt.close(fig)
    return path
