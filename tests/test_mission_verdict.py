"""A mission the autopilot refuses after its MISSION_ACK (PX4's feasibility check) is reported
REJECTED with the vehicle's own words, and `start` never leaves such a vehicle armed."""

from __future__ import annotations

import numpy as np
import pytest

from gcs_planner.cli import main
from gcs_planner.core.geo import Origin
from gcs_planner.mavlink.statustext import TextAssembler
from gcs_planner.missions.items import plan_to_items
from gcs_planner.missions.wpl import dumps_wpl
from gcs_planner.model.plan import VehiclePlan

sitl_mock = pytest.importorskip("sitl_mock")

ORIGIN = Origin(47.397742, 8.545594, 488.0)
TEXT = "Mission rejected: takeoff not first waypoint item"


@pytest.fixture(scope="module")
def fleet():
    with sitl_mock.MockFleet(vehicles=[{"profile": "px4"}], home=ORIGIN, speedup=20.0,
                             flight={"arm_ready_s": 0}) as f:  # fmt: skip
        yield f


def px4_items():
    wps = np.array([[0.0, 0.0, 0.0], [80.0, 0.0, 20.0], [160.0, 0.0, 25.0]])
    times = np.array([0.0, 8.0, 16.0])
    vp = VehiclePlan("a", 1, wps, times, np.array([0.0, 10.0, 10.0]), wps, times)
    return plan_to_items(vp, ORIGIN, "px4")


def argv(fleet):
    host, port = fleet.vehicle(1).address
    return ["--connect", f"udpout:{host}:{port}", "--sysid", "1", "--autopilot", "px4"]


def state(fleet):
    return fleet.call(lambda: fleet.vehicle(1).state)


def test_a_mission_refused_after_its_ack_is_rejected_and_start_does_not_arm(fleet, tmp_path, capsys):
    items = px4_items()
    waypoint_first = [items[2], *items]  # a waypoint before the NAV_TAKEOFF (row 0 is the home)
    bad = tmp_path / "bad.waypoints"
    bad.write_text(dumps_wpl([items[1], *waypoint_first]))
    assert main(["upload", *argv(fleet), str(bad)]) == 2
    captured = capsys.readouterr()
    assert "REJECTED" in captured.out and "ACCEPTED" not in captured.out
    assert TEXT in captured.err and captured.err.count("\n") == 1

    assert main(["start", *argv(fleet), str(bad)]) == 2
    captured = capsys.readouterr()
    assert "REJECTED" in captured.out and "arm" not in captured.out.split("REJECTED")[1]
    assert not state(fleet).armed

    # uploaded earlier, started now: the vehicle arms, refuses MISSION_START and is disarmed again
    assert main(["start", *argv(fleet)]) == 2
    err = capsys.readouterr().err
    assert "refused the mission start" in err and "disarmed it again" in err
    assert not state(fleet).armed

    good = tmp_path / "good.waypoints"
    good.write_text(dumps_wpl([items[1], *items]))
    assert main(["upload", *argv(fleet), str(good)]) == 0
    assert "ACCEPTED" in capsys.readouterr().out


class _Chunk:
    def __init__(self, text: str, text_id: int, seq: int, sysid: int = 1) -> None:
        self.text, self.id, self.chunk_seq, self._sysid = text, text_id, seq, sysid

    def get_srcSystem(self) -> int:  # noqa: N802 - pymavlink's name
        return self._sysid

    def get_srcComponent(self) -> int:  # noqa: N802
        return 1


def test_split_statustexts_are_whole_or_not_at_all():
    long = "Preflight Fail: " + "x" * 40 + " and the rest of it"
    chunks = [long[:50], long[50:]]
    texts = TextAssembler()
    assert texts.feed(_Chunk(chunks[0], 7, 0)) is None
    assert texts.feed(_Chunk(chunks[1], 7, 1)) == long
    assert texts.feed(_Chunk("t", 9, 1)) is None  # the tail of a text whose head was lost
    assert texts.feed(_Chunk("Armed", 0, 0)) == "Armed"


def test_arduplane_refuses_to_arm_with_do_land_start_unless_rtl_autoland(tmp_path, capsys):
    """Measured on ArduPlane SITL 4.8.0-dev: a mission with DO_LAND_START is refused at arming while
    RTL_AUTOLAND is 0, so the tool's fixed-wing routes carry none (they end with NAV_LAND)."""
    ready = {"arm_ready_s": 0, "position_fix_s": 0}
    with sitl_mock.MockFleet(count=1, profile="ardupilot", vehicle_type="fixed_wing", home=ORIGIN,
                             speedup=20.0, flight=ready) as plane:  # fmt: skip
        host, port = plane.vehicle(1).address
        argv = ["--connect", f"udpout:{host}:{port}", "--sysid", "1"]
        mission = tmp_path / "land_start.waypoints"
        mission.write_text(
            "QGC WPL 110\n0\t1\t0\t16\t0\t0\t0\t0\t47.397742\t8.545594\t488.0\t1\n"
            "1\t0\t3\t22\t15\t0\t0\t0\t47.397742\t8.545594\t50.0\t1\n"
            "2\t0\t3\t189\t0\t0\t0\t0\t47.398742\t8.545594\t50.0\t1\n"
            "3\t0\t3\t21\t0\t0\t0\t0\t47.400742\t8.545594\t0.0\t1\n"
        )
        assert main(["start", *argv, str(mission), "--arm-timeout", "1"]) == 2
        assert "DO_LAND_START set and RTL_AUTOLAND disable" in capsys.readouterr().err
        assert not plane.call(lambda: plane.vehicle(1).state.armed)


def test_a_fleet_start_disarms_the_vehicle_that_refuses_and_says_which_fly(tmp_path, capsys):
    items = px4_items()
    bad, good = tmp_path / "bad.waypoints", tmp_path / "good.waypoints"
    bad.write_text(dumps_wpl([items[1], items[2], *items]))  # a waypoint before the NAV_TAKEOFF
    good.write_text(dumps_wpl([items[1], *items]))
    with sitl_mock.MockFleet(
        count=2, profile="px4", home=ORIGIN, speedup=20.0, flight={"arm_ready_s": 0}
    ) as f:
        connects = [a for s in (1, 2) for a in ("--connect", "udpout:{}:{}".format(*f.vehicle(s).address))]
        assert main(["upload", *connects, "--sysid", "1", str(bad)]) == 2
        assert main(["upload", *connects, "--sysid", "2", str(good)]) == 0
        capsys.readouterr()
        assert main(["start", *connects, "--sysid", "1,2"]) == 2
        captured = capsys.readouterr()
        armed = [f.call(lambda s=s: f.vehicle(s).state.armed) for s in (1, 2)]
    rows = [line.split() for line in captured.out.splitlines() if line[:5].strip() in ("1", "2")]
    assert rows == [["1", "OK", "REFUSED"], ["2", "OK", "OK"]], captured.out
    last = captured.err.strip().splitlines()[-1]
    assert "1 of 2 vehicles refused the start; 2 fly their missions" in last and "disarmed it again" in last
    assert "Disarming" not in last, last  # its own words, not those of the disarm that followed
    assert armed == [False, True]
