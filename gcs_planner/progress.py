"""Progress bars for long work: tqdm on a terminal, quiet under CI or when output is piped."""

from __future__ import annotations

import os
import sys

from tqdm import tqdm


def progress_bar(total: float, desc: str, unit: str = "it") -> tqdm:
    """A tqdm bar that stays silent when stderr is not a terminal or CI is set."""
    quiet = bool(os.environ.get("CI")) or not sys.stderr.isatty()
    return tqdm(total=total, desc=desc, unit=unit, disable=quiet, leave=False)


def plan_with_progress(scenario, seed: int | None = None):
    """plan_scenario with a progress bar fed by the planner's ``progress(fraction, message)``."""
    from gcs_planner.planning import plan_scenario

    with progress_bar(1.0, f"planning {scenario.name}") as bar:

        def progress(fraction: float, message: str) -> None:
            bar.n = round(fraction, 3)
            bar.set_postfix_str(message)
            bar.refresh()

        return plan_scenario(scenario, seed=seed, progress=progress)
