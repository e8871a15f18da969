"""Autopilot side of the MAVLink mission protocol, free of I/O, for the mock vehicle.

The mock vehicle feeds every MISSION_* message to :meth:`MissionServer.handle` and calls
:meth:`MissionServer.poll` on its clock; both return the messages to send back (pymavlink message
objects, targeted at the partner). One server holds the three lists (mission, fence, rally).

Choices where the autopilots differ or the spec is open:
- Storage as the profile says (``AutopilotProfile.stores_as_received``): ArduPilot's
  mission and rally lists are truncated at MISSION_COUNT and written as items arrive, so a failed
  upload leaves a mix of old and new; its fence and every PX4 list are replaced only when an upload
  completes. ``non_atomic=True`` writes every list in place, ``non_atomic=False`` none.
- An upload session belongs to the ids of its MISSION_COUNT (profile: second_uploader_result,
  same_partner_restarts, foreign_item_denied, with the sources): ArduPilot DENIES other ids and lets
  the same ids restart; PX4 answers other ids ERROR and the same ids, once items flow, ERROR.
- ArduPilot-like: MISSION_REQUEST, re-request after 1 s, cancel with MISSION_ACK(OPERATION_CANCELLED)
  after 8 s without an item, wrong seq -> MISSION_ACK(INVALID_SEQUENCE) and the session continues,
  a second uploader or items from another system -> DENIED, downloads during an upload -> DENIED,
  count over capacity -> NO_SPACE + STATUSTEXT, CLEAR_ALL while receiving or (mission) in AUTO ->
  ERROR, CLEAR_ALL of mission_type ALL -> UNSUPPORTED, an item while no upload runs (a repeated
  final item after completion) -> MISSION_ACK(ERROR) (GCS_MAVLINK::handle_mission_item).
- Items are stored as the autopilot stores them (the profile's ``storage``, sitl_mock/storage.py:
  AP_Mission for ArduCopter / ArduPlane, PX4's mission_item_s, in float32 / C integers), so a
  download returns what the real one would; an altitude it refuses (ArduPilot: |z| >= 83000 m or
  NaN in a Location) is answered with MISSION_ACK(INVALID_PARAM7).
- PX4-like: MISSION_REQUEST_INT, 250 ms re-request, 5 s timeout, wrong seq ignored (the timer
  re-requests), a repeated final item is acknowledged again, MISSION_ACK(OPERATION_CANCELLED) from
  the uploader cancels, a positionless command outside MAV_FRAME_MISSION (or a positional one in
  it) -> UNSUPPORTED (parse_mavlink_mission_item).
- Both answer MISSION_REQUEST_INT with MISSION_ITEM_INT and legacy MISSION_REQUEST with MISSION_ITEM.
- opaque_id: CRC-32 of the stored list (never 0, which means "unsupported"), sent in the final
  MISSION_ACK, in MISSION_COUNT on download and in MISSION_CURRENT.
- Scripted failures (:class:`Failure`) follow QGroundControl's MockLinkMissionItemHandler; the
  ``*_FIRST_RESPONSE`` ones fire once, the others on every transfer until ``failure`` is reset.
"""

from __future__ import annotations

import logging
import math
import struct
import zlib
from collections.abc import Callable
from dataclasses import dataclass, field
from enum import StrEnum

from pymavlink.dialects.v20 import ardupilotmega as mavlink

from gcs_planner.wire.dialect import has_position
from gcs_planner.wire.enums import MissionResult, MissionState
from gcs_planner.wire.types import GLOBAL_FRAMES, MissionItem, MissionType
from gcs_planner.wire.wire import MissionAckMessage, MissionCountMessage, MissionCurrentMessage
from sitl_mock.profiles import AutopilotProfile
from sitl_mock.storage import Refused

__all__ = ["Failure", "MissionServer"]

log = logging.getLogger(__name__)

_LIST_TYPES = (MissionType.MISSION, MissionType.FENCE, MissionType.RALLY)
_KNOWN_FRAMES = frozenset({0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15, 16, 17, 18, 19, 20, 21})
_ITEM_PACK = struct.Struct("<HBHBBffffiifB")


