"""`gcs-planner sweep`: every run once, deterministic per seed, resumable, failures recorded, and the
same results on a Dask LocalCluster as on local processes."""

from __future__ import annotations

import csv
import math
import os
from pathlib import Path

import pytest

from gcs_planner.analysis.sweep import load_study, marginals, metric, run_study, summarise
from gcs_planner.analysis.sweep import runs as sweep_runs
from gcs_planner.cli import main
from gcs_planner.core.errors import UserError

MISSIONS = Path(__file__).resolve().parents[1] / "missions"


def _study(tmp_path: Path, grid: str, scenario: str = "straight_4uav", metrics: str = '"feasible_fraction"'):
    path = tmp_path / "study.toml"
    path.write_text(
        f'name = "t"\nscenario = "{MISSIONS / scenario}.toml"\nseeds = [0, 1]\nmetrics = [{metrics}]\n'
        f"[grid]\n{grid}\n"
    )
    return path


def _rows(out: Path) -> list[dict]:
    with out.open(newline="") as f:
        return list(csv.DictReader(f))


def test_a_killed_sweep_resumes_without_redoing_runs(tmp_path):
    study, base = load_study(_study(tmp_path, "waypoint_spacing_m = [50.0, 100.0, 200.0]"))
    out = tmp_path / "r.csv"
    assert run_study(study, base, out, workers=2, max_runs=2) == 2  # "killed" after two runs
    first = _rows(out)
    assert run_study(study, base, out, workers=2) == 4
    rows = _rows(out)
    assert rows[:2] == first and len(rows) == 6 and len({r["run_id"] for r in rows}) == 6
    assert run_study(study, base, out, workers=2) == 0  # nothing left
    summary = summarise(study, out)
    assert [s["runs"] for s in summary] == [2, 2, 2]
    assert all(s["feasible_fraction mean"] == 1.0 for s in summary)


def test_a_failing_run_is_recorded_and_the_sweep_goes_on(tmp_path):
    study, base = load_study(_study(tmp_path, "waypoint_spacing_m = [0.5, 100.0]"))
    out = tmp_path / "r.csv"
    run_study(study, base, out, workers=1)
    rows = _rows(out)
    failed = [r for r in rows if r["error"]]
    assert len(rows) == 4 and len(failed) == 2
    assert all("waypoint_spacing_m" in r["error"] and r["waypoint_spacing_m"] == "0.5" for r in failed)


def test_dask_local_cluster_gives_the_local_results(tmp_path):
    grid = "particles = [6]\niterations = [4]\nrounds = [1]\nrrt_iterations = [60]"
    path = _study(tmp_path, grid, "swarm_small", '"cost_total", "feasible_fraction", "evaluations"')
    study, base = load_study(path)
    local, dask = tmp_path / "local.csv", tmp_path / "dask.csv"
    run_study(study, base, local, workers=2)
    pytest.importorskip("distributed")
    run_study(study, base, dask, workers=2, scheduler="local")

    def results(out):
        return {r["run_id"]: {k: v for k, v in r.items() if k != "cpu_s"} for r in _rows(out)}

    assert results(local) == results(dask) and len(results(local)) == 2
    assert all(not r["error"] for r in results(local).values())


def test_cli_runs_a_study_and_refuses_a_misspelt_key(tmp_path, capsys):
    path = _study(tmp_path, "waypoint_spacing_m = [100.0]")
    out = tmp_path / "r.csv"
    assert main(["sweep", str(path), "-o", str(out), "--workers", "1"]) == 0
    assert (tmp_path / "r_summary.csv").exists() and len(_rows(out)) == 2
    png = tmp_path / "r_plots.png"
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and png.stat().st_size > 5000
    path.write_text(path.read_text().replace("seeds", "seed"))
    assert main(["sweep", str(path), "-o", str(out)]) == 2
    assert "unknown key 'seed'; did you mean 'seeds'?" in capsys.readouterr().err


def test_dotted_metrics_walk_nested_tables():
    values = {"uav1": {"fitness": 38.3, "history": [1, 2]}, "cost_total": 4.0}
    assert metric(values, "uav1.fitness") == 38.3 and metric(values, "cost_total") == 4.0
    assert math.isnan(metric(values, "uav2.fitness")) and math.isnan(metric(values, "cost_total.x"))


