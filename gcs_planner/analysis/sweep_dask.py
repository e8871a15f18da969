"""The Dask side of a sweep's workers: each prepared as a pool worker is (sweep_worker.py).

Imported only when a sweep runs on Dask, so the tool needs ``distributed`` only then.
"""

from __future__ import annotations

from distributed.diagnostics.plugin import WorkerPlugin

from gcs_planner.analysis.sweep_worker import prepare_worker


class PrepareWorker(WorkerPlugin):
    """``prepare_worker(task)`` once on every worker of the cluster, those that join later too, so
    that no run's CPU time carries the imports (Dask's nanny already gives each worker one native
    thread; a worker without a nanny gets it here, for the modules not yet loaded)."""

    name = "gcs-planner-prepare-worker"

    def __init__(self, task: str | None) -> None:
        self.task = task

    def setup(self, worker) -> None:
        prepare_worker(self.task)
