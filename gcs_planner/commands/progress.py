"""Progress bars for long work: tqdm on a terminal, quiet under CI or when output is piped."""

from __future__ import annotations

import contextlib
import os
import sys
from collections.abc import Callable, Iterator

from tqdm import tqdm

# what the bar says while numba compiles a planner's kernel (docs/planners.md, "Compiled kernels")
COMPILING = "compiling the planner's kernels for this machine (once after an install)"


def progress_bar(total: float, desc: str, unit: str = "it") -> tqdm:
    """A tqdm bar that stays silent when stderr is not a terminal or CI is set."""
    quiet = bool(os.environ.get("CI")) or not sys.stderr.isatty()
    return tqdm(total=total, desc=desc, unit=unit, disable=quiet, leave=False)


@contextlib.contextmanager
def counting_bar(desc: str, unit: str = "it") -> Iterator[Callable[[int, int], None]]:
    """A ``progress(done, total)`` callback (sweep.run_study's) drawing a bar opened on its first call."""
    bar: tqdm | None = None

    def progress(done: int, total: int) -> None:
        nonlocal bar
        bar = bar or progress_bar(total, desc, unit)
        bar.n = done
        bar.refresh()

    try:
        yield progress
    finally:
        if bar is not None:
            bar.close()


def say_ignored_tables(scenario) -> None:
    """A note naming the world tables the scenario's planner does not plan with: its plan does not
    avoid them (said once the input is checked, so that bad input still gets its one line)."""
    from gcs_planner.planning import ignored_tables

    if ignored := ignored_tables(scenario):
        tables = ", ".join(f"[{t}]" for t in ignored)
        print(f"note: planner {scenario.planner_name} does not plan with {tables}", file=sys.stderr)


def plan_with_progress(scenario, seed: int | None = None):
    """plan_scenario with a progress bar fed by the planner's ``progress(fraction, message)``."""
    from gcs_planner.core.compiled import on_compile  # numba: only where a plan is made
    from gcs_planner.planning import plan_scenario

    with progress_bar(1.0, f"planning {scenario.name}") as bar, on_compile(lambda: note(COMPILING)):

        def progress(fraction: float, message: str) -> None:
            bar.n = round(fraction, 3)
            note(message)

        def note(message: str) -> None:
            bar.set_postfix_str(message)
            bar.refresh()

        return plan_scenario(scenario, seed=seed, progress=progress)
