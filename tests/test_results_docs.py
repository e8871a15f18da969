"""The figures reproduce: every benchmark has a registered command, every results file says how and
when it was made, `benchmarks/run_all.py` writes such a file, and the README stays one page."""

from __future__ import annotations

import re
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
BENCHMARKS = ROOT / "benchmarks"
RESULTS = ROOT / "docs" / "results"
sys.path.insert(0, str(BENCHMARKS))

import figures  # noqa: E402
import run_all  # noqa: E402
from results_md import NOTES_MARK  # noqa: E402

RUNNER = {"run_all.py", "figures.py", "results_md.py"}
DATE = re.compile(r"\b20\d\d-\d\d-\d\d\b")


def test_every_benchmark_script_is_a_figures_command_or_a_generator():
    commands = " ".join(step for f in figures.FIGURES for step in (*f.steps, *f.quick))
    for script in BENCHMARKS.glob("*.py"):
        if script.name in RUNNER or script.name in figures.GENERATORS:
            continue
        assert f"benchmarks/{script.name}" in commands, f"{script.name} has no entry in benchmarks/figures.py"
    for f in figures.FIGURES:
        for step in (*f.steps, *f.quick):
            if step.startswith("python benchmarks/"):
                assert (ROOT / step.split()[1]).is_file(), step


def test_every_results_file_belongs_to_a_figure_and_says_command_date_machine_and_load():
    names = {f.name for f in figures.FIGURES}
    files = sorted(RESULTS.glob("*.md"))
    assert files
    for path in files:
        text = path.read_text()
        assert path.stem in names, f"{path.name}: no figure of that name in benchmarks/figures.py"
        assert DATE.search(text), f"{path.name}: no date"
        assert re.search(r"`(python|gcs-planner|\.venv/bin/python)[^`]*`", text), f"{path.name}: no command"
        assert "machine" in text.lower() and "load" in text.lower(), f"{path.name}: no machine or load"


def _figure(name: str, *steps: str) -> figures.Figure:
    return figures.Figure(name, "a test figure", steps)


def test_run_all_writes_the_output_with_its_facts_and_keeps_the_notes(tmp_path):
    table = "print('| a | b |'); print('|---|---|'); print('| 1 | 2 |')"
    figure = _figure("fake", f'python -c "{table}"', "python -c \"print('second')\"")
    (tmp_path / "fake.md").write_text(f"# old\n\nold figure\n\n{NOTES_MARK}\n\nWhy the figure matters.\n")
    assert run_all.run_figure(figure, False, tmp_path, 60, scratch_root=tmp_path / "scratch")
    text = (tmp_path / "fake.md").read_text()
    assert "old figure" not in text and text.endswith("Why the figure matters.\n")
    assert "| 1 | 2 |" in text and "second" in text
    assert DATE.search(text) and "machine:" in text and "cores" in text
    assert text.count("load average") == 2  # uptime before and after
    assert "`python -c" in text and "--only fake" in text


def test_run_all_records_a_failed_command_with_its_stderr_and_says_so(tmp_path):
    figure = _figure("broken", "python -c \"import sys; sys.exit('no such scenario')\"")
    assert not run_all.run_figure(figure, False, tmp_path, 60, scratch_root=tmp_path / "scratch")
    text = (tmp_path / "broken.md").read_text()
    assert "| 1 |" in text and "no such scenario" in text and "Exit status 1" in text


@pytest.mark.parametrize(
    ("argv", "error"),
    [
        (["--only", "nope"], "run_all: error: --only: unknown figure 'nope'"),
        (["--only", "fly_swarm500", "--quick"], "run_all: error: --quick: no quick run for fly_swarm500"),
    ],
)
def test_run_all_refuses_bad_input_in_one_line_and_runs_nothing(argv, error, capsys, tmp_path):
    assert run_all.main([*argv, "--results", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert err.startswith(error) and err.count("\n") == 1
    assert not list(tmp_path.iterdir())


def test_the_readme_is_one_page_and_its_links_resolve():
    readme = (ROOT / "README.md").read_text()
    assert len(readme.splitlines()) <= 150
    for target in re.findall(r"\]\(([^)#]+)\)", readme):
        if not target.startswith("http"):
            assert (ROOT / target).exists(), target
    assert "gcs-planner demo" in readme and "bash .ci/run" in readme
