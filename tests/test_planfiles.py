"""QGroundControl .plan and QGC WPL 110 files: exact round trips, pymavlink mavwp interop, errors."""

from __future__ import annotations

import json
import math
import os
from dataclasses import replace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavwp  # noqa: E402
from pymavlink.dialects.v20 import ardupilotmega as mavlink  # noqa: E402

from gcs_planner.core.geo import Origin  # noqa: E402
from gcs_planner.missions.files import (  # noqa: E402
    MissionFile,
    MissionFileError,
    in_file_frames,
    load_mission_file,
    plan_mission_file,
    save_mission_file,
)
from gcs_planner.missions.items import plan_to_items, scenario_fence_items, scenario_rally_items  # noqa: E402
from gcs_planner.missions.planfile import dumps_plan, loads_plan, plan_losses  # noqa: E402
from gcs_planner.missions.wpl import dumps_wpl, loads_wpl, loads_wpl_items, wpl_losses  # noqa: E402
from gcs_planner.model.plan import VehiclePlan  # noqa: E402
from gcs_planner.model.scenario import parse_scenario  # noqa: E402
from gcs_planner.wire.types import MissionItem, MissionType  # noqa: E402

ORIGIN = Origin(-33.8567844, 151.2152967, 12.5)  # southern/eastern hemisphere: negative latitudes
SCENARIO = {
    "origin": {"lat_deg": ORIGIN.lat_deg, "lon_deg": ORIGIN.lon_deg, "alt_m": ORIGIN.alt_m},
    "planner": {"name": "straight"},
    "vehicles": [{"id": "a", "sysid": 1, "start": [0.0, 0.0, 0.0], "goal": [100.0, 0.0, 20.0]}],
    "obstacles": {"cylinders": [{"x": 50.0, "y": 10.0, "radius_m": 8.0}]},
    "bounds": {"x": [-100.0, 400.0], "y": [-200.0, 300.0]},
}


def vehicle_plan(**kw) -> VehiclePlan:
    rng = np.random.default_rng(7)
    wps = np.cumsum(rng.uniform(-80, 80, size=(12, 3)), axis=0) + [0, 0, 60]
    wps[0, 2] = 0.0
    speeds = rng.uniform(5, 15, size=12).round(1)
    seg = np.linalg.norm(np.diff(wps, axis=0), axis=1)
    times = np.concatenate([[0.0], np.cumsum(seg / speeds[1:])])
    args = dict(
        vehicle_id="v", sysid=3, waypoints=wps, times_s=times, speeds_mps=speeds, path=wps, path_times_s=times
    )
    return VehiclePlan(**{**args, **kw})


@pytest.mark.parametrize("autopilot", ["ardupilot", "px4"])
def test_wpl_round_trip_is_exact(autopilot):
    items = plan_to_items(vehicle_plan(takeoff_delay_s=3.25), ORIGIN, autopilot)
    text = dumps_wpl(items)
    assert text.startswith("QGC WPL 110\n") and "\t" in text
    assert loads_wpl_items(text) == items
    assert dumps_wpl(loads_wpl_items(text)) == text
    # row 0 is the planned home for every autopilot (QGC): a PX4 list is written after a home row
    rows = items if autopilot == "ardupilot" else [MissionItem(0, 0, 16), *items]
    assert (
        loads_wpl(dumps_wpl(rows), autopilot=autopilot).items(autopilot)[
            1 if autopilot == "ardupilot" else 0 :
        ]
        == [replace(it, seq=it.seq, current=it.current) for it in items][
            1 if autopilot == "ardupilot" else 0 :
        ]
    )


