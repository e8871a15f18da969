"""What a sweep's pool worker does once, before its first run: one native thread, imports done.

A sweep runs one planner per worker process, ``workers`` of them on as many cores. Two things
would otherwise make a run's measured CPU grow with the number of workers:
- Native thread pools: OpenBLAS (numpy's and scipy's BLAS), OpenMP and MKL each start one thread
  per core in every worker, so N workers hold N x cores threads that compete for N cores (and
  OpenBLAS threads spin while they wait for work). A worker is one run at a time on one core, so
  its pools get one thread: OMP/OPENBLAS/MKL_NUM_THREADS=1, as Dask's nanny sets them for its own
  workers. A variable the user has set is kept. It must happen before numpy is imported, which a
  pool worker forked from the sweep does only here (the sweep's own process never imports it).
- Imports: the first run of each worker imported numpy, scipy and its planner (planning/ loads a
  planner when a scenario names it) inside its timed window, so with N workers N runs carried that
  cost; every planner module is imported here instead, once per worker.
- Compiled kernels: the planners' numba kernels load from numba's on-disk cache on their first
  call (~0.2 s of LLVM start-up, ~10 ms a kernel; max 0.75-1.14 s against a median 0.5 s a run,
  docs/results/sweep_scaling.md); ``planning.warm.load_kernels`` loads them here instead.
"""

from __future__ import annotations

import importlib
import os
import pkgutil
from types import ModuleType

__all__ = ["THREAD_ENV", "prepare_worker"]

THREAD_ENV = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")
_PLANNERS = "gcs_planner.planning"


def prepare_worker(task: str | None) -> None:
    """Pin the native thread pools to one thread, then import every planner and ``task``'s module
    ("module:function", a task the sweep may run; None: the planners only).

    An import that fails is left for the run, which records its error in its row."""
    for name in THREAD_ENV:
        os.environ.setdefault(name, "1")
    planners = _imported(_PLANNERS)
    modules = [m.name for m in pkgutil.iter_modules(planners.__path__, f"{_PLANNERS}.")] if planners else []
    for module in (*modules, *([task.partition(":")[0]] if task else [])):
        _imported(module)
    try:
        from gcs_planner.planning.warm import load_kernels  # here: the thread variables must be set first

        load_kernels()
    except Exception:  # noqa: BLE001 - a run that needs what failed here reports it itself
        return


def _imported(name: str) -> ModuleType | None:
    """The module ``name``, imported; None when its import fails (the run will say why)."""
    try:
        return importlib.import_module(name)
    except Exception:  # noqa: BLE001 - any import error is the run's to report
        return None
