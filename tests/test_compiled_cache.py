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
