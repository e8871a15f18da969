"""Every error is one line of bounded length, and huge inputs are refused before they are read
whole or built item by item."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from gcs_planner.cli import main
from gcs_planner.core.errors import MAX_ERROR_CHARS

MAX_LINE = len("gcs-planner import-log: error: ") + MAX_ERROR_CHARS


def one_bounded_line(capsys, *words) -> str:
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err[:3]
    assert len(err[0]) <= MAX_LINE, len(err[0])
    for word in words:
        assert word in err[0], err[0]
    return err[0]


def scenario(path: Path, n: int) -> Path:
    lines = ['name = "big"', "origin = {lat_deg = 47.4, lon_deg = 8.5, alt_m = 400.0}",
             '[planner]', 'name = "straight"']  # fmt: skip
    for i in range(n):  # no sysids: every vehicle is sysid 0, which cannot fly
        lines += ["[[vehicles]]", f'id = "v{i}"', f"start = [{i}.0, 0.0, 20.0]"]
        lines += [f"goal = [300.0, {i}.0, 20.0]"]
    path.write_text("\n".join(lines) + "\n")
    return path


def test_an_error_quoting_every_vehicle_is_one_bounded_line(tmp_path, capsys):
    """A fleet without sysids was one line of 3 characters per vehicle (300 KB for 100k)."""
    s = scenario(tmp_path / "s.toml", 600)
    assert main(["fly", str(s), "-o", str(tmp_path / "out"), "--no-rrd"]) == 2
    line = one_bounded_line(capsys, "sysid", "characters in all")
    assert line.startswith("gcs-planner fly: error: every vehicle needs its own MAVLink sysid")
    assert not (tmp_path / "out").exists()


def test_a_huge_flag_value_is_one_bounded_line(tmp_path, capsys):
    s = scenario(tmp_path / "s.toml", 1)
    assert main(["plan", str(s), "--seed", "x" * 100_000, "-o", str(tmp_path / "p.json")]) == 2
    one_bounded_line(capsys, "--seed")
    assert not (tmp_path / "p.json").exists()


def _plan_file(path: Path, n: int) -> Path:
    item = {"type": "SimpleItem", "command": 16, "frame": 3, "params": [0, 0, 0, 0, 47.4, 8.5, 20],
            "autoContinue": True, "doJumpId": 1}  # fmt: skip
    doc = {"fileType": "Plan", "version": 1, "groundStation": "QGroundControl",
           "mission": {"version": 2, "plannedHomePosition": [47.4, 8.5, 400], "items": [item] * n},
           "geoFence": {"version": 2, "polygons": [], "circles": []},
           "rallyPoints": {"version": 2, "points": []}}  # fmt: skip
    path.write_text(json.dumps(doc))
    return path


def test_a_plan_with_more_items_than_mission_count_is_refused_before_they_are_built(
    tmp_path, capsys, monkeypatch
):
    import gcs_planner.missions.planfile as planfile

    built = []
    real = planfile._parse_simple
    monkeypatch.setattr(planfile, "_parse_simple", lambda *a: built.append(1) or real(*a))
    src = _plan_file(tmp_path / "big.plan", 65_536)
    assert main(["convert", str(src), str(tmp_path / "out.plan")]) == 2
    one_bounded_line(capsys, "mission.items", "65,536", "65,535")
    assert built == [] and not (tmp_path / "out.plan").exists()


def test_a_rally_list_over_mission_count_is_refused(tmp_path, capsys):
    src = _plan_file(tmp_path / "r.plan", 1)
    doc = json.loads(src.read_text())
    doc["rallyPoints"]["points"] = [[47.4, 8.5, 20]] * 65_536
    src.write_text(json.dumps(doc))
    assert main(["convert", str(src), str(tmp_path / "out.plan")]) == 2
    one_bounded_line(capsys, "rallyPoints.points", "65,535")


@pytest.mark.parametrize("kind", ["scenario", "plan.json", ".plan"])
def test_a_file_over_the_size_limit_is_refused_before_it_is_read_whole(tmp_path, capsys, monkeypatch, kind):
    import gcs_planner.core.validation as validation
    import gcs_planner.missions.files as files

    monkeypatch.setattr(validation, "MAX_INPUT_BYTES", 4096)
    monkeypatch.setattr(files, "MAX_INPUT_BYTES", 4096)
    out = tmp_path / "out.json"
    if kind == "scenario":
        argv = ["plan", str(scenario(tmp_path / "s.toml", 100)), "-o", str(out)]
    elif kind == "plan.json":
        (tmp_path / "p.json").write_text(json.dumps({"pad": "x" * 5000}))
        argv = ["export", str(tmp_path / "p.json"), "-o", str(tmp_path / "exp")]
    else:
        argv = ["convert", str(_plan_file(tmp_path / "b.plan", 100)), str(tmp_path / "out.plan")]
    assert main(argv) == 2
    one_bounded_line(capsys, "MiB")
    assert not out.exists() and not (tmp_path / "exp").exists() and not (tmp_path / "out.plan").exists()


def test_an_endless_input_is_refused_at_the_limit(tmp_path, capsys, monkeypatch):
    """/dev/zero has no size to check first: reading stops one byte past the limit."""
    import gcs_planner.core.validation as validation

    monkeypatch.setattr(validation, "MAX_INPUT_BYTES", 1 << 20)
    assert main(["plan", "/dev/zero", "-o", str(tmp_path / "p.json")]) == 2
    one_bounded_line(capsys, "/dev/zero", "MiB")
