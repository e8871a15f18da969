"""Sweeps run only the project's study tasks, resume a cut CSV cleanly, refuse a CSV that is not
UTF-8 text, and take their pool workers with them when killed."""

from __future__ import annotations

import csv
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from cli_checks import refused as _fails

from gcs_planner.analysis.sweep import ALLOW_USER_TASK_ENV, load_study, run_study
from gcs_planner.cli import main

MISSIONS = Path(__file__).resolve().parents[1] / "missions"


def _study(tmp_path: Path, extra: str = "", grid: str = "waypoint_spacing_m = [50.0, 100.0, 200.0]") -> Path:
    path = tmp_path / "study.toml"
    path.write_text(
        f'name = "t"\nscenario = "{MISSIONS / "straight_4uav"}.toml"\nseeds = [0, 1]\n'
        f'metrics = ["feasible_fraction"]\n{extra}[grid]\n{grid}\n'
    )
    return path


@pytest.fixture
def evil(tmp_path, monkeypatch):
    """A module whose import leaves a marker file: proof that a study ran someone's code."""
    marker = tmp_path / "ran"
    (tmp_path / "evil_task_mod.py").write_text(
        f"from pathlib import Path\nPath({str(marker)!r}).write_text('imported')\n"
        "def run(scenario, params, seed):\n    return {'feasible_fraction': 1.0}\n"
    )
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.delenv(ALLOW_USER_TASK_ENV, raising=False)
    sys.modules.pop("evil_task_mod", None)
    yield marker
    sys.modules.pop("evil_task_mod", None)


@pytest.mark.parametrize("task", ["evil_task_mod:run", "logging.config:fileConfig", "os:system", "x" * 5000])
def test_a_study_cannot_name_code_outside_the_registry(tmp_path, capsys, evil, task):
    study = _study(tmp_path, f'task = "{task}"\n')
    out = tmp_path / "r.csv"
    _fails(["sweep", str(study), "-o", str(out)], capsys, "task", "--allow-user-task")
    assert not evil.exists() and not out.exists()
    assert len(capsys.readouterr().err) < 1000


def test_user_task_runs_with_the_flag_or_the_env(tmp_path, capsys, evil, monkeypatch):
    study = _study(tmp_path, 'task = "evil_task_mod:run"\n', grid="waypoint_spacing_m = [50.0]")
    out = tmp_path / "r.csv"
    assert main(["sweep", str(study), "-o", str(out), "--workers", "1", "--allow-user-task"]) == 0
    assert evil.exists()
    monkeypatch.setenv(ALLOW_USER_TASK_ENV, "1")
    load_study(study)  # the environment opt-in


def _rows(out: Path) -> list[dict]:
    with out.open(newline="") as f:
        return list(csv.DictReader(f))


def test_a_cut_last_row_is_run_again_and_the_next_row_starts_a_line(tmp_path):
    study, base = load_study(_study(tmp_path))
    out = tmp_path / "r.csv"
    assert run_study(study, base, out, workers=1, max_runs=3) == 3
    text = out.read_text()
    cut = text[: text.rstrip("\n").rfind("\n") + 1] + text.rstrip("\n").rsplit("\n", 1)[1][:14]
    out.write_text(cut)  # the third row lost its tail and newline (a killed sweep)
    assert run_study(study, base, out, workers=1) == 4  # the cut row is run again, with the three left
    rows = _rows(out)
    assert len(rows) == 6 and len({r["run_id"] for r in rows}) == 6
    assert all(None not in r and None not in r.values() and not r["error"] for r in rows)
    assert out.read_text().endswith("\n")


@pytest.mark.parametrize("encoding", ["utf-16", "latin-1-binary"])
def test_a_csv_that_is_not_utf8_is_one_line_and_untouched(tmp_path, capsys, encoding):
    study = _study(tmp_path)
    out = tmp_path / "r.csv"
    if encoding == "utf-16":
        out.write_bytes("run_id,seed,error,cpu_s\n".encode("utf-16"))
    else:
        out.write_bytes(b"run_id,seed\n\xff\xfe\x00garbage\n")
    before = out.read_bytes()
    _fails(["sweep", str(study), "-o", str(out)], capsys, str(out), "UTF-8")
    assert out.read_bytes() == before


WORKER = """
import os, sys, time
from gcs_planner.analysis.sweep import _executor
with _executor(None, 1) as submit:
    future = submit(os.getpid)
    print(future.result(), flush=True)
    submit(time.sleep, 3600)
    time.sleep(3600)
"""


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="/proc")
def test_pool_workers_die_with_a_killed_sweep():
    proc = subprocess.Popen([sys.executable, "-c", WORKER], stdout=subprocess.PIPE, text=True)
    try:
        worker = int(proc.stdout.readline())
        assert Path(f"/proc/{worker}").exists()
    finally:
        proc.send_signal(signal.SIGKILL)
        proc.wait()
    deadline = time.monotonic() + 30  # generous: the worker goes at once on Linux, else within ~1 s
    while time.monotonic() < deadline and _running(worker):
        time.sleep(0.1)
    alive = _running(worker)
    if alive:
        os.kill(worker, signal.SIGKILL)
    assert not alive, "a pool worker outlived its killed sweep"


def _running(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except OSError:
        return False
    return state != "Z"


def test_a_control_character_in_a_metric_name_is_refused_before_any_csv(tmp_path, capsys):
    """A NUL in a metric name went into the results CSV, which the sweep then refused as binary,
    leaving it behind (found by the fuzz harness)."""
    study = tmp_path / "study.toml"
    study.write_text(_study(tmp_path).read_text().replace('"feasible_fraction"', '"feasible\\u0000fraction"'))
    out = tmp_path / "r.csv"
    _fails(["sweep", str(study), "-o", str(out)], capsys, "metrics", "control characters")
    assert not out.exists()
