"""A sweep's worker (a pool process or a Dask worker) runs with one native (BLAS / OpenMP / MKL)
thread unless the user chose a number, and has numpy and the planners imported before its first
run, and the compiled kernels loaded, so no run's CPU time carries them or competes with N x cores
BLAS threads."""

from __future__ import annotations

import csv
import sys
from pathlib import Path

import pytest

from gcs_planner.analysis.sweep import ALLOW_USER_TASK_ENV, load_study, run_study

MISSIONS = Path(__file__).resolve().parents[1] / "missions"
PROBE = """import os, sys
def run(scenario, params, seed):
    return {
        "loaded": float("numpy" in sys.modules and "gcs_planner.planning.priority_swarm" in sys.modules),
        "kernels": float(
            bool(sys.modules["gcs_planner.planning.traffic"]._violations.signatures)
            and bool(sys.modules["gcs_planner.planning.rrt_star"]._grow_tree.signatures)
            and bool(sys.modules["gcs_planner.planning.deconflict4d.conflicts"]._pair_kernel.signatures)
        ),
        **{name.lower(): float(os.environ.get(name, "-1"))
           for name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")},
    }
"""


@pytest.fixture
def probe(tmp_path, monkeypatch):
    """A study whose task reports what its worker saw when the run started."""
    (tmp_path / "sweep_probe_mod.py").write_text(PROBE)
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.delenv(ALLOW_USER_TASK_ENV, raising=False)
    for name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
        monkeypatch.delenv(name, raising=False)
    path = tmp_path / "study.toml"
    path.write_text(
        f'name = "t"\nscenario = "{MISSIONS / "straight_4uav"}.toml"\ntask = "sweep_probe_mod:run"\n'
        'seeds = [0, 1]\nmetrics = ["loaded", "kernels", "omp_num_threads", "openblas_num_threads",'
        ' "mkl_num_threads"]\n'
        "[grid]\nwaypoint_spacing_m = [50.0]\n"
    )
    yield path
    sys.modules.pop("sweep_probe_mod", None)


def _sweep(tmp_path: Path, study_path: Path, workers: int, scheduler: str | None = None) -> list[dict]:
    study, base = load_study(study_path, allow_user_task=True)
    out = tmp_path / f"r{workers}{scheduler or ''}.csv"
    assert run_study(study, base, out, workers, scheduler, allow_user_task=True) == 2
    with out.open(newline="") as f:
        return list(csv.DictReader(f))


@pytest.mark.parametrize(("workers", "scheduler"), [(1, None), (2, None), (2, "local")])
def test_every_run_finds_one_native_thread_and_the_imports_done(tmp_path, probe, workers, scheduler):
    if scheduler:
        pytest.importorskip("distributed")
    rows = _sweep(tmp_path, probe, workers, scheduler)
    assert all(not r["error"] for r in rows)
    for r in rows:
        assert float(r["loaded"]) == 1.0  # the first run of each worker too
        assert float(r["kernels"]) == 1.0  # the compiled kernels loaded (numba's cache) before it
        threads = ("omp_num_threads", "openblas_num_threads", "mkl_num_threads")
        assert [float(r[k]) for k in threads] == [1.0, 1.0, 1.0]


def test_a_thread_count_the_user_set_is_kept(tmp_path, probe, monkeypatch):
    monkeypatch.setenv("OPENBLAS_NUM_THREADS", "3")
    rows = _sweep(tmp_path, probe, 1)
    assert [float(r["openblas_num_threads"]) for r in rows] == [3.0, 3.0]
    assert [float(r["omp_num_threads"]) for r in rows] == [1.0, 1.0]
