"""The planners' compiled loops: numba's ``njit``, cached on disk where numba finds a place.

numba keeps a compiled function beside its module (``__pycache__``) or, where that is read-only,
in the user's cache folder (~/.cache/numba); ``NUMBA_CACHE_DIR`` overrides both. With none of
them writable (a read-only install under a read-only home, as in some containers) numba refuses
to cache at import; the loops are then compiled in every process instead, and the tool says so
once.
"""

from __future__ import annotations

import contextlib
import sys
from collections.abc import Callable, Iterator

from numba import njit
from numba.core import event

__all__ = ["compiled", "on_compile"]

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


@contextlib.contextmanager
def on_compile(say: Callable[[], None]) -> Iterator[None]:
    """``say()`` each time numba starts compiling a kernel inside the block: only where no cached
    copy fits (the first run after an install or a change), so a progress bar can say why it waits."""

    class Listener(event.Listener):
        def on_start(self, _event: event.Event) -> None:
            say()

        def on_end(self, _event: event.Event) -> None:
            pass

    with event.install_listener("numba:compile", Listener()):
        yield


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
