"""Manned traffic, terrain peaks, starts and JSON numbers are checked: one line, exit 2, no traceback."""

from __future__ import annotations

import copy
import json
import math

import pytest
from input_mutations import SCENARIO, base_plan, toml_dumps

from gcs_planner.cli import main

MANNED = {
    "id": "ga1", "dt_s": 1.0, "position_m": [-60.0, 6.0, 12.0], "velocity_mps": [10.0, 0.0, 0.0],
    "observed_s": 10.0,
    "modes": [{"name": "cruise", "velocity_mps": [10.0, 0.0, 0.0], "sigma_mps": [0.3, 0.3, 0.1],
               "strength": 20.0, "weight": 0.9}],
}  # fmt: skip
TERRAIN = {"type": "peaks", "peaks": [{"h_m": 50.0, "x_m": 100.0, "y_m": 100.0, "sx_m": 30.0, "sy_m": 30.0}]}


def _fails(argv, capsys, *words):
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    assert len(err[0]) < 400, err[0][:400]
    for word in words:
        assert word in err[0], err[0]


def _edit_manned(key, value, mode=False):
    def edit(d):
        m = copy.deepcopy(MANNED)
        (m["modes"][0] if mode else m)[key] = value
        d["manned"] = [m]

    return edit


def _edit_peak(key, value):
    def edit(d):
        t = copy.deepcopy(TERRAIN)
        t["peaks"][0][key] = value
        d["terrain"] = t

    return edit


def _start_z(z):
    def edit(d):
        d["vehicles"][0]["start"] = [0.0, 0.0, z]

    return edit


@pytest.mark.parametrize(
    ("edit", "word"),
    [
        (_edit_manned("strength", 0.0, mode=True), "strength"),
        (_edit_manned("strength", math.inf, mode=True), "strength"),
        (_edit_manned("sigma_mps", [0.0, 0.3, 0.1], mode=True), "sigma_mps"),
        (_edit_manned("velocity_mps", [], mode=True), "velocity_mps"),
        (_edit_manned("weight", math.nan, mode=True), "weight"),
        (_edit_manned("dt_s", math.nan), "dt_s"),
        (_edit_manned("dt_s", 0.0), "dt_s"),
        (_edit_manned("velocity_mps", []), "velocity_mps"),
        (_edit_manned("observed_s", 1e9), "observed_s"),
        (_edit_manned("position_m", [0.0, 0.0, math.inf]), "position_m"),
        (_edit_manned("track", [[0.0, 1.0, 2.0]]), "track"),
        (_edit_peak("h_m", -math.inf), "h_m"),
        (_edit_peak("sx_m", math.inf), "sx_m"),
        (_edit_peak("sy_m", 0.0), "sy_m"),
        (_edit_peak("x_m", math.nan), "x_m"),
        (_start_z(-500.0), "underground"),
    ],
)
def test_nonsense_world_tables_are_one_line(tmp_path, capsys, edit, word):
    data = copy.deepcopy(SCENARIO)
    edit(data)
    path = tmp_path / "s.toml"
    path.write_text(toml_dumps(data))
    out = tmp_path / "p.json"
    _fails(["plan", str(path), "-o", str(out)], capsys, word)
    assert not out.exists()


def test_valid_world_tables_pass(tmp_path):
    from gcs_planner.planning import parse_scenario

    data = copy.deepcopy(SCENARIO)
    data["manned"], data["terrain"] = [copy.deepcopy(MANNED)], copy.deepcopy(TERRAIN)
    parse_scenario(data)


@pytest.mark.parametrize("number", ["1" * 5000, "-" + "9" * 6000])
def test_huge_json_numbers_are_one_line(tmp_path, capsys, number):
    text = json.dumps(base_plan()).replace('"sysid": 1', f'"sysid": {number}', 1)
    plan = tmp_path / "p.json"
    plan.write_text(text)
    _fails(["export", str(plan), "-o", str(tmp_path / "o")], capsys, "JSON")
    (tmp_path / "x.plan").write_text('{"fileType": "Plan", "version": ' + number + "}")
    _fails(["convert", str(tmp_path / "x.plan"), str(tmp_path / "y.waypoints")], capsys, "JSON")
    (tmp_path / "d.plan").write_text('{"fileType": "Plan", "mission": ' + "[" * 100_000 + "]" * 100_000 + "}")
    _fails(["convert", str(tmp_path / "d.plan"), str(tmp_path / "y.waypoints")], capsys, "nested")
