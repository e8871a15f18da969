"""Reproduce Table 3 of seed 001 (ACMPSO): 100 independent runs each of BPSO, LPSO and ACMPSO.

Prints, per variant (literal reading / documented tuned variant / safe, see
gcs_planner/planning/acmpso.py) and algorithm: mean CPU time per run, mean fitness and fitness
variance beside the paper's numbers, the best run's fitness and convergence iteration, and how many
runs' best tracks violate a radar, an obstacle or terrain + h_safe on a dense resample (10 samples
per km) of the 100-node track (the paper checks the nodes only). Optionally writes a convergence
plot (PNG).

    nice .venv/bin/python benchmarks/acmpso_table3.py --runs 100 --plot acmpso_convergence.png

The runs are studies/acmpso_table3.toml through the sweep runner (task
gcs_planner.planning.acmpso_study:table3_run, --workers processes); they are appended to --out as
they finish, so a rerun, or `gcs-planner sweep studies/acmpso_table3.toml`, redoes no finished run.
Variance is the sample variance (ddof = 1) of the runs' final fitness; times are one run's solver
CPU time on one core (BLAS threads pinned to 1), initialisation included.
"""

from __future__ import annotations

import os

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("MKL_NUM_THREADS", "1")

import argparse  # noqa: E402
import csv  # noqa: E402
import json  # noqa: E402
import platform  # noqa: E402
from pathlib import Path  # noqa: E402

import msgspec  # noqa: E402
import numpy as np  # noqa: E402

from gcs_planner.analysis.sweep import load_study, run_study, runs  # noqa: E402
from gcs_planner.commands.progress import counting_bar  # noqa: E402
from gcs_planner.planning.acmpso import VARIANTS  # noqa: E402
from gcs_planner.planning.acmpso_study import KINDS, TABLE_ORDER  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
STUDY = ROOT / "studies" / "acmpso_table3.toml"
# paper Table 3 (MATLAB R2014a, i7-8750H): mean time [s], mean fitness, fitness variance;
# best-run convergence iteration read from its Fig. 4
PAPER = {
    "bpso": (11.579, 41.347, 1.065, 55),
    "lpso": (11.591, 38.659, 0.392, 60),
    "acmpso": (11.726, 38.597, 0.318, 45),
}


def sweep_rows(variants: list[str], runs_each: int, collision: str, seed: int, out: Path, workers: int):
    """The study's runs for these variants (run 0..runs_each - 1 of each algorithm), run where not
    yet in ``out``; its rows, keyed by (variant, algorithm) and ordered by run."""
    study, base = load_study(STUDY)
    grid = {**study.grid, "variant": variants, "collision": [collision], "base_seed": [seed]}
    study = msgspec.structs.replace(study, grid=grid, seeds=list(range(runs_each)))
    with counting_bar("table 3 runs", "run") as progress:
        run_study(study, base, out, workers, progress=progress)
    wanted = {ident for ident, _, _ in runs(study)}
    rows = [r for r in csv.DictReader(out.open(newline="")) if r["run_id"] in wanted]
    failed = [r for r in rows if r["error"]]
    if failed:
        raise SystemExit(f"{len(failed)} runs failed; run {failed[0]['run_id']}: {failed[0]['error']}")
    keyed: dict[tuple[str, str], list[dict]] = {}
    for row in sorted(rows, key=lambda r: int(r["seed"])):
        keyed.setdefault((row["variant"], row["algorithm"]), []).append(row)
    return keyed


def statistics(rows: list[dict]) -> dict:
    """One algorithm's runs as the table's statistics."""
    f = np.array([float(r["fitness"]) for r in rows])
    histories = np.array([json.loads(r["history"]) for r in rows])
    best = int(np.argmin(f))
    h = histories[best]
    return {
        "fitness": f,
        "seconds": np.array([float(r["cpu_seconds"]) for r in rows]),
        "histories": histories,
        "best": best,
        "conv_1pct": int(np.argmax(h <= h[-1] * 1.01)) + 1,
        "last_improvement": int(np.flatnonzero(np.diff(h) < -1e-9).max(initial=-1)) + 2,
        "evaluations": int(np.mean([float(r["evaluations"]) for r in rows])),
        "viol": {k: sum(r[f"{k}_violated"] == "True" for r in rows) for k in KINDS},
        "depth": {k: max(float(r[f"{k}_depth_m"]) for r in rows) for k in KINDS},
    }


