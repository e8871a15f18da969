"""Parameter sweeps: a study's grid x seeds planned on local processes or a Dask cluster, resumable.

A study (TOML) names a scenario, the grid of ``[planner]`` values, the seeds and the metrics to
keep (keys of ``Plan.metrics``, dotted for nested ones, plus ``feasible_fraction`` and ``cpu_s``)::

    name = "priority swarm budget"
    scenario = "../missions/swarm_small.toml"      # relative to the study file
    seeds = [0, 1, 2]
    metrics = ["cost_total", "feasible_fraction", "evaluations"]
    [grid]
    particles = [6, 10]
    iterations = [4, 8]

``task = "package.module:function"`` runs another function per run instead of the planner (e.g.
``gcs_planner.planning.coalition.montecarlo:run``): ``function(scenario_path, params, seed)``
returns the metrics. Only the project's own tasks (STUDY_TASKS) run: a study file is data, and
importing and calling whatever it names runs anyone's code (``logging.config:fileConfig`` on a
crafted file ran a shell command). Your own task needs ``sweep --allow-user-task`` or
ALLOW_USER_TASK_ENV=1. A grid key ``scenario`` (a list of scenario files, relative to the study file)
sweeps over scenarios as well, e.g. the fleet sizes of a table; the top-level ``scenario`` may then
be left out.

Every run (one grid point, one seed) is planned with that seed, so its result does not depend on
the worker or the order. Rows are appended to one CSV as runs finish; a killed sweep started again
skips every run already in the file. A run that fails is recorded with its error, not fatal.
"""

from __future__ import annotations

import csv
import hashlib
import importlib
import io
import itertools
import json
import math
import os
import sys
import threading
import time
from collections.abc import Callable, Iterator
from concurrent.futures import ProcessPoolExecutor, as_completed
from pathlib import Path
from typing import Annotated, Any

from msgspec import Meta

from gcs_planner.analysis.sweep_worker import prepare_worker
from gcs_planner.core.config import Config, parse
from gcs_planner.core.errors import UserError
from gcs_planner.core.validation import InputError, load_toml, read_text

__all__ = ["ALLOW_USER_TASK_ENV", "STUDY_TASKS", "Study", "load_study", "marginals", "run_study", "summarise"]

FIXED_COLUMNS = ["run_id", "seed", "error", "cpu_s"]
STUDY_TASKS = frozenset({
    "gcs_planner.analysis.sweep:plan",
    "gcs_planner.planning.acmpso_study:table3_run",
    "gcs_planner.planning.baselines:compare_run",
    "gcs_planner.planning.coalition.montecarlo:run",
})  # fmt: skip
ALLOW_USER_TASK_ENV = "GCS_PLANNER_ALLOW_USER_TASK"


class Study(Config):
    """A study file's keys."""

    name: str
    seeds: list[Annotated[int, Meta(ge=0, le=2**63 - 1)]]
    metrics: list[str]
    grid: dict[str, list[int | float | str | bool]] = {}
    scenario: str = ""
    task: str = "gcs_planner.analysis.sweep:plan"


def _check_csv_text(path: Path, study: Study) -> None:
    """Every name and text value that goes into the results CSV is free of control characters
    (a NUL in a metric name made the sweep refuse its own CSV as binary)."""
    texts = [("name", study.name), *(("metrics", m) for m in study.metrics)]
    texts += [("grid", k) for k in study.grid]
    texts += [(f"grid.{k}", v) for k, values in study.grid.items() for v in values if isinstance(v, str)]
    for field, text in texts:
        if any(ord(c) < 32 or ord(c) == 127 for c in text):
            raise UserError(f"{path}: {field} {text!r} holds control characters (it goes into the CSV)")


