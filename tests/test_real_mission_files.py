"""Mission files as QGroundControl, Mission Planner and MAVProxy write them (issue 13, failures 1-11):
read without refusal, written back exactly or with a warning naming what the format cannot carry,
and uploaded list by list as the file says."""

from __future__ import annotations

import json
import math
from dataclasses import replace

import pytest

from gcs_planner.cli import main
from gcs_planner.core.geo import Origin
from gcs_planner.missions.files import MissionFile, load_mission_file, save_mission_file
from gcs_planner.missions.planfile import dumps_plan, loads_plan, plan_losses
from gcs_planner.missions.wpl import dumps_mission_file, loads_wpl, wpl_losses
from gcs_planner.wire.types import MissionItem, MissionType

ORIGIN = Origin(47.397742, 8.545594, 488.0)


def plan_doc(items, fence=None, rally=None, home=(47.3977, 8.5456, 488.0)) -> str:
    return json.dumps(
        {
            "fileType": "Plan",
            "version": 1,
            "groundStation": "QGroundControl",
            "mission": {
                "version": 2,
                "firmwareType": 12,
                "vehicleType": 2,
                "cruiseSpeed": 15,
                "hoverSpeed": 5,
                "plannedHomePosition": list(home),
                "items": items,
            },  # fmt: skip
            "geoFence": fence or {"version": 2, "polygons": [], "circles": []},
            "rallyPoints": rally or {"version": 2, "points": []},
        }
    )


def simple(command, params, frame=3, jump_id=1, **extra) -> dict:
    item = {"type": "SimpleItem", "autoContinue": True, "command": command, "doJumpId": jump_id}
    return {**item, "frame": frame, "params": params, **extra}


def wpl(*rows: str, header: str = "QGC WPL 110") -> str:
    return "\n".join([header, *(r if r.startswith("#") else "\t".join(r.split()) for r in rows)]) + "\n"


HOME_ROW = "0 1 0 16 0 0 0 0 47.3977420 8.5455940 488.0 1"


# 1. null params
def test_qgc_null_params_read_as_nan_and_null_position_params_as_zero():
    camera_mode = simple(530, [0, 1, None, None, None, None, None], frame=2, jump_id=2)  # QGC survey start
    mf = loads_plan(plan_doc([simple(22, [0, 0, 0, None, 47.398, 8.546, 30]), camera_mode]))
    item = mf.mission[1]
    assert (item.command, item.x, item.y, item.z) == (530, 0, 0, 0.0)
    assert math.isnan(item.param3) and math.isnan(item.param4) and math.isnan(mf.mission[0].param4)
    assert any("params 5/6 null" in note for note in mf.notes)
    back = loads_plan(dumps_plan(mf))
    assert json.loads(dumps_plan(mf))["mission"]["items"][1]["params"][2] is None  # NaN -> null again
    assert back.mission[1].x == 0 and math.isnan(back.mission[1].param4)


# 2. null altitude of a "calculated above terrain" waypoint
def test_calculated_above_terrain_waypoint_is_the_terrain_frame_until_qgc_computed_it():
    waiting = simple(16, [0, 0, 0, None, 47.37, 8.58, None], frame=0, jump_id=2,
                     AltitudeMode=3, Altitude=80, AMSLAltAboveTerrain=None)  # fmt: skip
    computed = simple(16, [0, 0, 0, None, 47.37, 8.59, None], frame=0, jump_id=3,
                      AltitudeMode=3, Altitude=80, AMSLAltAboveTerrain=612.5)  # fmt: skip
    mf = loads_plan(plan_doc([simple(22, [0, 0, 0, None, 47.37, 8.58, 30]), waiting, computed]))
    assert (mf.mission[1].frame, mf.mission[1].z) == (10, 80.0)  # MAV_FRAME_GLOBAL_TERRAIN_ALT, 80 m AGL
    assert (mf.mission[2].frame, mf.mission[2].z) == (0, 612.5)  # QGC's AMSL value, as QGC uploads it
    assert any("calculated above terrain" in note for note in mf.notes)
    with pytest.raises(ValueError, match=r"params\[6\] \(altitude\) must be a number"):
        loads_plan(plan_doc([simple(16, [0, 0, 0, 0, 47.37, 8.58, None])]))


