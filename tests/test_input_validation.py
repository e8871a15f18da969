"""Issue 14 regressions: each bad input is one stderr line naming the field and value, exit 2, and
nothing sent or left half written (every test here failed on 7e4d890)."""

from __future__ import annotations

import copy
import errno
import json
import math
import tomllib
from pathlib import Path

import pytest
from cli_checks import refused as _fails
from input_mutations import SCENARIO, base_mcap, base_plan, base_tlog, toml_dumps

from gcs_planner.cli import main
from gcs_planner.commands import fly as fly_command
from gcs_planner.flight import runner as fly_module
from gcs_planner.missions.validate import MissionValidationError, validate_items
from gcs_planner.telemetry import FlightLogger
from gcs_planner.wire.types import MissionItem, MissionType

MISSIONS = Path(__file__).resolve().parents[1] / "missions"


def _scenario(tmp_path, edit=None, name="s.toml"):
    data = copy.deepcopy(SCENARIO)
    if edit:
        edit(data)
    path = tmp_path / name
    path.write_text(toml_dumps(data))
    return str(path)


def _plan(tmp_path, edit=None, name="p.json"):
    data = base_plan()
    if edit:
        edit(data)
    path = tmp_path / name
    path.write_text(json.dumps(data))
    return str(path)


def _veh(i, key, value):
    def edit(d):
        d["vehicles"][i][key] = value

    return edit


# -- 9: tracebacks ----------------------------------------------------------------------------------
def test_fly_and_import_tlog_with_a_broken_plan_json(tmp_path, capsys):
    bad = tmp_path / "bad.json"
    bad.write_text('{"origin": ')
    _fails(["fly", _scenario(tmp_path), "--plan", str(bad), "-o", str(tmp_path / "o")], capsys, "bad.json")
    assert not (tmp_path / "o").exists()
    (tmp_path / "f.tlog").write_bytes(base_tlog())
    _fails(["import-tlog", str(tmp_path / "f.tlog"), "--plan", str(bad)], capsys, "bad.json")
    assert not (tmp_path / "f.mcap").exists()


@pytest.mark.parametrize(
    "text, words",
    [
        (b"origin = 3\n", ["origin", "3"]),
        (b'vehicles = 5\n[origin]\nlat_deg = 1\nlon_deg = 1\n[planner]\nname = "straight"\n', ["vehicles"]),
        (b"name = '\xff\xfe'\n", ["UTF-8"]),
        (toml_dumps({**SCENARIO, "obstacles": [1]}).encode(), ["[obstacles]", "[1]"]),
        (toml_dumps({**SCENARIO, "vehicles": [1, 2]}).encode(), ["vehicles[0]"]),
    ],
)
def test_scenario_that_is_not_tables_lists_or_utf8(tmp_path, capsys, text, words):
    (tmp_path / "s.toml").write_bytes(text)
    _fails(["plan", str(tmp_path / "s.toml"), "-o", str(tmp_path / "p.json")], capsys, *words)


@pytest.mark.parametrize("spacing", [0, 1e-9, -5, "x"])
def test_unchecked_waypoint_spacing(tmp_path, capsys, spacing):
    scen = _scenario(tmp_path, lambda d: d["planner"].update(waypoint_spacing_m=spacing))
    _fails(["plan", scen, "-o", str(tmp_path / "p.json")], capsys, "waypoint_spacing_m")
    assert not (tmp_path / "p.json").exists()


def test_seed_must_be_a_non_negative_integer(tmp_path, capsys):
    _fails(["plan", _scenario(tmp_path, lambda d: d["planner"].update(seed="x")), "-o", "p"], capsys, "seed")
    _fails(["plan", _scenario(tmp_path), "--seed", "-1", "-o", str(tmp_path / "p.json")], capsys, "--seed")


def test_deeply_nested_json_and_toml(tmp_path, capsys):
    (tmp_path / "p.json").write_bytes(b"[" * 100_000 + b"]" * 100_000)
    _fails(["export", str(tmp_path / "p.json"), "-o", str(tmp_path)], capsys, "nested too deeply")
    (tmp_path / "s.toml").write_bytes(b"a = " + b"[" * 100_000 + b"]" * 100_000)
    _fails(["plan", str(tmp_path / "s.toml"), "-o", str(tmp_path / "x.json")], capsys, "nested too deeply")


