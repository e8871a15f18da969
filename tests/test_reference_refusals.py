"""Files and values the reference tools (QGroundControl, MAVSDK, the autopilots) refuse are refused
here too, with one line; and `download FILE | head` keeps FILE and ends quietly."""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys

import pytest
from cli_checks import refused as _fails

from gcs_planner.core.geo import Origin
from gcs_planner.missions.files import MissionFile, MissionFileError, load_mission_file, save_mission_file
from gcs_planner.missions.validate import MissionValidationError, validate_items
from gcs_planner.wire.types import MissionItem

ORIGIN = Origin(47.397742, 8.545594, 488.0)
HOME = "0\t1\t0\t16\t0\t0\t0\t0\t47.3977420\t8.5455940\t488.0\t1\n"


def _plan_doc(**edit):
    doc = {"fileType": "Plan", "version": 1, "groundStation": "QGroundControl",
           "mission": {"version": 2, "firmwareType": 3, "vehicleType": 2, "cruiseSpeed": 15, "hoverSpeed": 5,
                       "items": [], "plannedHomePosition": [47.39, 8.54, 488.0]},
           "geoFence": {"version": 2, "circles": [], "polygons": []},
           "rallyPoints": {"version": 2, "points": []}}  # fmt: skip
    doc.update(edit)
    return doc


@pytest.mark.parametrize("mission", [None, [], {"version": 2}])
def test_plan_without_a_mission_object_is_refused(tmp_path, capsys, mission):
    doc = _plan_doc()
    if mission is None:
        del doc["mission"]
    else:
        doc["mission"] = mission
    src = tmp_path / "x.plan"
    src.write_text(json.dumps(doc))
    with pytest.raises(MissionFileError, match="mission"):
        load_mission_file(src)
    _fails(["convert", str(src), str(tmp_path / "y.waypoints")], capsys, "mission")
    assert not (tmp_path / "y.waypoints").exists()


def _wpl(tmp_path, *rows):
    path = tmp_path / "m.waypoints"
    path.write_text("QGC WPL 110\n" + HOME + "".join(rows))
    return path


def test_nan_only_where_the_command_gives_it_a_meaning(tmp_path):
    mf = load_mission_file(_wpl(tmp_path, "1\t0\t3\t178\t1\tnan\t-1\t0\t0\t0\t0\t1\n"))
    with pytest.raises(MissionValidationError, match="param2 = nan"):
        validate_items(mf.items("ardupilot"))
    yaw = [MissionItem(0, 3, 16, current=1, param4=math.nan, x=473977420, y=85455940, z=20.0)]
    validate_items(yaw)  # NaN yaw: "use the current heading mode"
    validate_items([MissionItem(0, 3, 22, current=1, param4=math.nan, x=473977420, y=85455940, z=20.0)])
    for field in ("param1", "param2"):  # hold time, acceptance radius: NaN means nothing
        bad = [MissionItem(0, 3, 16, current=1, x=473977420, y=85455940, z=20.0, **{field: math.nan})]
        with pytest.raises(MissionValidationError, match=field):
            validate_items(bad)


def test_nan_speed_wpl_upload_sends_nothing(tmp_path, capsys):
    path = _wpl(tmp_path, "1\t0\t3\t178\t1\tnan\t-1\t0\t0\t0\t0\t1\n")
    argv = ["upload", "--connect", "udpout:127.0.0.1:9", "--sysid", "1", "--heartbeat-timeout", "0.2"]
    _fails([*argv, str(path)], capsys, "param2", "nan")


@pytest.mark.parametrize("command", [5001, 5002, 5003, 5004, 5100])
def test_fence_or_rally_row_in_a_mission_wpl_is_refused(tmp_path, capsys, command):
    path = _wpl(
        tmp_path,
        "1\t0\t3\t16\t0\t0\t0\t0\t47.39\t8.54\t20\t1\n",
        f"2\t0\t3\t{command}\t4\t0\t0\t0\t47.39\t8.54\t0\t1\n",
    )
    with pytest.raises(MissionFileError, match=f"line 4: command {command}"):
        load_mission_file(path)
    _fails(["convert", str(path), str(tmp_path / "o.plan")], capsys, "line 4", str(command))
    bad = [MissionItem(0, 3, 16, current=1, x=1, y=1, z=20.0), MissionItem(1, 0, command, param1=4, x=1, y=1)]
    with pytest.raises(MissionValidationError, match="fence / rally"):
        validate_items(bad)