class Failure(StrEnum):
    """Scripted failures after QGroundControl's MockLinkMissionItemHandler::FailureMode_t."""

    NONE = "none"
    READ_REQUEST_LIST_NO_RESPONSE = "read_request_list_no_response"
    READ_REQUEST_LIST_FIRST_RESPONSE = "read_request_list_first_response"
    READ_REQUEST0_NO_RESPONSE = "read_request0_no_response"
    READ_REQUEST1_NO_RESPONSE = "read_request1_no_response"
    READ_REQUEST0_FIRST_RESPONSE = "read_request0_first_response"
    READ_REQUEST1_FIRST_RESPONSE = "read_request1_first_response"
    READ_REQUEST0_INCORRECT_SEQUENCE = "read_request0_incorrect_sequence"
    READ_REQUEST1_INCORRECT_SEQUENCE = "read_request1_incorrect_sequence"
    READ_REQUEST0_ERROR_ACK = "read_request0_error_ack"
    READ_REQUEST1_ERROR_ACK = "read_request1_error_ack"
    WRITE_COUNT_NO_RESPONSE = "write_count_no_response"
    WRITE_COUNT_FIRST_RESPONSE = "write_count_first_response"
    WRITE_REQUEST1_NO_RESPONSE = "write_request1_no_response"
    WRITE_REQUEST0_INCORRECT_SEQUENCE = "write_request0_incorrect_sequence"
    WRITE_REQUEST1_INCORRECT_SEQUENCE = "write_request1_incorrect_sequence"
    WRITE_REQUEST0_ERROR_ACK = "write_request0_error_ack"
    WRITE_REQUEST1_ERROR_ACK = "write_request1_error_ack"
    WRITE_FINAL_ACK_NO_RESPONSE = "write_final_ack_no_response"
    WRITE_FINAL_ACK_ERROR_ACK = "write_final_ack_error_ack"
    # not QGC's: a vehicle stuck asking for item 0 whatever it gets (the client's overall deadline ends it)
    WRITE_REQUEST0_REPEAT = "write_request0_repeat"


_ONE_SHOT = frozenset(f for f in Failure if f.value.endswith("first_response"))


@dataclass
class _Upload:
    """One upload session (a MISSION_COUNT or WRITE_PARTIAL_LIST being served)."""

    partner: tuple[int, int]
    first: int  # first seq requested (0, or start_index of a partial write)
    last: int  # last seq requested (inclusive)
    next_seq: int
    last_receive_s: float
    last_request_s: float
    received: list[MissionItem] = field(default_factory=list)
    partial: bool = False  # MISSION_WRITE_PARTIAL_LIST: replace items first..last only
    silent: bool = False  # scripted: stop requesting (the session then times out)


@dataclass(frozen=True)
class _Completed:
    """The last finished upload, to re-acknowledge a repeated final item (PX4 behaviour)."""

    partner: tuple[int, int]
    last_seq: int
    opaque_id: int