def test_mission_altitude_must_fit_float32_and_the_planet():
    item = MissionItem(0, 6, 16, 1, 1, 0, 2, 0, 0, 473977420, 85455940, 1e308)
    with pytest.raises(MissionValidationError, match="float32"):
        validate_items([item])
    with pytest.raises(MissionValidationError, match="altitude limits"):
        validate_items([MissionItem(0, 6, 16, 1, 1, 0, 2, 0, 0, 473977420, 85455940, 1e6)])


def test_plan_altitude_1e308_is_refused_before_anything_is_sent(tmp_path, capsys):
    def edit(d):
        d["vehicles"][0]["waypoints"][1][2] = 1e308

    plan = _plan(tmp_path, edit)
    argv = ["upload", "--connect", "udpout:127.0.0.1:9", "--sysid", "1", "--heartbeat-timeout", "0.1", plan]
    _fails(argv, capsys, "altitude", "1e+308")


def test_corrupt_tlog_timestamps_leave_no_mcap(tmp_path, capsys):
    data = bytearray(base_tlog())
    data[0:8] = b"\xff" * 8  # the first frame's timestamp
    (tmp_path / "f.tlog").write_bytes(data)
    assert main(["import-tlog", str(tmp_path / "f.tlog"), "-o", str(tmp_path / "f.mcap")]) == 0
    capsys.readouterr()
    (tmp_path / "g.tlog").write_bytes(b"\xff" * 8 + data[8:40])  # nothing usable
    _fails(["import-tlog", str(tmp_path / "g.tlog"), "-o", str(tmp_path / "g.mcap")], capsys, "g.tlog")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["f.mcap", "f.tlog", "g.tlog"]


def test_bad_mcap_attachment_is_ignored_not_a_traceback(tmp_path, capsys):
    data = bytearray(base_mcap(tmp_path))
    at = data.index(b'"origin"')
    data[at : at + 8] = b"\xff\xfe\x00[[[[["
    (tmp_path / "f.mcap").write_bytes(data)
    assert main(["replay", str(tmp_path / "f.mcap"), "--to", "udpout:127.0.0.1:9", "--speed", "0"]) == 0


@pytest.mark.parametrize(
    "flags, word",
    [
        (["--workers", "0"], "--workers"),
        (["--speedup", "nan"], "--speedup"),
        (["--speedup", "0"], "--speedup"),
        (["--drift", "99:1:1"], "99"),
        (["--drift", "1:nan:0"], "--drift"),
        (["--max-cross-track", "-1"], "--max-cross-track"),
    ],
)
def test_fly_flags_are_checked_before_anything_is_written_or_sent(tmp_path, capsys, monkeypatch, flags, word):
    monkeypatch.setattr(fly_command, "mock_vehicles", lambda *a, **k: pytest.fail("a mock fleet was started"))
    out = tmp_path / "out"
    _fails(["fly", _scenario(tmp_path), "-o", str(out), "--no-rrd", *flags], capsys, word)
    assert not out.exists()


def test_output_into_a_missing_folder_or_onto_a_file(tmp_path, capsys):
    scen = _scenario(tmp_path)
    _fails(["plan", scen, "-o", str(tmp_path / "missing" / "p.json")], capsys, "does not exist")
    _fails(["fly", scen, "-o", scen, "--no-rrd"], capsys, "is a file")
    _fails(["export", _plan(tmp_path), "-o", scen], capsys, "is a file")
    (tmp_path / "f.tlog").write_bytes(base_tlog())
    _fails(["import-tlog", str(tmp_path / "f.tlog"), "-o", str(tmp_path / "no" / "f.mcap")], capsys, "-o")


def test_full_disk_still_reports_the_flight(tmp_path, capsys, monkeypatch):
    class FullDisk(FlightLogger):
        def close(self):
            super().close()
            raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(fly_module, "FlightLogger", FullDisk)

    def one_short_vehicle(d):
        d["vehicles"] = d["vehicles"][:1]
        d["vehicles"][0]["goal"] = [60.0, 0.0, 20.0]

    scen = _scenario(tmp_path, one_short_vehicle)
    assert main(["fly", scen, "-o", str(tmp_path / "o"), "--no-rrd"]) == 2
    out, err = capsys.readouterr()
    assert err.strip().splitlines()[-1].endswith("No space left on device")
    assert "vehicles conform" in out  # the report came before the error line


