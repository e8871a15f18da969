"""What the GCS knows of each vehicle's state from its telemetry: arming, readiness, texts, progress.

``VehicleStatus`` subscribes to a link and keeps, per system id, what a run needs to decide and
to explain: the pre-arm check bit of SYS_STATUS, the newest STATUSTEXTs (an autopilot's own
reason for a refusal), position and home altitude, and mission progress (MISSION_CURRENT,
MISSION_ITEM_REACHED). It sends nothing.

Completion (``mission_done``): a finished mission looks different on each autopilot, so any of
- MISSION_CURRENT mission_state COMPLETE after the mission was seen ACTIVE (PX4; the mock);
- MISSION_ITEM_REACHED of the last item (PX4 repeats it; ArduPilot sends it for most items);
- the last item was current while in AUTO and then the vehicle disarmed (ArduCopter after a final
  NAV_LAND: it disarms and resets the mission, so neither of the above arrives) or switched to
  RTL (ArduPlane runs a final NAV_RETURN_TO_LAUNCH by changing mode; mission_state drops).
"""

from __future__ import annotations

import collections
from dataclasses import dataclass, field

from pymavlink.dialects.v20 import ardupilotmega as mavlink

from gcs_planner.autopilots import mode_of
from gcs_planner.mavlink.link import MavlinkLink, is_autopilot_heartbeat
from gcs_planner.mavlink.statustext import TextAssembler
from gcs_planner.wire.enums import MissionState
from gcs_planner.wire.units import reports_no_fix

__all__ = ["PREARM_BIT", "VehicleStatus", "VehicleTrack"]

PREARM_BIT = mavlink.MAV_SYS_STATUS_PREARM_CHECK  # SYS_STATUS sensor bit: pre-arm checks pass
TEXTS_KEPT = 20


@dataclass
class VehicleTrack:
    """One vehicle's latest state as its telemetry reported it."""

    texts: collections.deque = field(default_factory=lambda: collections.deque(maxlen=TEXTS_KEPT))
    prearm_ok: bool | None = None  # None: SYS_STATUS not seen or the bit not reported
    rel_alt_m: float | None = None
    home_amsl_m: float | None = None  # GLOBAL_POSITION_INT alt - relative_alt, or HOME_POSITION
    seq: int | None = None
    state: int = MissionState.UNKNOWN
    started: bool = False
    last_seq_current: bool = False  # the mission's last item was current while armed
    done: bool = False
    text_count: int = 0  # STATUSTEXTs received so far (to find the ones after an attempt)

    def texts_since(self, count: int) -> list[str]:
        new = self.text_count - count
        return list(self.texts)[-new:] if new > 0 else []


class VehicleStatus:
    """Per-vehicle state from ``link``'s frames; ``last_seq[sysid]`` is the mission's final seq."""

    def __init__(self, link: MavlinkLink, sysids: list[int]) -> None:
        self.link = link
        self.tracks = {s: VehicleTrack() for s in sysids}
        self.last_seq: dict[int, int] = {}
        self._texts = TextAssembler()
        self._unsubscribe = link.subscribe(self.on_frame)

    def close(self) -> None:
        self._unsubscribe()

    def on_frame(self, msg, raw: bytes, t_s: float) -> None:
        track = self.tracks.get(msg.get_srcSystem())
        if track is None:
            return
        kind = msg.get_type()
        if kind == "GLOBAL_POSITION_INT" and not reports_no_fix(msg):
            track.rel_alt_m = msg.relative_alt / 1000.0
            track.home_amsl_m = (msg.alt - msg.relative_alt) / 1000.0
        elif kind == "STATUSTEXT":
            text = self._texts.feed(msg)
            if text is not None:
                track.texts.append(text)
                track.text_count += 1
        elif kind == "SYS_STATUS":
            if msg.onboard_control_sensors_present & PREARM_BIT:
                track.prearm_ok = bool(msg.onboard_control_sensors_health & PREARM_BIT)
        elif kind == "HOME_POSITION":
            track.home_amsl_m = msg.altitude / 1000.0
        elif kind == "MISSION_CURRENT":
            self._on_current(msg.get_srcSystem(), track, msg)
        elif kind == "MISSION_ITEM_REACHED" and msg.seq == self.last_seq.get(msg.get_srcSystem()):
            track.done = track.started or track.done
        elif kind == "HEARTBEAT" and is_autopilot_heartbeat(msg):  # not a camera's, a gimbal's, ...
            self._on_heartbeat(msg.get_srcSystem(), track)

    def _on_current(self, sysid: int, track: VehicleTrack, msg) -> None:
        track.seq = msg.seq
        track.state = getattr(msg, "mission_state", MissionState.UNKNOWN)
        info = self.link.vehicles.get(sysid)
        if track.state == MissionState.ACTIVE or (
            info is not None and info.armed and mode_of(info) == "AUTO"
        ):
            track.started = True
        elif track.state == MissionState.COMPLETE and track.started:
            track.done = True
        if track.started and msg.seq == self.last_seq.get(sysid) and info is not None and info.armed:
            track.last_seq_current = True

    def _on_heartbeat(self, sysid: int, track: VehicleTrack) -> None:
        info = self.link.vehicles.get(sysid)
        if (
            info is not None
            and track.last_seq_current
            and (not info.armed or mode_of(info) in ("RTL", "LAND"))
        ):
            track.done = True

    def reason(self, sysid: int, since: int = 0, prefixes: tuple[str, ...] = ("",)) -> str:
        """The vehicle's newest STATUSTEXT after ``since`` texts that starts with one of ``prefixes``
        (its own words for a refusal), or ''."""
        texts = [t for t in self.tracks[sysid].texts_since(since) if t.startswith(prefixes)]
        return texts[-1] if texts else ""