class MissionServer:
    """Mission, fence and rally lists of one vehicle, served over the mission protocol.

    Attributes the vehicle may set: ``failure`` / ``failure_result`` (scripted failures and the
    MAV_MISSION_RESULT their error ACKs carry), ``on_change(mission_type)`` (a list was replaced),
    ``on_current(seq)`` (MISSION_SET_CURRENT accepted), ``mission_running`` (vehicle in AUTO:
    ArduPilot refuses CLEAR_ALL then), ``home`` (item reported at seq 0 of an empty ArduPilot-like
    mission).
    """

    def __init__(
        self,
        sysid: int,
        compid: int,
        profile: AutopilotProfile,
        *,
        capacity: int | None = None,
        non_atomic: bool | None = None,
        vehicle_type: str = "multirotor",
    ) -> None:
        self.sysid = sysid
        self.storage = profile.storage[vehicle_type]
        self.compid = compid
        self.profile = profile
        if non_atomic is None:  # as the autopilot stores each list
            self.in_place = frozenset(profile.stores_as_received)
        else:
            self.in_place = frozenset(_LIST_TYPES) if non_atomic else frozenset()
        self.capacity = dict(profile.capacity)
        if capacity is not None:
            self.capacity[MissionType.MISSION] = capacity
        self.failure: Failure = Failure.NONE
        self.failure_result: MissionResult = MissionResult.ERROR
        self.on_change: Callable[[int], None] | None = None
        self.on_current: Callable[[int], None] | None = None
        self.mission_running = False
        self.home: MissionItem | None = None
        self._lists: dict[int, list[MissionItem]] = {t: [] for t in _LIST_TYPES}
        self._ids: dict[int, int] = dict.fromkeys(_LIST_TYPES, 0)
        self._uploads: dict[int, _Upload] = {}
        self._completed: dict[int, _Completed] = {}
        self._fired: set[Failure] = set()
        self._current_seq = 0
        self._handlers: dict[
            str, Callable[[mavlink.MAVLink_message, float], list[mavlink.MAVLink_message]]
        ] = {
            "MISSION_COUNT": self._on_count,
            "MISSION_WRITE_PARTIAL_LIST": self._on_write_partial_list,
            "MISSION_ITEM_INT": self._on_item,
            "MISSION_ITEM": self._on_item,
            "MISSION_REQUEST_LIST": self._on_request_list,
            "MISSION_REQUEST_INT": self._on_request,
            "MISSION_REQUEST": self._on_request,
            "MISSION_ACK": self._on_ack,
            "MISSION_CLEAR_ALL": self._on_clear_all,
            "MISSION_SET_CURRENT": self._on_set_current,
        }

    # ----------------------------------------------------------------- public API for the vehicle
    def handle(self, msg: mavlink.MAVLink_message, now_s: float) -> list[mavlink.MAVLink_message]:
        """Process one received MISSION_* message; returns the replies (others are ignored)."""
        handler = self._handlers.get(msg.get_type())
        if handler is None or msg.target_system not in (0, self.sysid):
            return []
        if msg.target_component not in (0, self.compid):
            return []
        mission_type = getattr(msg, "mission_type", MissionType.MISSION)
        valid = (*_LIST_TYPES, MissionType.ALL) if handler == self._on_clear_all else _LIST_TYPES
        if mission_type not in valid:
            return [self._ack(msg, MissionResult.UNSUPPORTED, mission_type)]
        return handler(msg, now_s)

    def poll(self, now_s: float) -> list[mavlink.MAVLink_message]:
        """Re-request overdue items and cancel stalled uploads; call often (every <= 50 ms)."""
        out: list[mavlink.MAVLink_message] = []
        for mission_type, up in list(self._uploads.items()):
            if now_s >= up.last_receive_s + self.profile.timeout_s:
                log.info(
                    "sysid %d: upload of type %d timed out at seq %d", self.sysid, mission_type, up.next_seq
                )
                del self._uploads[mission_type]
                ack = MissionAckMessage(*up.partner, MissionResult.OPERATION_CANCELLED, mission_type)
                out.append(ack)
            elif not up.silent and now_s >= up.last_request_s + self.profile.rerequest_s:
                out.append(self._request(up, mission_type, up.next_seq, now_s))
        return out

    def next_deadline_s(self) -> float | None:
        """Earliest time at which :meth:`poll` has something to do (None: nothing pending)."""
        times = []
        for up in self._uploads.values():
            times.append(up.last_receive_s + self.profile.timeout_s)
            if not up.silent:
                times.append(up.last_request_s + self.profile.rerequest_s)
        return min(times, default=None)

    def items(self, mission_type: int = MissionType.MISSION) -> list[MissionItem]:
        """The stored list (a copy) as the vehicle would fly it."""
        return list(self._lists[mission_type])

    def count(self, mission_type: int = MissionType.MISSION) -> int:
        return len(self._lists[mission_type])

    def opaque_id(self, mission_type: int = MissionType.MISSION) -> int:
        """Id of the stored list (0 when empty)."""
        return self._ids[mission_type]

    def busy(self, mission_type: int = MissionType.MISSION) -> bool:
        """True while an upload of this type is in progress."""
        return mission_type in self._uploads

    @property
    def current_seq(self) -> int:
        return self._current_seq

    def set_current(self, seq: int) -> bool:
        """Make ``seq`` the current mission item; False (nothing changed) when out of range."""
        if not 0 <= seq < len(self._lists[MissionType.MISSION]):
            return False
        self._current_seq = seq
        if self.on_current is not None:
            self.on_current(seq)
        return True

    def mission_current(
        self, mission_state: int | None = None, mission_mode: int = 0
    ) -> MissionCurrentMessage:
        """MISSION_CURRENT for the vehicle's 1 Hz stream; state defaults to NO_MISSION / NOT_STARTED."""
        total = len(self._lists[MissionType.MISSION])
        if mission_state is None:
            mission_state = MissionState.NOT_STARTED if total else MissionState.NO_MISSION
        return MissionCurrentMessage(
            self._current_seq,
            total if total else 65535,
            int(mission_state),
            mission_mode,
            self._ids[MissionType.MISSION],
            self._ids[MissionType.FENCE],
            self._ids[MissionType.RALLY],
        )

    def forget(self) -> None:
        """Reboot without persistent storage: every list, id and session is lost."""
        self._lists = {t: [] for t in _LIST_TYPES}
        self._ids = dict.fromkeys(_LIST_TYPES, 0)
        self._uploads.clear()
        self._completed.clear()
        self._current_seq = 0

    # ----------------------------------------------------------------- upload
    def _on_count(self, msg: mavlink.MAVLink_message, now_s: float) -> list[mavlink.MAVLink_message]:
        mission_type = msg.mission_type
        if self._fails(Failure.WRITE_COUNT_NO_RESPONSE) or self._fails_once(
            Failure.WRITE_COUNT_FIRST_RESPONSE
        ):
            return []
        partner = (msg.get_srcSystem(), msg.get_srcComponent())
        up = self._uploads.get(mission_type)
        if up is not None and up.partner != partner:
            return [self._ack(msg, self.profile.second_uploader_result)]
        if up is not None and not self.profile.same_partner_restarts:
            if up.next_seq == up.first:  # PX4: "looks like our MISSION_REQUEST was lost, try again"
                up.last_receive_s = now_s
                return [self._request(up, mission_type, up.next_seq, now_s)]
            busy = mavlink.MAVLink_statustext_message(mavlink.MAV_SEVERITY_CRITICAL, b"WPM: REJ. CMD: Busy")
            up.last_receive_s = now_s
            return [busy, MissionAckMessage(*up.partner, MissionResult.ERROR, mission_type)]
        self._uploads.pop(mission_type, None)  # ArduPilot: the same GCS may restart
        capacity = self.capacity[mission_type]
        if msg.count > capacity:
            text = f"Only {capacity} items are supported"
            status = mavlink.MAVLink_statustext_message(mavlink.MAV_SEVERITY_WARNING, text.encode())
            return [self._ack(msg, MissionResult.NO_SPACE), status]
        if self._fails(Failure.WRITE_REQUEST0_ERROR_ACK):
            return [self._ack(msg, self.failure_result)]
        if msg.count == 0:
            return [self._complete(partner, mission_type, 0, [], -1)]
        if mission_type in self.in_place:
            del self._lists[mission_type][msg.count :]  # ArduPilot truncates at MISSION_COUNT
        up = _Upload(partner, 0, msg.count - 1, 0, now_s, now_s)
        self._uploads[mission_type] = up
        seq = 1 if self._fails(Failure.WRITE_REQUEST0_INCORRECT_SEQUENCE) else 0
        return [self._request(up, mission_type, seq, now_s)]

    def _on_write_partial_list(
        self, msg: mavlink.MAVLink_message, now_s: float
    ) -> list[mavlink.MAVLink_message]:
        mission_type = msg.mission_type
        stored = len(self._lists[mission_type])
        if not self.profile.supports_partial_write:
            return [self._ack(msg, MissionResult.UNSUPPORTED)]
        if mission_type in self._uploads:
            return [self._ack(msg, MissionResult.DENIED)]
        if not 0 <= msg.start_index <= msg.end_index < stored:
            return [self._ack(msg, MissionResult.ERROR)]
        partner = (msg.get_srcSystem(), msg.get_srcComponent())
        up = _Upload(partner, msg.start_index, msg.end_index, msg.start_index, now_s, now_s, partial=True)
        self._uploads[mission_type] = up
        return [self._request(up, mission_type, up.next_seq, now_s)]

    def _on_item(self, msg: mavlink.MAVLink_message, now_s: float) -> list[mavlink.MAVLink_message]:
        mission_type = msg.mission_type
        partner = (msg.get_srcSystem(), msg.get_srcComponent())
        up = self._uploads.get(mission_type)
        if up is None:
            done = self._completed.get(mission_type)
            if (
                self.profile.reacks_final_item
                and done is not None
                and done.partner == partner
                and done.last_seq == msg.seq
                and not self._fails(Failure.WRITE_FINAL_ACK_NO_RESPONSE)
            ):
                return [self._ack(msg, MissionResult.ACCEPTED, opaque_id=done.opaque_id)]
            return [self._ack(msg, MissionResult.ERROR)] if self.profile.error_on_stray_item else []
        if partner != up.partner and not self.profile.foreign_item_denied:
            text = b"REJ. MIS ITEM: partner id mismatch"
            return [mavlink.MAVLink_statustext_message(mavlink.MAV_SEVERITY_CRITICAL, text)]
        if msg.seq != up.next_seq:
            return (
                [self._ack(msg, MissionResult.INVALID_SEQUENCE)] if self.profile.uses_legacy_request else []
            )
        if partner != up.partner:
            return [self._ack(msg, MissionResult.DENIED)]
        if self._fails(Failure.WRITE_REQUEST0_REPEAT):
            up.last_receive_s = now_s
            return [self._request(up, mission_type, up.first, now_s)]
        item, result = self._decode_item(msg)
        if result != MissionResult.ACCEPTED:
            del self._uploads[mission_type]
            return [self._ack(msg, result)]
        up.received.append(item)
        if mission_type in self.in_place and not up.partial:
            self._store_in_place(mission_type, item)
        up.next_seq += 1
        up.last_receive_s = now_s
        if up.next_seq > up.last:
            return self._finish_upload(msg, mission_type, up)
        if up.next_seq == up.first + 1:
            if self._fails(Failure.WRITE_REQUEST1_ERROR_ACK):
                del self._uploads[mission_type]
                return [self._ack(msg, self.failure_result)]
            if self._fails(Failure.WRITE_REQUEST1_NO_RESPONSE):
                up.silent = True
                return []
            if self._fails(Failure.WRITE_REQUEST1_INCORRECT_SEQUENCE) and up.last > up.next_seq:
                return [self._request(up, mission_type, up.next_seq + 1, now_s)]
        return [self._request(up, mission_type, up.next_seq, now_s)]

    def _finish_upload(self, msg: mavlink.MAVLink_message, mission_type: int, up: _Upload) -> list:
        del self._uploads[mission_type]
        if self._fails(Failure.WRITE_FINAL_ACK_ERROR_ACK):
            return [self._ack(msg, self.failure_result)]
        new = up.received
        if up.partial:
            new = list(self._lists[mission_type])
            new[up.first : up.last + 1] = up.received
        ack = self._complete(up.partner, mission_type, len(new), new, up.last)
        return [] if self._fails(Failure.WRITE_FINAL_ACK_NO_RESPONSE) else [ack]

    def _complete(
        self, partner: tuple[int, int], mission_type: int, count: int, new: list[MissionItem], last_seq: int
    ) -> MissionAckMessage:
        self._replace(mission_type, new)
        opaque = self._ids[mission_type]
        self._completed[mission_type] = _Completed(partner, last_seq, opaque)
        return MissionAckMessage(*partner, MissionResult.ACCEPTED, mission_type, opaque)

    def _replace(self, mission_type: int, new: list[MissionItem]) -> None:
        self._lists[mission_type] = list(new)
        self._ids[mission_type] = _list_id(new, mission_type)
        if mission_type == MissionType.MISSION and self._current_seq >= max(len(new), 1):
            self._current_seq = 0
        if self.on_change is not None:
            self.on_change(mission_type)

    def _store_in_place(self, mission_type: int, item: MissionItem) -> None:
        stored = self._lists[mission_type]
        self._ids[mission_type] = 0  # a half-written list is no known plan
        if item.seq < len(stored):
            stored[item.seq] = item
        else:
            stored.append(item)

    def _request(self, up: _Upload, mission_type: int, seq: int, now_s: float) -> mavlink.MAVLink_message:
        up.last_request_s = now_s
        cls = mavlink.MAVLink_mission_request_message
        if not self.profile.uses_legacy_request:
            cls = mavlink.MAVLink_mission_request_int_message
        return cls(up.partner[0], up.partner[1], seq, mission_type)

    def _decode_item(self, msg: mavlink.MAVLink_message) -> tuple[MissionItem, MissionResult]:
        """MISSION_ITEM(_INT) -> stored item (rounded like the profile's autopilot) and a verdict."""
        item = MissionItem.from_message(msg)
        if msg.frame not in _KNOWN_FRAMES:
            return item, MissionResult.UNSUPPORTED_FRAME
        if msg.command not in mavlink.enums["MAV_CMD"] and msg.command not in self.profile.extra_commands:
            return item, MissionResult.UNSUPPORTED
        if msg.frame in GLOBAL_FRAMES and (item.x or item.y):
            if abs(item.x) > 90 * 10**7:
                return item, MissionResult.INVALID_PARAM5_X
            if abs(item.y) > 180 * 10**7:
                return item, MissionResult.INVALID_PARAM6_Y
        if self.profile.nan_params_rejected:
            bad = _bad_param(msg)
            if bad:
                return item, MissionResult(MissionResult.INVALID_PARAM1 + bad - 1)
        if (
            self.profile.mission_frame_for_positionless
            and item.mission_type == MissionType.MISSION
            and has_position(item.command) == (item.frame == mavlink.MAV_FRAME_MISSION)
        ):
            return item, MissionResult.UNSUPPORTED  # PX4: positionless items only in MAV_FRAME_MISSION
        try:  # the altitude check is the storage's (ArduPilot: only items kept in a Location)
            return self.storage(item), MissionResult.ACCEPTED
        except Refused as refused:
            return item, refused.result

    # ----------------------------------------------------------------- download
    def _on_request_list(self, msg: mavlink.MAVLink_message, now_s: float) -> list[mavlink.MAVLink_message]:
        mission_type = msg.mission_type
        if self._fails(Failure.READ_REQUEST_LIST_NO_RESPONSE) or self._fails_once(
            Failure.READ_REQUEST_LIST_FIRST_RESPONSE
        ):
            return []
        if mission_type in self._uploads:
            return [self._ack(msg, MissionResult.DENIED)]
        count = len(self._served(mission_type))
        sysid, compid = msg.get_srcSystem(), msg.get_srcComponent()
        return [MissionCountMessage(sysid, compid, count, mission_type, self._ids[mission_type])]

    def _on_request(self, msg: mavlink.MAVLink_message, now_s: float) -> list[mavlink.MAVLink_message]:
        mission_type, seq = msg.mission_type, msg.seq
        if mission_type in self._uploads:
            return [self._ack(msg, MissionResult.DENIED)]
        served = self._served(mission_type)
        if not 0 <= seq < len(served):
            return [self._ack(msg, MissionResult.INVALID_SEQUENCE)]
        if seq in (0, 1):
            failures = _READ_FAILURES[seq]
            if self._fails(failures["no"]) or self._fails_once(failures["first"]):
                return []
            if self._fails(failures["error"]):
                return [self._ack(msg, self.failure_result)]
            if self._fails(failures["wrong"]):
                seq = len(served)  # a seq the GCS did not ask for (and outside the list)
        item = served[min(seq, len(served) - 1)]
        return [_item_message(item, seq, msg, legacy=msg.get_type() == "MISSION_REQUEST")]

    def _served(self, mission_type: int) -> list[MissionItem]:
        """What a download returns: the stored list, with ArduPilot's home at seq 0 if it has one."""
        items = self._lists[mission_type]
        if mission_type == MissionType.MISSION and self.profile.home_at_seq0 and self.home is not None:
            return [self.home.with_seq(0), *items[1:]]
        return items

    # ----------------------------------------------------------------- ack, clear, set current
    def _on_ack(self, msg: mavlink.MAVLink_message, now_s: float) -> list[mavlink.MAVLink_message]:
        up = self._uploads.get(msg.mission_type)
        partner = (msg.get_srcSystem(), msg.get_srcComponent())
        cancels = msg.type == MissionResult.OPERATION_CANCELLED and not self.profile.uses_legacy_request
        if up is not None and up.partner == partner and cancels:
            del self._uploads[msg.mission_type]
        return []

    def _on_clear_all(self, msg: mavlink.MAVLink_message, now_s: float) -> list[mavlink.MAVLink_message]:
        if msg.mission_type == MissionType.ALL and not self.profile.clear_all_types:
            return [self._ack(msg, MissionResult.UNSUPPORTED)]
        types = _LIST_TYPES if msg.mission_type == MissionType.ALL else (msg.mission_type,)
        refuse = any(t in self._uploads for t in types) or (
            MissionType.MISSION in types and self.mission_running and self.profile.clear_denied_while_running
        )
        if refuse:
            return [self._ack(msg, MissionResult.ERROR)]
        for mission_type in types:
            self._replace(mission_type, [])
        return [self._ack(msg, MissionResult.ACCEPTED)]

    def _on_set_current(self, msg: mavlink.MAVLink_message, now_s: float) -> list[mavlink.MAVLink_message]:
        if self.set_current(msg.seq):
            return [self.mission_current()]
        text = f"Set current: seq {msg.seq} out of range"
        return [mavlink.MAVLink_statustext_message(mavlink.MAV_SEVERITY_WARNING, text.encode())]

    # ----------------------------------------------------------------- helpers
    def _ack(
        self,
        msg: mavlink.MAVLink_message,
        result: MissionResult,
        mission_type: int | None = None,
        opaque_id: int = 0,
    ) -> MissionAckMessage:
        if mission_type is None:
            mission_type = msg.mission_type
        return MissionAckMessage(msg.get_srcSystem(), msg.get_srcComponent(), result, mission_type, opaque_id)

    def _fails(self, failure: Failure) -> bool:
        return self.failure == failure

    def _fails_once(self, failure: Failure) -> bool:
        """A *_FIRST_RESPONSE failure: true the first time it is asked for, false afterwards."""
        if self.failure != failure or failure in self._fired:
            return False
        self._fired.add(failure)
        return True