# -- 10: nonsense accepted ---------------------------------------------------------------------------
@pytest.mark.parametrize(
    "edit, word",
    [
        (_veh(0, "speed_mps", math.inf), "speed_mps"),
        (_veh(0, "speed_mps", 1e9), "speed_mps"),
        (_veh(1, "turn_radius_m", -20.0), "turn_radius_m"),
        (_veh(0, "separation_m", -5.0), "separation_m"),
        (_veh(0, "min_alt_m", 200.0), "min_alt_m"),
        (_veh(0, "goal", [4e7, 0.0, 20.0]), "goal"),
        (lambda d: d.update(vehicles=[]), "vehicles"),
        (lambda d: d["planner"].update(waypoint_spacing_m=-80.0), "waypoint_spacing_m"),
        # a plan is sampled in time and space: these once asked the checker for terabytes
        (_veh(0, "speed_mps", 1e-9), "speed_mps"),
        (_veh(0, "speed_mps", 1e-6), "speed_mps"),
        (
            lambda d: d["vehicles"][0].update(speed_mps=0.01, goal=[9e5, 0.0, 20.0]),
            "speed_mps 0.01 m/s takes",
        ),
        (_veh(1, "turn_radius_m", 1e-6), "turn_radius_m must be 0 or at least 1"),
        (_veh(0, "landing_mps", 1e-9), "landing_mps"),
        (lambda d: d["vehicles"][0].update(landing_mps=0.01, goal=[300.0, 0.0, 9e4]), "to land"),
    ],
)
def test_nonsense_scenario_values(tmp_path, capsys, edit, word):
    out = tmp_path / "p.json"
    _fails(["plan", _scenario(tmp_path, edit), "-o", str(out)], capsys, word)
    assert not out.exists()


@pytest.mark.parametrize(
    "planner, key, value",
    [
        ("priority_swarm", "dt_s", 1e-4),
        ("priority_swarm", "rrt_step_m", 1e-9),
        ("priority_swarm", "delay_step_s", 1e-9),
        ("deconflict_4d", "zone_step_s", 1e-9),
        ("deconflict_4d", "delay_step_s", 1e-9),
        ("acmpso", "validate_spacing_m", 1e-9),
    ],
)
def test_sampling_steps_finer_than_a_vehicle_flies_are_refused(tmp_path, capsys, planner, key, value):
    """A step of 1e-4 s made the swarm planner ask for 8 GiB; every step has a floor (core/validation.py)."""
    out = tmp_path / "p.json"
    scenario = _scenario(tmp_path, lambda d: d.update(planner={"name": planner, key: value}))
    _fails(["plan", scenario, "-o", str(out)], capsys, f"planner.{key} must be a number >=")
    assert not out.exists()


@pytest.mark.parametrize(
    "edit, words",
    [
        ({"a_max_mps2": 1e-9}, ["vehicles[0].a_max_mps2", ">= 0.01"]),  # asked for 37 GiB
        ({"climb_mps": 1e-9}, ["vehicles[0].climb_mps", ">= 0.01"]),  # 119 GiB
        ({"v_max_mps": math.inf}, ["vehicles[0].v_max_mps", "inf"]),
        ({"takeoff_s": "x"}, ["vehicles[0].takeoff_s", "'x'"]),
        ({"arrival_s": math.nan}, ["vehicles[0].arrival_s", "nan"]),
        (
            {"climb_mps": 0.01, "start": [0.0, 0.0, 9e3], "max_alt_m": 1e4},
            ["vehicles[0]: the flight ends after"],
        ),
    ],
)
def test_nonsense_4d_vehicle_values(tmp_path, capsys, edit, words):
    data = tomllib.loads((MISSIONS / "deconflict_4uav.toml").read_text())
    data["vehicles"][0].update(edit)
    (tmp_path / "s.toml").write_text(toml_dumps(data))
    out = tmp_path / "p.json"
    _fails(["plan", str(tmp_path / "s.toml"), "-o", str(out)], capsys, *words)
    assert not out.exists()


def test_an_acmpso_path_of_one_node_is_refused(tmp_path, capsys):
    """n_nodes = 1 passed the config and ended in the problem's own ValueError (a traceback)."""
    scenario = _scenario(tmp_path, lambda d: d.update(planner={"name": "acmpso", "n_nodes": 1}))
    _fails(["plan", scenario, "-o", str(tmp_path / "p.json")], capsys, "planner.n_nodes", ">= 2")


