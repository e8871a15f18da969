"""Rerun every figure the docs quote and write each to docs/results/<name>.md.

    python benchmarks/run_all.py                 # every figure (several hours on 2 cores)
    python benchmarks/run_all.py --list          # names, minutes, commands
    python benchmarks/run_all.py --only logging_throughput,mcap_writers
    python benchmarks/run_all.py --quick         # smaller runs into out/results-quick/

The figures and their commands are benchmarks/figures.py. Each figure's scratch files go to
out/results/<name>/ (emptied first, so a resumable benchmark starts afresh). A figure whose
``needs`` do not import is skipped with the reason. Exit 1 when a command failed (its file is
still written, with its exit status and the end of its stderr).
"""

from __future__ import annotations

import argparse
import importlib.util
import os
import resource
import shlex
import shutil
import subprocess
import sys
import time
from datetime import UTC, datetime
from pathlib import Path

from figures import FIGURES, Figure, by_name
from results_md import StepResult, code_line, load_line, machine_line, notes_of, render

ROOT = Path(__file__).resolve().parents[1]
BIN = Path(sys.executable).parent
TOOLS = {
    "python": sys.executable,
    "gcs-planner": str(BIN / "gcs-planner"),
    "sitl-mock": str(BIN / "sitl-mock"),
}


def _children_cpu_s() -> float:
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def run_step(command: str, timeout_s: float | None) -> StepResult:
    """Run one command from the repository root, echoing its output as it comes."""
    argv = shlex.split(command)
    argv[0] = TOOLS.get(argv[0], argv[0])
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(ROOT), str(ROOT / "tests")]))
    cpu0, t0 = _children_cpu_s(), time.perf_counter()
    proc = subprocess.Popen(
        argv, cwd=ROOT, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
    )
    try:
        stdout, stderr = proc.communicate(timeout=timeout_s)
    except subprocess.TimeoutExpired:
        proc.kill()
        stdout, stderr = proc.communicate()
        stderr += f"\nrun_all: killed after {timeout_s:.0f} s"
    for line in stdout.splitlines():
        print(f"    | {line}", file=sys.stderr)
    tail = "\n".join(stderr.strip().splitlines()[-15:])
    return StepResult(
        command, stdout, tail, time.perf_counter() - t0, _children_cpu_s() - cpu0, proc.returncode
    )


def missing_needs(figure: Figure) -> list[str]:
    """The modules a figure needs that do not import here."""
    return [m for m in figure.needs if importlib.util.find_spec(m) is None]


def run_figure(
    figure: Figure, quick: bool, results: Path, timeout_s: float | None, scratch_root: Path = ROOT / "out"
) -> bool:
    """Run a figure's steps and write its results file; False when a step failed."""
    scratch = scratch_root / ("results-quick" if quick else "results") / figure.name
    shutil.rmtree(scratch, ignore_errors=True)
    scratch.mkdir(parents=True)
    where = scratch.relative_to(ROOT) if scratch.is_relative_to(ROOT) else scratch
    commands = [c.replace("{out}", str(where)) for c in (figure.quick if quick else figure.steps)]
    facts = {"date": datetime.now(UTC).strftime("%Y-%m-%d %H:%M UTC"), "machine": machine_line()}
    facts["code"] = code_line()
    facts["load before (uptime)"] = f"`{load_line()}`"
    steps = []
    for i, command in enumerate(commands, 1):
        print(f"  step {i}/{len(commands)}: {command}", file=sys.stderr, flush=True)
        steps.append(run_step(command, timeout_s))
        print(f"  step {i}: exit {steps[-1].returncode}, {steps[-1].wall_s:.1f} s wall", file=sys.stderr)
    facts["load after (uptime)"] = f"`{load_line()}`"
    rerun = "--quick " if quick else ""
    facts["regenerate"] = f"`python benchmarks/run_all.py {rerun}--only {figure.name}`"
    path = results / f"{figure.name}.md"
    path.write_text(render(figure.name, figure.title, facts, steps, figure.markdown, notes_of(path)))
    print(f"  wrote {path.relative_to(ROOT) if path.is_relative_to(ROOT) else path}", file=sys.stderr)
    return all(s.returncode == 0 for s in steps)


def _selected(only: str | None, quick: bool) -> list[Figure]:
    figures = [by_name(n.strip()) for n in only.split(",") if n.strip()] if only else list(FIGURES)
    return [f for f in figures if f.quick] if quick and not only else figures


def _list() -> None:
    for f in FIGURES:
        quick = "quick" if f.quick else "no quick run"
        needs = f"; needs {', '.join(f.needs)}" if f.needs else ""
        print(f"{f.name:<24} ~{f.minutes:g} min ({quick}{needs}): {f.title}")
        for step in f.steps:
            print(f"    {step.replace('{out}', f'out/results/{f.name}')}")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--list", action="store_true", help="list the figures and their commands, run nothing")
    ap.add_argument("--only", help="comma-separated figure names (see --list)")
    ap.add_argument(
        "--quick", action="store_true", help="each figure's smaller run; skips figures without one"
    )
    ap.add_argument(
        "--results", type=Path, help="folder of the results files [docs/results; --quick: out/results-quick]"
    )
    ap.add_argument("--timeout-min", type=float, default=None, help="kill a command after this many minutes")
    args = ap.parse_args(argv)
    if args.list:
        _list()
        return 0
    try:
        figures = _selected(args.only, args.quick)
    except KeyError as exc:
        print(f"run_all: error: --only: unknown figure {exc.args[0]}", file=sys.stderr)
        return 2
    if args.quick and any(not f.quick for f in figures):
        names = ", ".join(f.name for f in figures if not f.quick)
        print(f"run_all: error: --quick: no quick run for {names}", file=sys.stderr)
        return 2
    results = args.results or ROOT / ("out/results-quick" if args.quick else "docs/results")
    results.mkdir(parents=True, exist_ok=True)
    timeout_s = args.timeout_min * 60 if args.timeout_min else None
    failed, skipped = [], []
    total = sum(f.minutes for f in figures)
    print(
        f"run_all: {len(figures)} figures, ~{total:g} min for full runs on an idle 2-core machine",
        file=sys.stderr,
    )
    for i, figure in enumerate(figures, 1):
        missing = missing_needs(figure)
        if missing:
            print(
                f"[{i}/{len(figures)}] {figure.name}: skipped, {', '.join(missing)} not installed",
                file=sys.stderr,
            )
            skipped.append(figure.name)
            continue
        print(f"[{i}/{len(figures)}] {figure.name}: {figure.title}", file=sys.stderr, flush=True)
        if not run_figure(figure, args.quick, results, timeout_s):
            failed.append(figure.name)
    print(f"run_all: done; failed: {', '.join(failed) or 'none'}; skipped: {', '.join(skipped) or 'none'}")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
