"""Outputs stay inside their folder, never replace an input, and are as readable as open() makes them."""

from __future__ import annotations

import json
import os
import stat

import pytest
from cli_checks import refused as _fails
from input_mutations import SCENARIO, base_mcap, base_plan, base_tlog, toml_dumps

from gcs_planner.cli import main
from gcs_planner.core.validation import write_text_atomic


@pytest.mark.parametrize("vid", ["../../x", "/abs/x", "..", ".hidden", "a\\b", "c:x"])
def test_export_refuses_vehicle_ids_that_leave_the_output_folder(tmp_path, capsys, vid):
    data = base_plan()
    data["vehicles"][0]["vehicle_id"] = vid
    plan = tmp_path / "p.json"
    plan.write_text(json.dumps(data))
    work = tmp_path / "a" / "b"
    work.mkdir(parents=True)
    before = sorted(p for p in tmp_path.rglob("*"))
    _fails(["export", str(plan), "-o", str(work / "out")], capsys, "vehicle id")
    assert sorted(p for p in tmp_path.rglob("*")) == before
    assert not os.path.exists("/abs/x.plan")


def _same(path, data: bytes) -> None:
    assert path.read_bytes() == data


def test_commands_refuse_an_output_that_is_their_input(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    scen = tmp_path / "s.toml"
    scen.write_text(toml_dumps(SCENARIO))
    scen_bytes = scen.read_bytes()
    _fails(["plan", str(scen), "-o", str(scen)], capsys, "-o", "input")
    _fails(["plan", str(scen), "-o", "./s.toml"], capsys, "input")
    os.link(scen, tmp_path / "hard.toml")
    _fails(["plan", str(scen), "-o", str(tmp_path / "hard.toml")], capsys, "input")
    _same(scen, scen_bytes)

    mcap = tmp_path / "f.mcap"
    mcap.write_bytes(base_mcap(tmp_path))
    mcap_bytes = mcap.read_bytes()
    _fails(["replay", str(mcap), "--rrd", str(mcap)], capsys, "--rrd", "input")
    _same(mcap, mcap_bytes)

    wpl = tmp_path / "m.waypoints"
    wpl.write_text("QGC WPL 110\n0\t1\t0\t16\t0\t0\t0\t0\t47.0\t8.0\t100.0\t1\n")
    wpl_bytes = wpl.read_bytes()
    _fails(["convert", str(wpl), str(wpl)], capsys, "OUTPUT", "input")
    _same(wpl, wpl_bytes)

    plan = tmp_path / "p.json"
    plan.write_text(json.dumps(base_plan()))
    plan_bytes = plan.read_bytes()
    tlog = tmp_path / "f.tlog"
    tlog.write_bytes(base_tlog())
    _fails(["import-log", str(tlog), "-o", str(plan), "--plan", str(plan)], capsys, "-o", "input")
    _same(plan, plan_bytes)

    study = tmp_path / "study.toml"
    study.write_text(f'name = "t"\nscenario = "{scen}"\nseeds = [0]\nmetrics = ["feasible_fraction"]\n')
    study_bytes = study.read_bytes()
    _fails(["sweep", str(study), "-o", str(study)], capsys, "-o", "input")
    _same(study, study_bytes)


def test_export_output_file_that_is_the_plan_is_refused(tmp_path, capsys):
    data = base_plan()
    data["vehicles"][0]["vehicle_id"] = "p"
    plan = tmp_path / "p.plan"
    plan.write_text(json.dumps(data))
    before = plan.read_bytes()
    _fails(["export", str(plan), "-o", str(tmp_path)], capsys, "input")
    assert plan.read_bytes() == before


def test_atomic_writes_get_the_mode_open_would_give(tmp_path):
    old = os.umask(0o022)
    try:
        write_text_atomic(tmp_path / "new.txt", "x")
        assert stat.S_IMODE((tmp_path / "new.txt").stat().st_mode) == 0o644
        os.umask(0o002)
        write_text_atomic(tmp_path / "new2.txt", "x")
        assert stat.S_IMODE((tmp_path / "new2.txt").stat().st_mode) == 0o664
        kept = tmp_path / "kept.txt"
        kept.write_text("old")
        kept.chmod(0o640)
        write_text_atomic(kept, "new")
        assert stat.S_IMODE(kept.stat().st_mode) == 0o640 and kept.read_text() == "new"
    finally:
        os.umask(old)


def test_exported_missions_are_readable_by_the_group(tmp_path, capsys):
    plan = tmp_path / "p.json"
    plan.write_text(json.dumps(base_plan()))
    old = os.umask(0o022)
    try:
        assert main(["export", str(plan), "-o", str(tmp_path / "out")]) == 0
    finally:
        os.umask(old)
    files = list((tmp_path / "out").iterdir())
    assert files and all(stat.S_IMODE(f.stat().st_mode) == 0o644 for f in files)