# 3. older QGC formats
def test_qgc_coordinate_items_and_the_old_mission_file_load():
    section = simple(22, [0, 0, 0, None], coordinate=[47.633, -122.09, 20])  # SectionTest.plan's items
    mf = loads_plan(plan_doc([section, simple(205, [0, 0, 0, 0], frame=2, jump_id=2, coordinate=[0, 0, 2])]))
    assert (mf.mission[0].x, mf.mission[0].y, mf.mission[0].z) == (476330000, -1220900000, 20.0)
    assert (mf.mission[1].command, mf.mission[1].z) == (205, 2.0)
    old = {"firmwareType": 3, "groundStation": "QGroundControl", "version": 2,
           "plannedHomePosition": [47.66, -122.29, 0],
           "items": [{"type": "SimpleItem", "autoContinue": True, "command": 22, "doJumpId": 1, "frame": 3,
                      "coordinate": [47.6601, -122.2941, 50], "params": [0, 0, 0, 0]}]}  # fmt: skip
    mf = loads_plan(json.dumps(old))
    assert mf.home == (47.66, -122.29, 0.0) and mf.mission[0].z == 50.0
    assert mf.lists == {MissionType.MISSION}  # a .mission file says nothing about fence or rally
    v1 = {**old, "version": 1, "plannedHomePosition": {"coordinate": [47.66, -122.29, 10]},
          "items": [{"type": "missionItem", "command": 16, "frame": 3, "autoContinue": True, "param1": 2,
                     "param2": 0, "param3": 0, "param4": 0, "coordinate": [47.66, -122.29, 50]}]}  # fmt: skip
    mf = loads_plan(json.dumps(v1))
    assert mf.home == (47.66, -122.29, 10.0) and mf.mission[0].param1 == 2.0


# 4. positionless commands: params 5/6 are plain numbers
def test_positionless_params_5_6_are_not_scaled():
    mf = loads_wpl(wpl(HOME_ROW, "1 0 0 203 1 0 0 0 39 1 0 1"))  # DO_DIGICAM_CONTROL, x = 39, y = 1
    (item,) = mf.mission
    assert (item.x, item.y) == (39, 1)
    assert "\t39.0\t1.0\t" in dumps_mission_file(mf)
    assert json.loads(dumps_plan(mf))["mission"]["items"][0]["params"][4:6] == [39, 1]


# 5. local frames: metres in both formats
def test_local_frame_positions_are_metres_in_plan_and_wpl():
    mf = loads_wpl(wpl(HOME_ROW, "1 0 21 16 0 0 0 0 10.0 -2.5 3 1"))  # MAV_FRAME_LOCAL_FLU
    assert (mf.mission[0].x, mf.mission[0].y) == (100000, -25000)  # MISSION_ITEM_INT: metres x 1e4
    doc = json.loads(dumps_plan(mf))
    assert doc["mission"]["items"][0]["params"][4:6] == [10.0, -2.5]
    assert loads_plan(dumps_plan(mf)).mission == mf.mission


# 6. frames as written; the WPL home row's own fields
def test_frames_are_kept_and_a_home_row_a_plan_cannot_hold_is_named():
    text = wpl("0 1 3 22 15 0 0 0 47.3977420 8.5455940 5.0 1", "1 0 5 16 0 0 0 0 47.3980000 8.5460000 500 1")
    mf = loads_wpl(text)
    assert mf.mission[0].frame == 5 and mf.home_item.frame == 3
    back = loads_wpl(dumps_mission_file(mf))
    assert (back.mission, back.home_item, back.home) == (mf.mission, mf.home_item, mf.home)
    losses = plan_losses(mf)
    assert [(loss.part, loss.fields) for loss in losses] == [("home", ("frame", "command", "param1"))]
    assert "of the WPL home row are not carried by a .plan" in str(losses[0])


# 7. fence and rally from WPL into a .plan
def test_fence_and_rally_fields_a_plan_cannot_hold_are_named():
    fence = wpl(
        "0 0 3 5001 4 7 0 0 -35.36 149.16 100 0",
        "1 0 3 5001 4 0 0 0 -35.37 149.16 100 0",
        "2 0 3 5001 4 0 0 0 -35.37 149.17 100 0",
        "3 0 3 5001 4 0 0 0 -35.36 149.17 100 0",
        "4 0 0 5005 50 0 0 0 0 0 0 0",  # NAV_FENCE_HOME_CIRCLE_INCLUSION
    )
    mf = loads_wpl(fence)
    assert len(mf.fence) == 5 and not mf.mission and mf.lists == {MissionType.FENCE}
    lines = [str(loss) for loss in plan_losses(mf)]
    assert "fence items 0-3: frame not carried by a .plan (reads back as 0)" in lines
    assert "fence items 0-3: z not carried by a .plan (reads back as 0.0)" in lines
    assert "fence item 0: param2 not carried by a .plan (reads back as 0.0)" in lines
    assert any(line.startswith("fence item 4: every field not written") for line in lines)
    rally = loads_wpl(wpl("0 0 0 5100 8 0 0 0 40.07 -105.23 0 0", "1 0 0 5100 8 0 0 0 40.08 -105.23 0 1"))
    lines = [str(loss) for loss in plan_losses(rally)]
    assert "rally items 0-1: frame not carried by a .plan (reads back as 3)" in lines  # AMSL -> relative
    assert "rally item 1: autocontinue not carried by a .plan (reads back as 0)" in lines