def test_wpl_keeps_odd_values():
    items = [
        MissionItem(0, 0, 16, 1, 1, x=-899_999_999, y=1_799_999_999, z=1.0),
        MissionItem(1, 6, 16, 0, 0, 0.1, math.nan, -0.0, 1e-9, x=-1, y=5, z=-3.5),
        MissionItem(2, mavlink.MAV_FRAME_LOCAL_NED, 16, 0, 1, x=-123456, y=7, z=2.0),
        MissionItem(3, 11, 16, 0, 1, x=10, y=-10, z=0.3),
    ]
    back = loads_wpl_items(dumps_wpl(items))
    assert back[0] == items[0] and back[2:] == items[2:]
    # NaN is written as 0 (Mission Planner reads no 'nan', QGC no 'NaN'), and the writer says so
    assert back[1] == replace(items[1], param2=0.0)
    (loss,) = wpl_losses(MissionFile.from_items(items))
    assert loss.fields == ("param2",) and loss.indexes == (0,) and "written as 0" in str(loss)


def test_our_wpl_loads_in_pymavlink_mavwp(tmp_path):
    mf = plan_mission_file(vehicle_plan(), ORIGIN, "ardupilot")
    items = mf.items("ardupilot")
    path = tmp_path / "m.waypoints"
    assert [loss.part for loss in save_mission_file(path, mf)] == ["settings"]  # speeds: .plan only
    loader = mavwp.MAVWPLoader()
    assert loader.load(str(path)) == len(items)
    for ours, theirs in zip(items, loader.wpoints, strict=True):
        assert (theirs.seq, theirs.command, theirs.current, theirs.autocontinue) == (
            ours.seq,
            ours.command,
            ours.current,
            ours.autocontinue,
        )
        assert theirs.frame == ours.frame and ours.frame in (0, 2, 3)  # the numbers files use
        assert round(theirs.x * 1e7) == ours.x and round(theirs.y * 1e7) == ours.y
        assert (theirs.z, theirs.param1, theirs.param2, theirs.param3) == (
            ours.z,
            ours.param1,
            ours.param2,
            ours.param3,
        )


def test_mavwp_written_wpl_loads_in_ours(tmp_path):
    loader = mavwp.MAVWPLoader()
    rows = [(0, 16, 1, -33.856784, 151.215297, 12.5), (3, 22, 0, -33.856784, 151.215297, 30.0)]
    rows += [(3, 16, 0, -33.8567 - i * 1e-4, 151.2153 + i * 2e-4, 40.0 + i) for i in range(5)]
    rows += [(3, 21, 0, -33.857, 151.216, 0.0)]
    for seq, (frame, cmd, cur, lat, lon, alt) in enumerate(rows):
        loader.add(
            mavlink.MAVLink_mission_item_message(
                1, 1, seq, frame, cmd, cur, 1, 0, 2.0, 0, 0, lat, lon, alt, 0
            )
        )
    path = tmp_path / "mavwp.txt"
    loader.save(str(path))
    mf = load_mission_file(path)
    items = mf.items("ardupilot")
    assert len(items) == len(rows)
    assert mf.home == pytest.approx((-33.856784, 151.215297, 12.5))
    for it, (frame, cmd, cur, lat, lon, alt) in zip(items, rows, strict=True):
        assert it.command == cmd and it.current == cur and it.z == alt and it.param2 == 2.0
        assert it.frame == frame  # as written
        assert it.x == round(lat * 1e7) and it.y == round(lon * 1e7)