def print_table(results: dict[str, dict[str, dict]], runs: int) -> None:
    head = (
        f"{'variant':8} {'algo':6} | {'time s paper':>12} {'ours':>7} | {'mean F paper':>12} {'ours':>7}"
        f" | {'var paper':>9} {'ours':>7} | {'best F':>7} {'it1%':>4} {'last':>4} {'paper':>5}"
        f" | {'evals':>5} | dense-resample violations (runs of {runs}): radar/obst/terrain"
    )
    print(head)
    print("-" * len(head))
    for variant, per_alg in results.items():
        for algorithm in TABLE_ORDER:
            s = per_alg[algorithm]
            p = PAPER[algorithm]
            f = s["fitness"]
            v = s["viol"]
            worst = "/".join(f"{s['depth'][k]:.0f}" for k in KINDS)
            print(
                f"{variant:8} {algorithm:6} | {p[0]:12.3f} {s['seconds'].mean():7.4f}"
                f" | {p[1]:12.3f} {f.mean():7.3f} | {p[2]:9.3f} {f.var(ddof=1):7.3f}"
                f" | {f.min():7.3f} {s['conv_1pct']:4d}"
                f" {s['last_improvement']:4d} {p[3]:5d} | {s['evaluations']:5d} |"
                f" {v['radar']}/{v['obstacle']}/{v['terrain']}"
                f" (worst {worst} m)"
            )
        acm, lp, bp = (per_alg[a]["fitness"] for a in ("acmpso", "lpso", "bpso"))
        print(
            f"  {variant}: ACMPSO mean <= 38.597: {acm.mean() <= 38.597};"
            f" var <= 0.318: {acm.var(ddof=1) <= 0.318};"
            f" ACMPSO < LPSO < BPSO: {acm.mean() < lp.mean() < bp.mean()}"
        )
        times = "; ".join(
            f"{a} median {np.median(per_alg[a]['seconds']):.4f} min {per_alg[a]['seconds'].min():.4f}"
            for a in TABLE_ORDER
        )
        print(f"  {variant}: CPU s per run: {times}")
        n = len(acm)
        se = np.sqrt(acm.var(ddof=1) / n + lp.var(ddof=1) / n)
        se_paper = np.sqrt((PAPER["acmpso"][2] + PAPER["lpso"][2]) / 100)
        print(
            f"  {variant}: mean(ACMPSO) - mean(LPSO) = {acm.mean() - lp.mean():+.4f} +- {se:.4f} (1 s.e.);"
            f" paper {PAPER['acmpso'][1] - PAPER['lpso'][1]:+.3f} +- {se_paper:.3f}"
        )


def plot(results: dict[str, dict[str, dict]], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(results), figsize=(6 * len(results), 4.2), squeeze=False)
    for ax, (variant, per_alg) in zip(axes[0], results.items(), strict=True):
        for algorithm, colour in zip(TABLE_ORDER, ("tab:gray", "tab:blue", "tab:red"), strict=True):
            s = per_alg[algorithm]
            it = np.arange(1, s["histories"].shape[1] + 1)
            ax.plot(it, s["histories"][s["best"]], color=colour, label=f"{algorithm.upper()} best run")
            ax.plot(
                it,
                s["histories"].mean(axis=0),
                color=colour,
                ls="--",
                lw=1,
                label=f"{algorithm.upper()} mean",
            )
        ax.axhline(37.339, color="k", lw=0.8, ls=":", label="straight-line bound 37.339")
        ax.set(title=f"{variant} reading", xlabel="iteration", ylabel="best fitness F", ylim=(37.0, 48.0))
        ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=120)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=100)
    ap.add_argument("--variants", default=",".join(VARIANTS), help="comma-separated: literal,tuned,safe")
    ap.add_argument("--collision", default="literal", choices=("literal", "depth"))
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--workers", type=int, default=2, help="sweep runner processes [2]")
    ap.add_argument("--out", type=Path, default=Path("out/acmpso_table3.csv"), help="runs CSV, resumed")
    ap.add_argument("--plot", type=Path, help="write the convergence plot (PNG) here")
    args = ap.parse_args()
    variants = [v.strip() for v in args.variants.split(",") if v.strip()]
    for v in variants:
        if v not in VARIANTS:
            ap.error(f"--variants: {v!r} is not one of {VARIANTS}")
    print(
        f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cpus, python"
        f" {platform.python_version()}, numpy {np.__version__}; runs={args.runs},"
        f" 50 particles x 100 iterations, collision={args.collision}, seed={args.seed}"
    )
    args.out.parent.mkdir(parents=True, exist_ok=True)
    keyed = sweep_rows(variants, args.runs, args.collision, args.seed, args.out, args.workers)
    results = {v: {a: statistics(keyed[v, a]) for a in TABLE_ORDER} for v in variants}
    print_table(results, args.runs)
    if args.plot:
        plot(results, args.plot)
        print(f"convergence plot: {args.plot}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
