"""Our enums equal MAVLink's (from pymavlink's dialect) and every mission result maps to one error."""

from __future__ import annotations

import pytest
from pymavlink.dialects.v20 import ardupilotmega as mavlink
from refusals import refused

from gcs_planner.core.errors import UserError
from gcs_planner.mavlink import errors
from gcs_planner.wire.enums import ARDUCOPTER_MODES, PX4_MODES, CommandResult, MissionResult, MissionState
from sitl_mock.profiles import PROFILES


def _mavlink_enum(name: str, prefix: str) -> dict[str, int]:
    return {
        e.name.removeprefix(prefix): value
        for value, e in mavlink.enums[name].items()
        if not e.name.endswith("_ENUM_END")
    }


def test_mission_result_covers_the_whole_mavlink_enum():
    assert {m.name: m.value for m in MissionResult} == _mavlink_enum("MAV_MISSION_RESULT", "MAV_MISSION_")


def test_mission_state_and_command_result_match_mavlink():
    assert {m.name: m.value for m in MissionState} == _mavlink_enum("MISSION_STATE", "MISSION_STATE_")
    # MAV_RESULT grew CANCELLED (6) and COMMAND_UNSUPPORTED_MAV_FRAME (9) after pymavlink 2.4.50's XML
    ours = {m.name: m.value for m in CommandResult}
    assert _mavlink_enum("MAV_RESULT", "MAV_RESULT_").items() <= ours.items()


def test_every_error_result_is_one_mission_error_that_says_what_it_means():
    assert set(errors.RESULT_TEXT) == set(MissionResult) - {MissionResult.ACCEPTED}
    for result, text in errors.RESULT_TEXT.items():
        exc = errors.error_for_result(result, sysid=4, mission_type=1, operation="upload")
        assert refused(exc, result) and isinstance(exc, UserError)
        assert str(exc) == f"vehicle 4 refused the fence upload: {result.name} ({text})"


def test_unknown_result_is_still_a_clear_error():
    exc = errors.error_for_result(99, sysid=2, mission_type=0, operation="download")
    assert type(exc) is errors.MissionError and "unknown MAV_MISSION_RESULT 99" in str(exc)


def test_mode_tables_round_trip_through_profiles():
    ardupilot, px4 = PROFILES["ardupilot"], PROFILES["px4"]
    assert ardupilot.custom_mode("auto") == ARDUCOPTER_MODES["AUTO"] == 3
    assert ardupilot.custom_mode("AUTO", "fixed_wing") == 10
    assert px4.custom_mode("AUTO") == PX4_MODES["AUTO"] == (4 << 16) | (4 << 24)
    for profile in (ardupilot, px4):
        for vehicle_type, table in profile.modes.items():
            assert all(profile.mode_name(number, vehicle_type) == name for name, number in table.items())
    with pytest.raises(ValueError, match="mode 'LAND' does not exist on ardupilot fixed_wing"):
        ardupilot.custom_mode("LAND", "fixed_wing")