def test_plan_round_trip_with_fence_rally_and_nan():
    sc = parse_scenario(SCENARIO)
    mission = plan_to_items(vehicle_plan(final_action="loiter"), ORIGIN, "ardupilot")
    mission[4] = replace(mission[4], param4=math.nan)  # QGC stores NaN params as null
    fence = scenario_fence_items(sc)
    fence = [replace(fence[0], command=mavlink.MAV_CMD_NAV_FENCE_RETURN_POINT, param1=0.0, z=25.0)] + [
        it.with_seq(i + 1) for i, it in enumerate(fence)
    ]
    fence = [*fence[1:], replace(fence[0], frame=3, autocontinue=0)]  # QGC's order and frames
    fence = [replace(it, seq=i, autocontinue=0) for i, it in enumerate(fence)]
    rally = [replace(it, frame=3, autocontinue=0) for it in scenario_rally_items(sc)]
    mf = MissionFile.from_items(in_file_frames(mission), "ardupilot", fence=fence, rally=rally)
    assert plan_losses(mf) == []
    text = dumps_plan(mf)
    doc = json.loads(text)
    assert doc["fileType"] == "Plan" and doc["mission"]["version"] == 2
    assert doc["mission"]["plannedHomePosition"] == [ORIGIN.lat_deg, ORIGIN.lon_deg, ORIGIN.alt_m]
    assert doc["mission"]["items"][3]["params"][3] is None
    assert len(doc["geoFence"]["polygons"]) == 1 and len(doc["geoFence"]["circles"]) == 1
    assert doc["geoFence"]["circles"][0]["inclusion"] is False
    back = loads_plan(text)
    assert back.fence == fence and back.rally == mf.rally
    got = back.items("ardupilot")
    assert math.isnan(got[4].param4)
    assert [replace(it, param4=0.0) for it in got] == [
        replace(it, param4=0.0) for it in in_file_frames(mission)
    ]
    assert dumps_plan(back) == text


def test_plan_mission_file_and_save_load_both_formats(tmp_path):
    vp = vehicle_plan()
    mf = plan_mission_file(vp, ORIGIN, "px4")
    expected = in_file_frames(plan_to_items(vp, ORIGIN, "px4"))
    for name in ("m.plan", "m.waypoints"):
        losses = save_mission_file(tmp_path / name, mf)
        assert [loss.part for loss in losses] == ([] if name == "m.plan" else ["settings"])
        assert load_mission_file(tmp_path / name, autopilot="px4").items("px4") == expected


QGC_SURVEY = {
    "fileType": "Plan",
    "version": 1,
    "groundStation": "QGroundControl",
    "geoFence": {"circles": [], "polygons": [], "version": 2},
    "rallyPoints": {"points": [], "version": 2},
    "mission": {
        "cruiseSpeed": 15,
        "firmwareType": 12,
        "hoverSpeed": 5,
        "plannedHomePosition": [47.3977419, 8.5455938, 488.1],
        "vehicleType": 2,
        "version": 2,
        "items": [
            {
                "AMSLAltAboveTerrain": None,
                "Altitude": 50,
                "AltitudeMode": 1,
                "autoContinue": True,
                "command": 22,
                "doJumpId": 1,
                "frame": 3,
                "params": [0, 0, 0, None, 47.3979, 8.5457, 50],
                "type": "SimpleItem",
            },
            {
                "complexItemType": "survey",
                "type": "ComplexItem",
                "version": 5,
                "TransectStyleComplexItem": {
                    "Items": [
                        {
                            "autoContinue": True,
                            "command": 16,
                            "doJumpId": 2 + k,
                            "frame": 3,
                            "params": [0, 0, 0, None, 47.398 + k * 1e-4, 8.546, 50],
                            "type": "SimpleItem",
                        }
                        for k in range(3)
                    ],
                    "CameraCalc": {},
                },
            },
            {
                "autoContinue": True,
                "command": 20,
                "doJumpId": 5,
                "frame": 2,
                "params": [0, 0, 0, 0, 0, 0, 0],
                "type": "SimpleItem",
            },
        ],
    },
}


def test_qgc_plan_with_survey_complex_item():
    mf = loads_plan(json.dumps(QGC_SURVEY))
    items = mf.items("px4")
    assert [it.command for it in items] == [22, 16, 16, 16, 20]
    assert [it.seq for it in items] == [0, 1, 2, 3, 4] and items[0].current == 1
    assert items[1].x == 473980000 and items[3].x == 473982000 and items[1].frame == 3
    assert math.isnan(items[0].param4)
    assert mf.firmware_type == 12 and mf.home == (47.3977419, 8.5455938, 488.1)
    ap = mf.items("ardupilot")
    assert ap[0].x == 473977419 and ap[0].z == 488.1 and len(ap) == 6