def load_study(path: str | Path, allow_user_task: bool = False) -> tuple[Study, Path]:
    """The study and the folder its scenario paths are relative to (the study file's), every
    scenario checked to be a file and the task one of STUDY_TASKS unless ``allow_user_task``."""
    path = Path(path)
    try:
        study = parse(Study, load_toml(read_text(path, "study"), str(path)), "study")
    except InputError as exc:
        raise UserError(f"{path}: {exc}") from None
    if not study.seeds:
        raise UserError(f"{path}: seeds must name at least one seed")
    _check_csv_text(path, study)
    base = path.parent.resolve()
    named = study.grid.get("scenario") or ([study.scenario] if study.scenario else [])
    if not named:
        raise UserError(f"{path}: scenario must name a scenario file (or grid.scenario a list of them)")
    for name in named:
        if not isinstance(name, str) or not (base / name).is_file():
            raise UserError(f"{path}: scenario {name!r} is not a file ({base / str(name)})")
    try:
        task_named(study.task, allow_user_task)
    except UserError as exc:
        raise UserError(f"{path}: {exc}") from None
    return study, base


def runs(study: Study) -> Iterator[tuple[str, dict[str, Any], int]]:
    """(run id, grid values, seed) of every run, grid points outermost."""
    keys = sorted(study.grid)
    for values in itertools.product(*(study.grid[k] for k in keys)):
        params = dict(zip(keys, values, strict=True))
        for seed in study.seeds:
            ident = hashlib.sha1(json.dumps([params, seed], sort_keys=True).encode()).hexdigest()[:12]
            yield ident, params, seed


def plan(scenario: Path, params: dict[str, Any], seed: int) -> dict[str, Any]:
    """The default task: plan the scenario with ``params`` in its [planner] table; Plan.metrics
    plus the share of feasible vehicles."""
    from gcs_planner.planning import load_scenario, plan_scenario

    loaded = load_scenario(scenario)
    loaded.planner.update(params)
    result = plan_scenario(loaded, seed=seed)
    return {
        **result.metrics,
        "feasible_fraction": sum(v.feasible for v in result.vehicles) / len(result.vehicles),
    }


def user_tasks_allowed(flag: bool = False) -> bool:
    """The opt-in to run a study's own task: the flag, or ALLOW_USER_TASK_ENV=1."""
    return flag or os.environ.get(ALLOW_USER_TASK_ENV) == "1"


def task_named(
    name: str, allow_user_task: bool = False
) -> Callable[[Path, dict[str, Any], int], dict[str, Any]]:
    """The function a study's ``task = "package.module:function"`` names (UserError if none); a
    name outside STUDY_TASKS is refused before anything is imported unless user tasks are allowed."""
    if name not in STUDY_TASKS and not user_tasks_allowed(allow_user_task):
        shown = name if len(name) <= 80 else name[:77] + "..."
        raise UserError(
            f"task {shown!r} is not one of gcs-planner's study tasks ({', '.join(sorted(STUDY_TASKS))});"
            f" to run your own code pass --allow-user-task (or {ALLOW_USER_TASK_ENV}=1)"
        )
    module, _, attr = name.partition(":")
    try:
        fn = getattr(importlib.import_module(module), attr)
    except (ImportError, AttributeError, ValueError):
        raise UserError(f"study task {name!r} is not an importable 'package.module:function'") from None
    if not callable(fn):
        raise UserError(f"study task {name!r} is not a function")
    return fn


def run_task(
    task: str,
    base: str,
    params: dict[str, Any],
    seed: int,
    metrics: list[str],
    default: str,
    allow_user_task: bool = False,
) -> dict[str, Any]:
    """One run (in a worker): the study's task on its scenario (``params["scenario"]`` or
    ``default``, relative to ``base``) with the other ``params``; the named metrics and CPU time."""
    cpu = time.process_time()
    params = dict(params)
    scenario = Path(base) / params.pop("scenario", default)
    values = task_named(task, allow_user_task)(scenario, params, seed)
    values["cpu_s"] = time.process_time() - cpu
    return {m: metric(values, m) for m in [*metrics, "cpu_s"]}


