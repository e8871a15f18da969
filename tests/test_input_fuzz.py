"""Fuzz every CLI reader with mutated inputs (tests/input_mutations.py), bounded to ~30 s.

Rules: exit 0 or 2, never an uncaught exception, one stderr line on exit 2, and no file left in
the output folders on exit 2. The flight itself is stubbed (input_mutations.stub_fly).
"""

from __future__ import annotations

import logging
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