@pytest.mark.parametrize(
    ("mutate", "message"),
    [
        (lambda d: d.update(fileType="Mission"), "fileType"),
        (lambda d: d["mission"]["items"][0].update(command="22"), r"mission.items\[0\].command"),
        (lambda d: d["mission"]["items"][0]["params"].__setitem__(4, None), "latitude"),
        (lambda d: d["mission"]["items"][0]["params"].pop(), r"mission.items\[0\].params"),
        (lambda d: d["mission"]["items"][1].pop("TransectStyleComplexItem"), "ComplexItem 'survey'"),
        (lambda d: d["mission"]["items"][2].update(type="Bogus"), r"mission.items\[2\]: type"),
        (lambda d: d["geoFence"]["polygons"].append({"polygon": [[1, 2]]}), r"geoFence.polygons\[0\]"),
        (lambda d: d["rallyPoints"]["points"].append([1, 2]), r"rallyPoints.points\[0\]"),
    ],
)
def test_bad_plan_files_name_the_place(mutate, message):
    doc = json.loads(json.dumps(QGC_SURVEY))
    mutate(doc)
    with pytest.raises(MissionFileError, match=message):
        loads_plan(json.dumps(doc), where="x.plan")


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("QGC WPL 100\n", "line 1"),
        ("QGC WPL 110\n0\t1\t0\t16\t0\t0\t0\t0\t1\t2\t3\n", "line 2: expected 12"),
        ("QGC WPL 110\n# c\n0\t1\t0\tWP\t0\t0\t0\t0\t1\t2\t3\t1\n", "line 3: field command"),
        ("QGC WPL 110\n0\t1\t0\t16\t0\t0\t0\tx\t1\t2\t3\t1\n", "field param4"),
    ],
)
def test_bad_wpl_files(text, message):
    with pytest.raises(MissionFileError, match=message):
        loads_wpl_items(text)


def test_wpl_fence_and_rally_types_are_inferred():
    sc = parse_scenario(SCENARIO)
    fence = loads_wpl(dumps_wpl(scenario_fence_items(sc)))
    assert fence.mission == [] and fence.fence == scenario_fence_items(sc)
    rally = loads_wpl(dumps_wpl(scenario_rally_items(sc)))
    assert rally.rally == scenario_rally_items(sc) and rally.rally[0].mission_type == MissionType.RALLY


def test_load_mission_file_errors(tmp_path):
    with pytest.raises(MissionFileError, match="no such file"):
        load_mission_file(tmp_path / "missing.plan")
    (tmp_path / "x.txt").write_text("hello")
    with pytest.raises(MissionFileError, match="neither"):
        load_mission_file(tmp_path / "x.txt")
    # no planned home: ArduPilot gets a home row at 0, 0 (it puts its own home there)
    assert MissionFile(mission=[]).items("ardupilot") == [MissionItem(0, 0, 16, current=1)]


finite = st.floats(allow_nan=False, allow_infinity=False, width=32)


@settings(max_examples=60, deadline=None)
@given(
    st.lists(
        st.tuples(
            st.integers(-900_000_000, 900_000_000),
            st.integers(-1_800_000_000, 1_800_000_000),
            finite,
            finite,
            finite,
            st.sampled_from([0, 2, 3, 5, 6, 10, 11]),  # every frame is kept as written
        ),
        min_size=1,
        max_size=8,
    )
)
def test_wpl_and_plan_round_trip_any_items(rows):
    items = [
        MissionItem(i, frame, 16, int(i == 0), 1, p1, p2, 0.0, 0.0, x=x, y=y, z=z)
        for i, (x, y, p1, p2, z, frame) in enumerate(rows)
    ]
    assert loads_wpl_items(dumps_wpl(items)) == items
    mf = MissionFile.from_items(items, "px4", home=(1.0, 2.0, 3.0))
    assert loads_plan(dumps_plan(mf)).items("px4") == items