def metric(values: dict[str, Any], name: str) -> Any:
    """``values[name]``, where a dotted name walks nested tables ("uav1.fitness"); NaN if absent."""
    for key in name.split("."):
        if not isinstance(values, dict) or key not in values:
            return math.nan
        values = values[key]
    return values


def _done(out: Path, columns: list[str]) -> tuple[set[str], int | None]:
    """(the runs complete in ``out``, the size to cut it to first or None). UserError if it is not
    UTF-8 CSV text or its columns are not ``columns`` (another study's file: its rows would be
    misread, and new rows written under the wrong heads). A last row without its newline (a sweep
    killed mid-write) is incomplete: it is cut off and run again, so the next row starts on a line
    of its own. A row with the wrong number of fields does not count as done."""
    if not out.exists() or out.stat().st_size == 0:
        return set(), None
    data = _csv_text(out)
    cut = None
    if not data.endswith("\n"):
        keep = data.rfind("\n") + 1
        cut, data = len(data[:keep].encode()), data[:keep]
    try:
        reader = csv.DictReader(io.StringIO(data, newline=""))
        if data and reader.fieldnames != columns:
            raise UserError(
                f"{out}: its columns are not this study's (grid and metrics"
                f" {_short(columns[len(FIXED_COLUMNS) :])}); give another output file"
            )
        done = {row["run_id"] for row in reader if None not in row and None not in row.values()}
    except csv.Error as exc:
        raise UserError(f"{out}: not a results CSV ({exc})") from None
    if not data:  # only a cut header: write it again
        cut = 0
    return done, cut


def _csv_text(out: Path) -> str:
    """``out`` as text: UserError (one line) if it cannot be read or is not UTF-8 (UTF-16, binary)."""
    try:
        raw = out.read_bytes()
    except OSError as exc:
        raise UserError(f"{out}: cannot read: {exc.strerror or exc}") from None
    if b"\0" in raw:
        raise UserError(f"{out}: not a UTF-8 results CSV (it holds NUL bytes: UTF-16 or binary?)")
    try:
        return raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise UserError(f"{out}: not a UTF-8 results CSV (byte {exc.start})") from None


def _short(value: Any) -> str:
    text = str(value)
    return text if len(text) <= 120 else text[:117] + "..."


def run_study(
    study: Study,
    base: Path,
    out: Path,
    workers: int = 2,
    scheduler: str | None = None,
    progress: Callable[[int, int], None] | None = None,
    max_runs: int | None = None,
    allow_user_task: bool = False,
) -> int:
    """Run every run not yet in ``out`` (local processes, or the Dask scheduler at ``scheduler``:
    an address, or "local" for a LocalCluster of ``workers``); the number of runs done now."""
    columns = FIXED_COLUMNS + sorted(study.grid) + [m for m in study.metrics if m != "cpu_s"]
    done, cut = _done(out, columns)
    todo = [r for r in runs(study) if r[0] not in done][:max_runs]
    try:
        if cut is not None:
            with out.open("r+b") as f:
                f.truncate(cut)
        new_file = not out.exists() or out.stat().st_size == 0
        f = out.open("a", newline="")  # closed by the with below
    except OSError as exc:
        raise _cannot_write(out, exc) from None
    allowed = study.task in STUDY_TASKS or user_tasks_allowed(allow_user_task)  # imported only then
    with f, _executor(scheduler, workers, study.task if allowed else None) as submit:
        writer = csv.DictWriter(f, columns, extrasaction="ignore")
        if new_file:
            _append(f, writer.writeheader, out)
        args = (study.metrics, study.scenario, user_tasks_allowed(allow_user_task))
        futures = {submit(run_task, study.task, str(base), params, seed, *args): (ident, params, seed)
                   for ident, params, seed in todo}  # fmt: skip
        for n, (future, (ident, params, seed)) in enumerate(_completed(futures), 1):
            row = {"run_id": ident, "seed": seed, "error": "", **params}
            try:
                row.update(future.result())
            except Exception as exc:  # noqa: BLE001 - a failed run is recorded, the sweep goes on
                row["error"] = f"{type(exc).__name__}: {exc}".replace("\n", " ")
            _append(f, lambda row=row: writer.writerow(row), out)
            if progress:
                progress(n, len(todo))
    return len(todo)