def _target(key, value):
    def edit(d):
        d["coalition"]["targets"][0][key] = value

    return edit


@pytest.mark.parametrize(
    "edit, words",
    [
        (lambda d: d["planner"].update(detect_radius_m=0), ["planner.detect_radius_m", ">= 1"]),
        (lambda d: d["planner"].update(assess_radius_m=0), ["planner.assess_radius_m", ">= 1"]),
        (lambda d: d["planner"].update(t_end_s=0), ["planner.t_end_s", "> 0"]),
        (lambda d: d["planner"].update(kappa=1e9), ["planner.kappa", "<= 10"]),
        (lambda d: d["planner"].update(sample_ds_m=1e-9), ["planner.sample_ds_m", ">= 0.1"]),
        (_target("approx", [math.nan, 0.0]), ["targets[0]: approx[0]", "nan"]),
        (_target("position", [1e12, 0.0]), ["targets[0]: position[0]", "<= 1e+06"]),
        (_target("strike_angles_deg", [math.inf]), ["strike_angles_deg[0]", "inf"]),
        (_target("recon_s", 1e308), ["targets[0]: recon_s", "<= 604800"]),
        (lambda d: d["coalition"]["threats"][0].update(radius_m=-1.0), ["threats[0]: radius_m", "> 0"]),
    ],
)
def test_nonsense_coalition_values(tmp_path, capsys, edit, words):
    """Each once crashed the coalition planner (an infinite path length, an empty history) or asked
    for gigabytes of samples."""
    data = tomllib.loads((MISSIONS / "coalition_sitl.toml").read_text())
    edit(data)
    (tmp_path / "s.toml").write_text(toml_dumps(data))
    out = tmp_path / "p.json"
    _fails(["plan", str(tmp_path / "s.toml"), "-o", str(out)], capsys, *words)
    assert not out.exists()


@pytest.mark.parametrize(
    "key, index, value",
    [("speeds_mps", 1, 1e9), ("acceptance_radius_m", None, -2.0), ("waypoints", 1, [4e7, 0.0, 20.0])],
)
def test_nonsense_plan_json_values(tmp_path, capsys, key, index, value):
    def edit(d):
        if index is None:
            d["vehicles"][0][key] = value
        else:
            d["vehicles"][0][key][index] = value

    out = tmp_path / "out"
    _fails(["export", _plan(tmp_path, edit), "-o", str(out)], capsys, key)
    assert not out.exists()


def test_negative_speed_change_and_fence_radius_are_refused():
    speed = MissionItem(0, 2, 178, 1, 1, 1.0, -5.0, -1.0, 0.0)
    with pytest.raises(MissionValidationError, match="speed"):
        validate_items([speed])
    validate_items([MissionItem(0, 2, 178, 1, 1, 1.0, -1.0, -1.0, 0.0)])  # -1: no change
    circle = MissionItem(0, 0, 5004, 0, 1, -50.0, x=473977420, y=85455940, mission_type=MissionType.FENCE)
    with pytest.raises(MissionValidationError, match="radius"):
        validate_items([circle], mission_type=MissionType.FENCE)


def test_duplicate_sysids_in_a_plan_upload(tmp_path, capsys):
    plan = _plan(tmp_path, lambda d: d["vehicles"][1].update(sysid=1))
    argv = ["upload", "--connect", "udpout:127.0.0.1:9", "--sysid", "all", "--heartbeat-timeout", "0.1", plan]
    _fails(argv, capsys, "sysid", "twice")


def test_duplicate_vehicle_ids_in_export(tmp_path, capsys):
    plan = _plan(tmp_path, lambda d: d["vehicles"][1].update(vehicle_id="uav1"))
    _fails(["export", plan, "-o", str(tmp_path / "out")], capsys, "uav1", "twice")
    assert not (tmp_path / "out").exists()


def test_replay_of_a_file_that_is_not_mcap(tmp_path, capsys):
    (tmp_path / "x.mcap").write_text("hello")
    _fails(["replay", str(tmp_path / "x.mcap"), "--to", "udpout:127.0.0.1:9"], capsys, "not an MCAP file")
