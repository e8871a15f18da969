"""The planners' compiled loops: numba's ``njit``, cached on disk where numba finds a place.

numba keeps a compiled function beside its module (``__pycache__``) or, where that is read-only,
in the user's cache folder (~/.cache/numba); ``NUMBA_CACHE_DIR`` overrides both. With none of
them writable (a read-only install under a read-only home, as in some containers) numba refuses
to cache at import; the loops are then compiled in every process instead, and the tool says so
once.
"""

from __future__ import annotations

import sys
from collections.abc import Callable

from numba import njit

__all__ = ["compiled"]

_told = False


def compiled(fn: Callable) -> Callable:
    """fn compiled to machine code at its first call, and cached for later processes."""
    try:
        return njit(cache=True)(fn)
    except RuntimeError as error:
        if "no locator available" not in str(error):
            raise
        _tell_once()
        return njit(fn)


def _tell_once() -> None:
    global _told
    if not _told:
        _told = True
        print(
            "gcs-planner: no writable place for numba's cache (the install and the home folder are"
            " read-only): the planners compile their kernels in each run (~7 s); set NUMBA_CACHE_DIR"
            " to a writable folder to keep them",
            file=sys.stderr,
        )
