"""The planners' compiled kernels work, and say so once, where numba has no place for its cache."""

from __future__ import annotations

import os
import subprocess
import sys

# every planner module with kernels imported (numba looks for the cache's place there), one called
KERNELS = """
import gcs_planner.planning.deconflict4d.conflicts, gcs_planner.planning.priority_swarm
from gcs_planner.geometry.vec3 import dot
print(dot((1.0, 2.0, 3.0), (4.0, 5.0, 6.0)))
"""


def _run(extra_env: dict) -> subprocess.CompletedProcess:
    env = {**os.environ, **extra_env}
    env.pop("NUMBA_CACHE_DIR", None)
    return subprocess.run([sys.executable, "-c", KERNELS], capture_output=True, text=True, env=env)


def test_no_place_for_the_cache_compiles_in_process_and_says_so_once():
    # the only locator left is numba's zip-file one, which never applies: as with a read-only
    # install under a read-only home, numba finds no place for the cache
    done = _run({"NUMBA_CACHE_LOCATOR_CLASSES": "ZipCacheLocator"})
    assert done.returncode == 0, done.stderr
    assert done.stdout.split() == ["32.0"]
    assert done.stderr.count("no writable place for numba's cache") == 1
    assert "NUMBA_CACHE_DIR" in done.stderr


def test_a_cache_in_place_says_nothing():
    done = _run({})
    assert done.returncode == 0, done.stderr
    assert done.stdout.split() == ["32.0"]
    assert "numba" not in done.stderr


def test_a_compile_is_told_while_it_runs_and_a_compiled_kernel_is_not():
    from numba import njit

    from gcs_planner.core.compiled import on_compile

    @njit
    def twice(x):
        return 2 * x

    told = []
    with on_compile(lambda: told.append(1)):
        assert twice(2) == 4
        assert len(told) == 1
        assert twice(3) == 6  # compiled already: nothing to say
    assert twice(2.5) == 5.0  # a new signature compiles, but outside the block nobody listens
    assert len(told) == 1


def test_the_plan_bar_says_it_is_compiling(monkeypatch):
    """On a terminal the first plan after an install waits for numba: the bar says why."""
    import io

    from numba import njit
    from tqdm import tqdm

    from gcs_planner import planning
    from gcs_planner.commands import progress

    shown = io.StringIO()
    monkeypatch.setattr(progress, "progress_bar", lambda total, desc: tqdm(total=total, file=shown))

    @njit
    def kernel(x):
        return x + 1

    monkeypatch.setattr(planning, "plan_scenario", lambda scenario, seed, progress: kernel(1))
    assert progress.plan_with_progress(type("S", (), {"name": "s"})()) == 2
    assert progress.COMPILING in shown.getvalue()