def test_marginals_pool_the_other_keys_and_seeds(tmp_path):
    study, _ = load_study(_study(tmp_path, "a = [1, 2]\nb = [true, false]", metrics='"m"'))
    out = tmp_path / "r.csv"
    rows = [("1", "True", "0", "1.0"), ("1", "False", "1", "3.0"), ("2", "True", "0", "10.0"),
            ("2", "False", "1", ""), ("2", "False", "0", "99.0")]  # fmt: skip
    with out.open("w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(["run_id", "seed", "error", "cpu_s", "a", "b", "m"])
        for i, (a, b, seed, m) in enumerate(rows):
            writer.writerow([i, seed, "boom" if m == "99.0" else "", 0.5, a, b, m])
    curves = marginals(study, out)
    assert curves["m", "a"] == [("1", 2.0, math.sqrt(2.0), 2), ("2", 10.0, 0.0, 1)]  # failed run left out
    assert [(v, n) for v, _, _, n in curves["m", "b"]] == [("True", 2), ("False", 1)]
    assert curves["cpu_s", "a"][1] == ("2", 0.5, 0.0, 2)


def test_a_grid_over_scenarios_plans_each_file_and_pools_flags(tmp_path):
    from gcs_planner.planning import load_scenario, plan_scenario

    names = [os.path.relpath(MISSIONS / f"deconflict_{n}uav.toml", tmp_path) for n in (5, 10)]
    path = tmp_path / "study.toml"
    path.write_text(f'name = "t"\nseeds = [1]\nmetrics = ["iterations_total", "conflict_free"]\n'
                    f"[grid]\nscenario = {names!r}\nmax_rounds = [1]\n".replace("'", '"'))  # fmt: skip
    study, base = load_study(path)
    out = tmp_path / "r.csv"
    assert run_study(study, base, out, workers=1) == 2
    rows = {r["scenario"]: r for r in _rows(out)}
    for name in names:
        scenario = load_scenario(tmp_path / name)
        scenario.planner.update(max_rounds=1)
        direct = plan_scenario(scenario, seed=1).metrics
        assert int(rows[name]["iterations_total"]) == direct["iterations_total"]
    assert [s["scenario"] for s in summarise(study, out)] == names  # the study's order
    summary = {s["scenario"]: s for s in summarise(study, out)}
    assert all(s["conflict_free mean"] in (0.0, 1.0) for s in summary.values()) and len(summary) == 2
    path.write_text(path.read_text().replace("deconflict_10uav", "deconflict_55uav"))
    with pytest.raises(UserError, match="deconflict_55uav.toml' is not a file"):
        load_study(path)


@pytest.mark.parametrize("path", sorted((MISSIONS.parent / "studies").glob("*.toml")), ids=lambda p: p.stem)
def test_every_bundled_study_loads_and_names_its_runs(path):
    study, base = load_study(path)
    runs = list(sweep_runs(study))
    assert runs and len({ident for ident, _, _ in runs}) == len(runs)


def test_a_study_task_runs_instead_of_the_planner_and_a_misspelt_one_is_refused(tmp_path):
    from gcs_planner.planning.coalition import montecarlo

    paper = MISSIONS / "coalition_paper.toml"
    path = tmp_path / "study.toml"
    task = "gcs_planner.planning.coalition.montecarlo:run"
    path.write_text(f'name = "t"\nscenario = "{paper}"\ntask = "{task}"\nseeds = [3]\n'
                    'metrics = ["J", "served"]\n[grid]\nuavs = [24]\nt_end_s = [350.0]\n')  # fmt: skip
    study, base = load_study(path)
    out = tmp_path / "r.csv"
    run_study(study, base, out, workers=1)
    (row,) = _rows(out)
    direct = montecarlo.run(paper, {"uavs": 24, "t_end_s": 350.0}, 3)
    assert not row["error"] and float(row["J"]) == direct["J"] and float(row["served"]) == direct["served"]
    path.write_text(path.read_text().replace("montecarlo:run", "montecarlo:rnu"))
    with pytest.raises(UserError, match="task 'gcs_planner.planning.coalition.montecarlo:rnu' is not"):
        load_study(path)


def test_an_output_file_of_another_study_is_refused_before_any_run(tmp_path):
    out = tmp_path / "r.csv"
    study, base = load_study(_study(tmp_path, "waypoint_spacing_m = [100.0]"))
    run_study(study, base, out, workers=1, max_runs=1)
    before = out.read_text()
    other, base = load_study(_study(tmp_path, "waypoint_spacing_m = [100.0]\nparticles = [6]"))
    with pytest.raises(UserError, match="r.csv: its columns are not this study's"):
        run_study(other, base, out, workers=1)
    assert out.read_text() == before  # nothing appended under the wrong heads


def test_table3_runs_through_the_runner_as_solved_directly_with_a_history_kept_whole(tmp_path):
    """benchmarks/acmpso_table3.py's runs: the sweep row of (tuned, lpso, run 3) is the run solved
    with its generator; its JSON history is the PSO's, and the summary leaves it out."""
    import json

    import msgspec
    import numpy as np

    from gcs_planner.planning.acmpso import solve
    from gcs_planner.planning.acmpso_study import _problem

    study, base = load_study(MISSIONS.parent / "studies" / "acmpso_table3.toml")
    grid = {**study.grid, "algorithm": ["lpso"], "variant": ["tuned"]}
    study = msgspec.structs.replace(study, seeds=[3], grid=grid)
    out = tmp_path / "t3.csv"
    run_study(study, base, out, workers=1)
    (row,) = _rows(out)
    problem, _, _ = _problem(MISSIONS / "acmpso_paper.toml", "literal")
    direct = solve(problem, "lpso", np.random.default_rng([0, 1, 1, 3]), "tuned")
    assert not row["error"] and float(row["fitness"]) == direct.fitness
    assert json.loads(row["history"]) == direct.pso.history.tolist()
    assert row["radar_violated"] in ("True", "False")
    (summary,) = summarise(study, out)
    assert summary["fitness mean"] == direct.fitness and math.isnan(summary["history mean"])