# 8. no home
def test_a_file_without_home_round_trips_without_inventing_one(tmp_path):
    mf = loads_plan(plan_doc([simple(22, [0, 0, 0, 0, 47.37, 8.58, 30])], home=(0, 0, 0)))
    assert mf.home is None
    for name in ("a.plan", "a.waypoints"):
        save_mission_file(tmp_path / name, mf)
        back = load_mission_file(tmp_path / name)
        assert back.home is None and back.mission == mf.mission


# 10. commands the pinned dialect lacks
def test_unknown_commands_pass_through_with_a_note():
    mf = loads_wpl(
        wpl(HOME_ROW, "1 0 3 116 0 0 0 0 -35.362364 149.165237 20 1", "2 0 0 219 120 1 0 0 0 0 0 1")
    )
    assert [it.command for it in mf.mission] == [116, 219]
    assert mf.mission[0].x == -353623640  # an unknown command's x/y are a position (MAVLink's default)
    assert len(mf.notes) == 2 and "command 116 is not in the MAVLink dialect" in mf.notes[0]


# 11. comments and NaN in WPL
def test_wpl_comments_stay_in_place_and_nan_is_written_as_zero_with_a_warning():
    text = wpl("# written by hand", HOME_ROW, "# the climb", "1 0 3 22 0 0 0 nan 47.3980 8.5460 30 1")
    mf = loads_wpl(text)
    assert math.isnan(mf.mission[0].param4)
    out = dumps_mission_file(mf)
    assert out.splitlines()[1] == "# written by hand" and out.splitlines()[3] == "# the climb"
    assert "nan" not in out.lower() and out.splitlines()[4].split("\t")[7] == "0.0"
    (loss,) = wpl_losses(mf)
    assert "NaN (use the default) written as 0" in str(loss)
    assert [loss.part for loss in plan_losses(mf)] == ["comments"]


def test_qgc_wpl_120_has_no_home_row_and_jumps_one_lower():
    mf = loads_wpl(wpl("0 1 3 22 0 0 0 0 47.398 8.546 30 1", "1 0 2 177 0 3 0 0 0 0 0 1",
                       header="QGC WPL 120"))  # fmt: skip
    assert mf.home is None and [it.command for it in mf.mission] == [22, 177]
    assert mf.mission[1].param1 == 1.0  # 0-based in 120; item 1 of an ArduPilot list (home = 0)


def test_mission_planner_fence_file_with_a_home_row():
    mf = loads_wpl(wpl(HOME_ROW, *(f"{i} 0 0 5001 3 0 0 0 -35.3{i} 149.1{i} 0 1" for i in (1, 2, 3))))
    assert not mf.mission and len(mf.fence) == 3 and mf.lists == {MissionType.FENCE}
    assert mf.home_item is not None and dumps_mission_file(mf).splitlines()[1].split("\t")[3] == "16"


# 9. DO_JUMP targets when PX4 gets no home item
def test_do_jump_targets_follow_the_dropped_home_item():
    rows = [HOME_ROW, "1 0 3 22 0 0 0 0 47.398 8.546 30 1", "2 0 3 16 0 0 0 0 47.399 8.546 30 1",
            "3 0 0 177 2 3 0 0 0 0 0 1"]  # fmt: skip
    mf = loads_wpl(wpl(*rows))
    assert mf.items("ardupilot")[3].param1 == 2.0  # seq 2: the waypoint
    px4 = mf.items("px4")
    assert px4[2].param1 == 1.0 and px4[1].command == 16  # seq 1 on PX4
    assert px4[2].frame == 2  # PX4 takes positionless commands in MAV_FRAME_MISSION only
    downloaded = MissionFile.from_items(px4, "px4").mission
    assert downloaded == [*mf.mission[:2], replace(mf.mission[2], frame=2)]
    doc = json.loads(dumps_plan(mf))  # QGC: param1 is the target's doJumpId
    target = doc["mission"]["items"][2]["params"][0]
    assert [it["doJumpId"] for it in doc["mission"]["items"]][1] == target