def _append(f, write: Callable[[], object], out: Path) -> None:
    """Write one CSV line and flush it; a full disk is one line (a rerun redoes a cut last row)."""
    try:
        write()
        f.flush()
    except OSError as exc:
        raise _cannot_write(out, exc) from None


def _cannot_write(out: Path, exc: OSError) -> UserError:
    """The one-line error for a results CSV that cannot be written: the path and the OS reason."""
    reason = exc.strerror or exc
    return UserError(f"cannot write {str(out)!r}: {reason}; a rerun resumes from the rows written")


class _executor:
    """``with _executor(scheduler, workers, task) as submit``: a process pool or a Dask client;
    ``task``: the study task every worker, pool or Dask, imports before its first run (None: none)."""

    def __init__(self, scheduler: str | None, workers: int, task: str | None = None) -> None:
        self.scheduler, self.workers, self.task = scheduler, workers, task

    def __enter__(self):
        if self.scheduler is None:
            self.pool = ProcessPoolExecutor(
                self.workers, initializer=_start_worker, initargs=(os.getpid(), self.task)
            )
            return self.pool.submit
        try:
            import dask
            from distributed import Client, LocalCluster

            from gcs_planner.analysis.sweep_dask import PrepareWorker
        except ImportError:
            raise UserError("--scheduler needs dask.distributed: pip install 'gcs-planner[dask]'") from None
        # the workers' stack profiler samples every 10 ms and takes the GIL from the planners; the
        # nanny's MALLOC_TRIM_THRESHOLD_ also fixes glibc's mmap threshold, so every numpy array
        # over 128 KiB is mapped and unmapped afresh (docs/sweeps.md has both measured)
        environ = dict(dask.config.get("distributed.nanny.pre-spawn-environ"))
        environ.pop("MALLOC_TRIM_THRESHOLD_", None)
        dask.config.set(
            {"distributed.worker.profile.enabled": False, "distributed.nanny.pre-spawn-environ": environ}
        )
        self.cluster = (
            LocalCluster(n_workers=self.workers, threads_per_worker=1, dashboard_address=None)
            if self.scheduler == "local" else None
        )  # fmt: skip
        self.pool = Client(self.cluster or self.scheduler)
        self.pool.register_plugin(PrepareWorker(self.task))
        return lambda fn, *args: self.pool.submit(fn, *args, pure=False)

    def __exit__(self, *exc) -> None:
        if self.scheduler is None:
            self.pool.shutdown(cancel_futures=True)
            return
        self.pool.close()
        if self.cluster is not None:
            self.cluster.close()


def _start_worker(parent_pid: int, task: str | None) -> None:
    """Pool worker initializer: tied to the sweep's life, one native thread, imports done
    (sweep_worker.py) so that no run's CPU time carries them."""
    _die_with(parent_pid)
    prepare_worker(task)


def _die_with(parent_pid: int) -> None:
    """End this pool worker when the sweep that started it ends, even by SIGKILL (its atexit never
    runs, and an orphaned worker would plan on for ever). Linux: PR_SET_PDEATHSIG; everywhere: a
    thread that checks the sweep's pid every second."""
    if sys.platform.startswith("linux"):
        try:
            import ctypes
            import signal

            ctypes.CDLL(None, use_errno=True).prctl(1, signal.SIGKILL, 0, 0, 0)  # 1 = PR_SET_PDEATHSIG
        except (OSError, AttributeError):
            pass

    def watch() -> None:
        while True:
            try:
                os.kill(parent_pid, 0)
            except ProcessLookupError:
                os._exit(1)
            except PermissionError:
                pass
            time.sleep(1.0)

    if not _alive(parent_pid):  # died before the prctl above took hold
        os._exit(1)
    threading.Thread(target=watch, name="sweep-parent-watch", daemon=True).start()


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def _completed(futures: dict) -> Iterator[tuple[Any, Any]]:
    """(future, its key) as each finishes, for process-pool and Dask futures alike."""
    if futures and type(next(iter(futures))).__module__.startswith("distributed"):
        from distributed import as_completed as dask_completed

        for future in dask_completed(list(futures)):
            yield future, futures[future]
        return
    for future in as_completed(futures):
        yield future, futures[future]


