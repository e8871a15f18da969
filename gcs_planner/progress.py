"""Progress bars for long work: tqdm on a terminal, quiet under CI or when output is piped."""

from __future__ import annotations

import os
import sys

from tqdm import tqdm


def progress_bar(total: float, desc: str, unit: str = "it") -> tqdm:
    """A tqdm bar that stays silent when stderr is not a terminal or CI is set."""
    quiet = bool(os.environ.get("CI")) or not sys.stderr.isatty()
    return tqdm(total=total, desc=desc, unit=unit, disable=quiet, leave=False)
