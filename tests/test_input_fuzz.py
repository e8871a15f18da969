"""Fuzz every CLI reader with mutated inputs (tests/input_mutations.py, and the real mission files
and logs of ../shared/corpus), bounded to ~40 s.

Rules: exit 0 or 2, never an uncaught exception, one stderr line on exit 2, and no file left in
the output folders on exit 2. The flight itself is stubbed (input_mutations.stub_fly).
"""

from __future__ import annotations

import logging
import os
import shutil
import tempfile
from pathlib import Path

import input_mutations as im
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st


@pytest.fixture(autouse=True)
def _quiet_stub_flight(monkeypatch):
    monkeypatch.setattr("gcs_planner.commands.fly.fly", im.stub_fly)
    logging.disable(logging.CRITICAL)
    yield
    logging.disable(logging.NOTSET)


@pytest.mark.parametrize("case", sorted(im.CASES))
@settings(max_examples=60, deadline=None, suppress_health_check=list(HealthCheck), database=None)
@given(rng=st.randoms(use_true_random=False))
def test_mutated_inputs_exit_0_or_2_cleanly(case, rng):
    folder = Path(tempfile.mkdtemp(prefix="fuzz-"))
    try:
        argv = im.CASES[case](rng, folder)
        outcome = im.run_case(argv, folder)
        assert not im.problems(outcome), (argv, outcome.stderr, outcome.exception)
    finally:
        shutil.rmtree(folder, ignore_errors=True)


CORPUS = Path(os.environ.get("GCS_PLANNER_CORPUS", Path(__file__).resolve().parents[2] / "shared" / "corpus"))
MISSION_FILES = sorted(
    p for p in CORPUS.rglob("*") if p.suffix in (".plan", ".txt", ".waypoints", ".mission")
)
LOG_FILES = [CORPUS / "logs/pymavlink/test.BIN", CORPUS / "logs/pyulog/sample_log_small.ulg"]


@pytest.mark.skipif(not MISSION_FILES, reason=f"no corpus mission files at {CORPUS}")
@settings(max_examples=60, deadline=None, suppress_health_check=list(HealthCheck), database=None)
@given(rng=st.randoms(use_true_random=False))
def test_mutated_real_mission_files_convert_cleanly(rng):
    source = rng.choice(MISSION_FILES)
    _converts_cleanly(
        source, im.mutate_bytes(source.read_bytes(), rng), rng.choice(["o.plan", "o.waypoints"])
    )


@pytest.mark.skipif(not all(p.is_file() for p in LOG_FILES), reason=f"no corpus logs at {CORPUS}")
@settings(max_examples=8, deadline=None, suppress_health_check=list(HealthCheck), database=None)
@given(rng=st.randoms(use_true_random=False))
def test_mutated_real_logs_import_cleanly(rng):
    """A mutated DataFlash log once ended the import with an MCAP struct error (a damaged time)."""
    source = rng.choice(LOG_FILES)
    _converts_cleanly(source, im.mutate_bytes(source.read_bytes(), rng), "o.mcap")


def _converts_cleanly(source: Path, data: bytes, out_name: str) -> None:
    folder = Path(tempfile.mkdtemp(prefix="fuzz-"))
    try:
        (folder / "out").mkdir()
        given_file = folder / f"in{source.suffix}"
        given_file.write_bytes(data)
        out = str(folder / "out" / out_name)
        argv = (
            ["import-log", str(given_file), "-o", out]
            if out_name.endswith(".mcap")
            else ["convert", str(given_file), out]
        )
        outcome = im.run_case(argv, folder)
        assert not im.problems(outcome), (source.name, outcome.stderr, outcome.exception)
    finally:
        shutil.rmtree(folder, ignore_errors=True)
