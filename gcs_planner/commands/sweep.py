"""Run a study: a scenario's planner over a grid of parameters and seeds, resumable, on processes or Dask."""

from __future__ import annotations

import argparse
import csv
import io
from pathlib import Path

from gcs_planner.analysis.sweep import load_study, run_study, summarise
from gcs_planner.analysis.sweep_plots import write_plots
from gcs_planner.commands.progress import counting_bar
from gcs_planner.core.errors import UserError
from gcs_planner.core.validation import not_an_input, output_file, write_text_atomic


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("study", type=Path, help="study TOML (see gcs_planner/analysis/sweep.py, studies/)")
    p.add_argument("-o", "--out", default=None, help="results CSV, appended and resumed [out/<study>.csv]")
    p.add_argument("--workers", type=int, default=2, help="local worker processes [2]")
    p.add_argument("--scheduler", default=None, help="Dask scheduler tcp://HOST:PORT or 'local'")
    p.add_argument(
        "--allow-user-task",
        action="store_true",
        help="let the study's task name your own package.module:function (it runs your code) [off]",
    )


def run(args: argparse.Namespace) -> int:
    if args.workers < 1:
        raise UserError(f"--workers must be >= 1, got {args.workers}")
    study, base = load_study(args.study, args.allow_user_task)
    if args.out:
        out = output_file(args.out, "-o", [args.study])
    else:
        out = Path("out") / f"{args.study.stem}.csv"
        try:
            out.parent.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise UserError(f"cannot make the folder {str(out.parent)!r}: {exc.strerror or exc}") from None
    with counting_bar("sweeping", "run") as progress:
        ran = run_study(
            study, base, out, args.workers, args.scheduler, progress, allow_user_task=args.allow_user_task
        )
    summary = summarise(study, out)
    summary_path = out.with_name(out.stem + "_summary.csv")
    for extra in (summary_path, out.with_name(out.stem + "_plots.png")):
        not_an_input(extra, [args.study], "-o")
    text = io.StringIO(newline="")
    writer = csv.DictWriter(text, list(summary[0]) if summary else ["runs"])
    writer.writeheader()
    writer.writerows(summary)
    write_text_atomic(summary_path, text.getvalue())  # a full disk: one line, no partial summary
    plots = write_plots(study, out, out.with_name(out.stem + "_plots.png"))
    print(f"{ran} runs now, results {out}, summary {summary_path}" + (f", plots {plots}" if plots else ""))
    for entry in summary:
        said = (f"{k} {v:.4g}" if isinstance(v, float) else f"{k} {v}" for k, v in entry.items())
        print("  " + ", ".join(said))
    return 0