def _read(out: Path) -> list[dict[str, str]]:
    """The complete rows of a results CSV (one-line UserError if it is not one)."""
    try:
        reader = csv.DictReader(io.StringIO(_csv_text(out), newline=""))
        return [row for row in reader if None not in row and None not in row.values()]
    except csv.Error as exc:
        raise UserError(f"{out}: not a results CSV ({exc})") from None


def _mean_std(values: list[float]) -> tuple[float, float]:
    """Mean and sample standard deviation (NaN and 0 for no values, 0 for one)."""
    mean = sum(values) / len(values) if values else math.nan
    var = sum((v - mean) ** 2 for v in values) / (len(values) - 1) if len(values) > 1 else 0.0
    return mean, math.sqrt(var)


_FLAGS = {"True": 1.0, "False": 0.0}  # a met / unmet condition counts as 1 / 0


def _number(text: str) -> float:
    """A cell as a number; NaN for one that is not (a metric kept whole, e.g. a JSON history)."""
    if text in _FLAGS:
        return _FLAGS[text]
    try:
        return float(text)
    except ValueError:
        return math.nan


def _numbers(rows: list[dict[str, str]], name: str) -> list[float]:
    """The metric's numeric values over the runs that ran and defined it (NaN: undefined for that
    run, or not a number)."""
    cells = (_number(r[name]) for r in rows if not r["error"] and r.get(name) not in (None, ""))
    return [v for v in cells if not math.isnan(v)]


def summarise(study: Study, out: Path) -> list[dict[str, Any]]:
    """Per grid point: runs, failures, and each metric's mean and standard deviation over seeds."""
    rows = _read(out)
    keys = sorted(study.grid)
    groups: dict[tuple, list[dict]] = {}
    for row in rows:
        groups.setdefault(tuple(row[k] for k in keys), []).append(row)
    summary = []
    rank = {k: {str(v): i for i, v in enumerate(study.grid[k])} for k in keys}  # the study's order

    def grid_order(item: tuple[tuple, list]) -> tuple:
        return tuple(rank[k].get(v, len(rank[k])) for k, v in zip(keys, item[0], strict=True))

    for point, members in sorted(groups.items(), key=grid_order):
        ok = [r for r in members if not r["error"]]
        entry: dict[str, Any] = {**dict(zip(keys, point, strict=True)), "runs": len(members),
                                 "failed": len(members) - len(ok)}  # fmt: skip
        for m in [*study.metrics, "cpu_s"]:
            entry[f"{m} mean"], entry[f"{m} std"] = _mean_std(_numbers(ok, m))
        summary.append(entry)
    return summary


def marginals(study: Study, out: Path) -> dict[tuple[str, str], list[tuple[str, float, float, int]]]:
    """Per (metric, grid key): for each of the key's values, the metric's mean, standard deviation
    and run count over every run with that value (the other keys and the seeds pooled)."""
    rows = _read(out)
    curves = {}
    for m in [*study.metrics, "cpu_s"]:
        for key in sorted(study.grid):
            points = []
            for value in study.grid[key]:
                values = _numbers([r for r in rows if r[key] == str(value)], m)
                points.append((str(value), *_mean_std(values), len(values)))
            curves[m, key] = points
    return curves