@pytest.mark.parametrize("z", [99_999.0, -20_000.0, 10_000.5])
def test_relative_altitudes_beyond_10_km_are_refused(z):
    for command in (22, 16):
        with pytest.raises(MissionValidationError, match="field z"):
            validate_items([MissionItem(0, 3, command, current=1, x=473977420, y=85455940, z=z)])
    validate_items([MissionItem(0, 3, 22, current=1, x=473977420, y=85455940, z=9_999.0)])


def test_infinite_values_are_not_written_to_a_mission_file(tmp_path):
    items = [MissionItem(0, 3, 16, current=1, param1=math.inf, x=473977420, y=85455940, z=20.0)]
    for name in ("x.plan", "x.waypoints"):
        with pytest.raises(MissionFileError, match="param1 = inf"):
            save_mission_file(tmp_path / name, MissionFile.from_items(items, "px4"))
        assert not (tmp_path / name).exists()


@pytest.fixture(scope="module")
def fleet():
    sitl_mock = pytest.importorskip("sitl_mock")
    with sitl_mock.MockFleet(vehicles=[{"profile": "px4"}], home=ORIGIN, speedup=20.0) as f:
        yield f


def _url(fleet):
    host, port = fleet.vehicle(1).address
    return f"udpout:{host}:{port}"


def _store(fleet, items):
    def put():
        fleet.vehicle(1).mission_server._lists[0] = list(items)

    fleet.call(put)


def test_download_of_infinite_params_is_one_line_and_no_file(fleet, tmp_path, capsys):
    _store(fleet, [MissionItem(0, 6, 16, current=1, param1=math.inf, x=473977420, y=85455940, z=20.0)])
    out = tmp_path / "x.plan"
    _fails(["download", "--connect", _url(fleet), "--sysid", "1", str(out)], capsys, "param1 = inf")
    assert not out.exists()


def test_download_into_a_closed_pipe_writes_the_file_and_ends_quietly(fleet, tmp_path):
    _store(fleet, [MissionItem(i, 6, 16, current=int(i == 0), x=473977420 + i, y=1, z=2.0) for i in range(5)])
    out = tmp_path / "back.plan"
    read_end, write_end = os.pipe()
    os.close(read_end)  # `| head` that has already gone
    try:
        proc = subprocess.run(
            [sys.executable, "-m", "gcs_planner.cli", "download", "--connect", _url(fleet), "--sysid", "1",
             str(out)],
            stdout=write_end, stderr=subprocess.PIPE, text=True, timeout=60,
        )  # fmt: skip
    finally:
        os.close(write_end)
    assert "Traceback" not in proc.stderr and "BrokenPipe" not in proc.stderr, proc.stderr
    assert proc.returncode == 141 and proc.stderr == ""
    assert len(load_mission_file(out).mission) == 5


def test_a_user_error_logged_on_its_way_leaves_no_traceback():
    """A link subscriber that hits a duplicate sysid logs it; the CLI's one error line is enough."""
    import io
    import logging

    from gcs_planner.cli import one_line_logs
    from gcs_planner.mavlink.errors import DuplicateSysidError

    stream = io.StringIO()
    handler = logging.StreamHandler(stream)
    handler.addFilter(one_line_logs)
    log = logging.getLogger("gcs_planner.test_one_line")
    log.addHandler(handler)
    log.propagate = False
    try:
        for exc in (DuplicateSysidError(1, [("127.0.0.1", 1), ("127.0.0.1", 2)]), RuntimeError("boom\nmore")):
            try:
                raise exc
            except Exception:
                log.exception("MAVLink subscriber failed")
        log.warning("plain %d", 1)
    finally:
        log.removeHandler(handler)
    assert stream.getvalue().splitlines() == [
        "MAVLink subscriber failed: RuntimeError: boom (-v: traceback)",
        "plain 1",
    ]