@pytest.fixture(scope="module")
def fleet():
    sitl_mock = pytest.importorskip("sitl_mock")
    with sitl_mock.MockFleet(vehicles=[{"profile": "ardupilot"}, {"profile": "px4"}], home=ORIGIN) as f:
        yield f


def held(fleet, sysid: int, mission_type: int) -> list[MissionItem]:
    return fleet.call(lambda: fleet.vehicle(sysid).mission_server.items(mission_type))


MISSION = wpl(HOME_ROW, "1 0 3 22 0 0 0 0 47.3980 8.5460 30 1", "2 0 3 16 0 0 0 0 47.3990 8.5460 30 1",
              "3 0 3 21 0 0 0 0 47.3990 8.5460 0 1")  # fmt: skip
FENCE = wpl(*(f"{i} 0 0 5001 4 0 0 0 {lat} {lon} 0 0" for i, (lat, lon) in
              enumerate([(47.39, 8.54), (47.41, 8.54), (47.41, 8.56), (47.39, 8.56)])))  # fmt: skip


# 9. upload: the lists the file defines, list by list
@pytest.mark.parametrize("sysid", [1, 2])
def test_upload_sends_the_lists_the_file_defines(fleet, tmp_path, capsys, sysid):
    host, port = fleet.vehicle(sysid).address
    argv = ["upload", "--connect", f"udpout:{host}:{port}", "--sysid", str(sysid)]
    (tmp_path / "m.waypoints").write_text(MISSION)
    (tmp_path / "f.waypoints").write_text(FENCE)
    assert main([*argv, str(tmp_path / "m.waypoints")]) == 0
    mission = held(fleet, sysid, 0)
    assert main([*argv, str(tmp_path / "f.waypoints")]) == 0  # a fence-only file: the mission stays
    out = capsys.readouterr().out
    assert "note: mission: not in the file; the vehicle's list is kept" in out
    assert held(fleet, sysid, 0) == mission and len(held(fleet, sysid, 1)) == 4
    assert len(mission) == (4 if sysid == 1 else 3)  # PX4 gets no home row
    # a .plan defines all three lists: no fence in it clears the vehicle's fence (QGC's sendToVehicle)
    mf = load_mission_file(tmp_path / "m.waypoints")
    save_mission_file(tmp_path / "m.plan", mf)
    assert main([*argv, str(tmp_path / "m.plan")]) == 0
    assert held(fleet, sysid, 1) == [] and len(held(fleet, sysid, 0)) == len(mission)
    # --clear-absent clears what a WPL file does not define, as QGC would
    assert main([*argv, str(tmp_path / "f.waypoints")]) == 0 and len(held(fleet, sysid, 1)) == 4
    assert main([*argv, "--clear-absent", str(tmp_path / "m.waypoints")]) == 0
    assert held(fleet, sysid, 1) == [] and len(held(fleet, sysid, 0)) == len(mission)


def test_start_uploads_the_file_lists_first(fleet, tmp_path, capsys):
    host, port = fleet.vehicle(1).address
    (tmp_path / "f.waypoints").write_text(FENCE)
    code = main(["start", "--connect", f"udpout:{host}:{port}", "--sysid", "1", "--no-arm",
                 str(tmp_path / "f.waypoints")])  # fmt: skip
    out = capsys.readouterr().out
    assert code in (0, 2) and "upload fence" in out and "upload mission" not in out
    assert len(held(fleet, 1, 1)) == 4


def test_convert_says_what_it_interpreted_and_what_the_target_drops(tmp_path, capsys):
    src = tmp_path / "in.waypoints"
    src.write_text(wpl("# survey", HOME_ROW, "1 0 3 16 0 0 0 nan 47.398 8.546 30 1"))
    assert main(["convert", str(src), str(tmp_path / "out.plan")]) == 0
    out = capsys.readouterr().out.splitlines()
    assert out[0] == "warning: comments: every line not carried by a .plan"
    (back,) = load_mission_file(tmp_path / "out.plan").mission
    (item,) = loads_wpl(src.read_text()).mission
    assert math.isnan(back.param4) and replace(back, param4=0.0) == replace(item, param4=0.0)
    assert main(["convert", str(tmp_path / "out.plan"), str(tmp_path / "back.txt")]) == 0
    assert "param4 NaN (use the default) written as 0" in capsys.readouterr().out
    assert main(["convert", str(tmp_path / "missing.plan"), str(tmp_path / "x.plan")]) == 2
    assert not (tmp_path / "x.plan").exists()
    assert "no such file" in capsys.readouterr().err
