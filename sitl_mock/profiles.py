"""Autopilot profiles: the mission-protocol and flight-mode conventions the mock emulates.

Numbers come from the autopilots' sources (see ../shared/reference/mavlink-mission-notes.md):
ArduPilot MissionItemProtocol (requests with legacy MISSION_REQUEST, re-requests after 1000 ms,
cancels after 8000 ms, home at seq 0, rounds stored values) and PX4 mavlink_mission (MISSION_REQUEST_INT,
250 ms retry, 5 s protocol timeout, no home item). Capacities are typical defaults (ArduPilot's
mission storage on a 16 kB FRAM, PX4's dataman), both overridable per vehicle.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from gcs_planner.mavlink.enums import ARDUCOPTER_MODES, ARDUPLANE_MODES, PX4_MODES, Autopilot
from gcs_planner.mavlink.types import MissionType

__all__ = ["PROFILES", "AutopilotProfile"]


@dataclass(frozen=True)
class AutopilotProfile:
    """How one autopilot family runs the mission protocol and encodes its flight modes.

    rerequest_s: time without the requested item before the vehicle asks again [s].
    timeout_s: time without any item before the vehicle cancels an upload [s].
    capacity: items per mission type (MISSION, FENCE, RALLY); more -> MISSION_ACK(NO_SPACE).
    modes: vehicle type ("multirotor" / "fixed_wing") -> mode name -> HEARTBEAT custom_mode.
    rounds_values: emulate ArduPilot's storage (altitude in cm, hold time in whole seconds), so a
        read-back is close to, not equal to, the upload.
    reacks_final_item: a repeated last item after completion is answered with the ACK again
        (PX4 does; ArduPilot drops it, so a lost final ACK is never repeated).
    clear_denied_while_running: MISSION_CLEAR_ALL of the mission in AUTO -> ERROR (ArduPilot).
    """

    name: str
    autopilot: Autopilot
    uses_legacy_request: bool
    rerequest_s: float
    timeout_s: float
    home_at_seq0: bool
    capacity: dict[int, int]
    modes: dict[str, dict[str, int]]
    rounds_values: bool
    reacks_final_item: bool
    clear_denied_while_running: bool
    supports_partial_write: bool = field(default=True)

    def custom_mode(self, mode: str, vehicle_type: str = "multirotor") -> int:
        """HEARTBEAT custom_mode of a mode name; ValueError naming the mode if it does not exist."""
        table = self.modes[vehicle_type]
        try:
            return table[mode.upper()]
        except KeyError:
            raise ValueError(
                f"mode {mode!r} does not exist on {self.name} {vehicle_type}; known: {', '.join(table)}"
            ) from None

    def mode_name(self, custom_mode: int, vehicle_type: str = "multirotor") -> str | None:
        """Mode name of a HEARTBEAT custom_mode, None when the number is not in the table."""
        for name, number in self.modes[vehicle_type].items():
            if number == custom_mode:
                return name
        return None


ARDUPILOT = AutopilotProfile(
    name="ardupilot",
    autopilot=Autopilot.ARDUPILOTMEGA,
    uses_legacy_request=True,
    rerequest_s=1.0,
    timeout_s=8.0,
    home_at_seq0=True,
    capacity={MissionType.MISSION: 724, MissionType.FENCE: 84, MissionType.RALLY: 10},
    modes={"multirotor": ARDUCOPTER_MODES, "fixed_wing": ARDUPLANE_MODES},
    rounds_values=True,
    reacks_final_item=False,
    clear_denied_while_running=True,
)

PX4 = AutopilotProfile(
    name="px4",
    autopilot=Autopilot.PX4,
    uses_legacy_request=False,
    rerequest_s=0.25,
    timeout_s=5.0,
    home_at_seq0=False,
    capacity={MissionType.MISSION: 2000, MissionType.FENCE: 64, MissionType.RALLY: 32},
    modes={"multirotor": PX4_MODES, "fixed_wing": PX4_MODES},
    rounds_values=False,
    reacks_final_item=True,
    clear_denied_while_running=False,
    supports_partial_write=False,
)

PROFILES: dict[str, AutopilotProfile] = {p.name: p for p in (ARDUPILOT, PX4)}