_READ_FAILURES = {
    seq: {
        "no": Failure(f"read_request{seq}_no_response"),
        "first": Failure(f"read_request{seq}_first_response"),
        "error": Failure(f"read_request{seq}_error_ack"),
        "wrong": Failure(f"read_request{seq}_incorrect_sequence"),
    }
    for seq in (0, 1)
}
assert all(f in _ONE_SHOT for f in (_READ_FAILURES[0]["first"], _READ_FAILURES[1]["first"]))


def _list_id(items: list[MissionItem], mission_type: int) -> int:
    """opaque_id of a list: CRC-32 over the packed items, 0 only for an empty list."""
    if not items:
        return 0
    crc = zlib.crc32(bytes([mission_type]))
    for it in items:
        packed = _ITEM_PACK.pack(*it.fields())
        crc = zlib.crc32(packed, crc)
    return crc or 1


def _item_message(
    item: MissionItem, seq: int, request: mavlink.MAVLink_message, legacy: bool
) -> mavlink.MAVLink_message:
    """MISSION_ITEM_INT for MISSION_REQUEST_INT; float MISSION_ITEM (degrees) for legacy MISSION_REQUEST."""
    target = (request.get_srcSystem(), request.get_srcComponent())
    common = (
        item.frame,
        item.command,
        item.current,
        item.autocontinue,
        item.param1,
        item.param2,
        item.param3,
        item.param4,
    )
    if legacy:
        scale = 1e7 if item.frame in GLOBAL_FRAMES else 1e4
        return mavlink.MAVLink_mission_item_message(
            *target, seq, *common, item.x / scale, item.y / scale, item.z, request.mission_type
        )
    return mavlink.MAVLink_mission_item_int_message(
        *target, seq, *common, item.x, item.y, item.z, request.mission_type
    )


# AP_Mission::sanity_check_params: the params (1-4) that may be NaN, per command; inf never may
_NAN_ALLOWED = {
    mavlink.MAV_CMD_NAV_WAYPOINT: {4},
    mavlink.MAV_CMD_NAV_LAND: {4},
    mavlink.MAV_CMD_NAV_TAKEOFF: {4},
    mavlink.MAV_CMD_NAV_VTOL_TAKEOFF: {4},
    mavlink.MAV_CMD_NAV_VTOL_LAND: {3, 4},
}


def _bad_param(msg: mavlink.MAVLink_message) -> int:
    """The first of params 1-4 ArduPilot refuses (NaN where not allowed, or inf); 0 when none."""
    allowed = _NAN_ALLOWED.get(msg.command, set())
    for k, value in enumerate((msg.param1, msg.param2, msg.param3, msg.param4), start=1):
        if math.isinf(value) or (math.isnan(value) and k not in allowed):
            return k
    return 0
