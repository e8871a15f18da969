"""The autopilot registry (gcs_planner.autopilots): each family chosen from its HEARTBEAT, each
drives a vehicle its own way, and the docs' example family joins with one module."""

from __future__ import annotations

import asyncio
import re
from pathlib import Path

import pytest

from gcs_planner import autopilots
from gcs_planner.autopilots import ARDUCOPTER, ARDUPLANE, GENERIC, PX4, Conventions, quirks_for, quirks_named
from gcs_planner.wire.enums import Autopilot

DOC = Path(__file__).resolve().parents[1] / "docs" / "autopilots.md"


class RecordingPort:
    """A VehiclePort that writes down what a family asks of the vehicle."""

    def __init__(self, home_amsl_m: float = 488.0) -> None:
        self.calls: list[tuple] = []
        self.home = home_amsl_m

    async def set_param(self, name: str, value: float) -> float:
        self.calls.append(("param", name, value))
        return value

    async def set_mode(self, mode: str) -> None:
        self.calls.append(("mode", mode))

    async def arm_when_ready(self) -> None:
        self.calls.append(("arm",))

    async def takeoff(self, param7: float) -> None:
        self.calls.append(("takeoff", param7))

    def home_amsl_m(self) -> float:
        return self.home

    async def mission_start(self, first: int, last: int) -> None:
        self.calls.append(("start", first, last))

    async def set_current(self, seq: int) -> None:
        self.calls.append(("current", seq))


def _take_off(family, alt_m=20.0, climb_past_m=0.0, takeoff_dist_m=0.0) -> list[tuple]:
    port = RecordingPort()
    asyncio.run(family.take_off(port, alt_m, climb_past_m, takeoff_dist_m))
    return port.calls


def _start(family, first=2, last=9) -> list[tuple]:
    port = RecordingPort()
    asyncio.run(family.start_mission(port, first, last))
    return port.calls


@pytest.mark.parametrize(
    ("autopilot", "mav_type", "family"),
    [
        (Autopilot.ARDUPILOTMEGA, 2, ARDUCOPTER),  # quadrotor
        (Autopilot.ARDUPILOTMEGA, 13, ARDUCOPTER),  # hexarotor
        (Autopilot.ARDUPILOTMEGA, 1, ARDUPLANE),  # fixed wing
        (Autopilot.ARDUPILOTMEGA, 20, ARDUPLANE),  # a QuadPlane (VTOL quadrotor)
        (Autopilot.PX4, 2, PX4),
        (Autopilot.PX4, 1, PX4),
        (0, 2, GENERIC),  # MAV_AUTOPILOT_GENERIC (MAVSDK's servers)
        (None, None, GENERIC),  # not heard yet
    ],
)
def test_each_heartbeat_gets_its_family(autopilot, mav_type, family):
    assert quirks_for(autopilot, mav_type) is family


def test_the_fallback_is_asked_last_and_flags_name_a_family():
    assert autopilots.FAMILIES[-1] is GENERIC and GENERIC.matches(Autopilot.PX4, 2)  # matches any: last
    assert quirks_named("ardupilot") is ARDUCOPTER and quirks_named("ardupilot", fixed_wing=True) is ARDUPLANE
    assert quirks_named("px4") is PX4
    assert [f.conventions for f in (ARDUCOPTER, ARDUPLANE, PX4, GENERIC)] == [
        "ardupilot",
        "ardupilot",
        "px4",
        "px4",
    ]
    assert ARDUCOPTER.home_at_seq0 and not PX4.home_at_seq0 and Conventions.PX4 == "px4"


def test_each_family_takes_off_its_own_way():
    # ArduCopter: armed in GUIDED, NAV_TAKEOFF param7 in metres above home
    assert _take_off(ARDUCOPTER) == [("mode", "GUIDED"), ("arm",), ("takeoff", 20.0)]
    # PX4: armed as it is, NAV_TAKEOFF param7 in metres AMSL (home 488 m)
    assert _take_off(PX4) == [("arm",), ("takeoff", 508.0)]
    # ArduPlane: TAKEOFF mode climbs once armed, to TKOFF_ALT, straight until TKOFF_DIST
    assert _take_off(ARDUPLANE, 40.0, 5.0, 350.0) == [
        ("param", "TKOFF_ALT", 45.0), ("param", "TKOFF_DIST", 350.0), ("mode", "TAKEOFF"), ("arm",),
    ]  # fmt: skip
    assert ARDUPLANE.takeoff_level_off_m == 2.0 and ARDUCOPTER.takeoff_level_off_m == 0.0
    assert _take_off(GENERIC) == [("arm",), ("takeoff", 20.0)]


def test_modes_parameters_and_signing_as_each_family_has_them():
    assert PX4.mode_command_params(0x04030000) == (3.0, 4.0)  # main mode 3 (AUTO), sub mode 4 (MISSION)
    assert ARDUCOPTER.mode_command_params(4) == (4.0,)  # GUIDED
    assert PX4.params_bytewise and not ARDUCOPTER.params_bytewise and not GENERIC.params_bytewise
    stacks = (ARDUCOPTER.stack, ARDUPLANE.stack, PX4.stack, GENERIC.stack)
    assert stacks == ("ArduPilot", "ArduPilot", "PX4", "")
    assert "SERIAL0" in ARDUPLANE.signing_note and PX4.signing_note is None


def test_ardupilot_starts_at_the_current_item_the_rest_with_a_range():
    for family in (ARDUCOPTER, ARDUPLANE):
        assert _start(family) == [("current", 2), ("start", 0, 0)]  # ArduPilot denies other ranges
    for family in (PX4, GENERIC):
        assert _start(family) == [("start", 2, 9)]


def test_the_docs_example_family_joins_with_one_module(monkeypatch):
    code = re.search(r"```python\n(.*?)```", DOC.read_text(), re.S)[1]
    namespace: dict = {"__name__": "ardurover_example"}
    exec(compile(code, str(DOC), "exec"), namespace)
    rover = namespace["FAMILY"]
    monkeypatch.setattr(autopilots, "FAMILIES", (rover, *autopilots.FAMILIES))
    assert quirks_for(Autopilot.ARDUPILOTMEGA, 10) is rover
    assert quirks_for(Autopilot.ARDUPILOTMEGA, 2) is ARDUCOPTER  # the others keep theirs
    assert _take_off(rover) == [("mode", "GUIDED"), ("arm",)]  # a rover drives: no take-off
    assert _start(rover) == [("current", 2), ("start", 0, 0)]  # ArduPilot's start
    assert rover.modes["HOLD"] == 4 and rover.land_mode == "HOLD" and rover.conventions == "ardupilot"
