"""GCS side of the mission protocol as I/O-free state machines (upload, download, clear, set-current).

Each transfer is driven by three calls that return the messages to send: ``start(now_s)``,
``on_message(msg, now_s)`` for messages that pass ``accepts(msg)``, and ``on_timeout(now_s)`` once
``now_s >= deadline_s``. A transfer ends exactly once, in ``_finish``: ``done`` becomes True and
``outcome`` holds the items / opaque id or the typed error. The async client (mission.py) and the
fake-time tests wrap the same cores, so retry counts are tested exactly.

Choices (where the spec leaves room):
- MISSION_COUNT is resent every COUNT_RETRY_S = 1.5 s up to COUNT_RETRIES = 5 times until the first
  request (Skybrush); after that the vehicle drives the upload with its own re-requests.
- Each request is answered once, always with MISSION_ITEM_INT (also legacy MISSION_REQUEST, as
  ArduPilot sends). A request for an item sent less than max(DUPLICATE_WINDOW_S, 2 x smoothed RTT)
  ago is a duplicate (link duplication, reordering, or the request for an item already in flight)
  and is ignored instead of answered again: this is what keeps slow links from flooding (PX4
  #11078). Genuine re-requests come after the vehicle's retry time (>= 250 ms), so they pass.
- Items in flight (``Timing.window``, default 16): the first request for item r also sends the
  items up to r + window - 1 not sent yet, so the vehicle's next item is already on its way when it
  asks. That moves ``window`` items per round trip instead of one. They leave in datagrams of
  ``Timing.batch`` items (8: 400 bytes; mission.py puts a datagram boundary after each batch of
  what link.py would otherwise send together), so the first window is two datagrams: the vehicle
  works on the second while the client answers the requests of the first with the next batch, and
  each side keeps the other busy instead of waiting for it. ArduPilot answers a datagram of items
  with one datagram of requests (its UDP driver sends what its buffer holds), so on a fast link each
  side wakes once per batch, not once per item; PX4 sends each request in a datagram of its own,
  so the window is topped up a whole batch (at most half the window) at a time: most of PX4's
  requests send nothing, and the items it gets still come eight to a datagram (on PX4 SITL 12-18 %
  less client CPU per item than refilling one item per request; docs/results/upload_cpu.md).
  It rests on the behaviour push-ahead relies on (below): both autopilots store the item they wait
  for and drop or refuse the others; on an in-order link items arrive in order, so nothing is
  refused. The cost is on a lossy link: a lost item makes the vehicle drop the rest of the window
  (ArduPilot answers each with INVALID_SEQUENCE), resent by the push. The final-ACK phase starts
  once the vehicle asked for the last item (or a push sent it). ``Timing(push_ahead=False,
  window=1)`` is the spec-literal client.
- Only the last item is resent on our own timer, until MISSION_ACK (lost final ACK, devguide #171);
  its timeout adapts to the measured round trip (4 x smoothed RTT within 0.3..1.5 s). Where a push
  sent the last item before the vehicle asked for it, the vehicle may still wait for an earlier one
  (lost again): the timer then resends the window from the highest item it asked for, so the
  final-item retries never run out on a vehicle that is mid-upload and report its ACK as lost.
- Loss recovery ahead of the vehicle's timer ("push-ahead"): when the next request is overdue
  (1.5 x smoothed RTT within 0.05..0.5 s; requests normally come every RTT / window) the client
  resends the highest requested item r and the rest of its window, and pushes one item more
  unasked (r .. r + window). Whichever frame was lost (item r, or the request for r + 1), the
  vehicle then accepts what it expects, because ArduPilot and PX4 both store any item whose seq is
  the one they wait for and drop the rest (go-back-N); a surplus copy costs one
  MISSION_ACK(INVALID_SEQUENCE) on ArduPilot (ignored, see below) and nothing on PX4. A genuine
  re-request (item r not sent within the duplicate window) likewise gets the whole window again. If
  a push goes unanswered too, up to Timing.push_rounds (3) follow, each at twice the previous
  timeout and one item wider, which also covers a lost push. Then the client waits for the vehicle,
  so a silent vehicle gets a few frames, not the mission. Without push-ahead every lost frame waits
  for the vehicle's re-request: 1 s on ArduPilot (docs/mavlink-protocol.md).
  ``Timing(push_ahead=False)`` turns it off.
- MISSION_ACK(INVALID_SEQUENCE) mid-upload is ignored: ArduPilot sends it for an out-of-order item
  and then re-requests the expected one (QGC PR #6718). Success only on MISSION_ACK(ACCEPTED) after
  the last item was sent (whether or not the vehicle's request for it arrived: with items in flight
  the vehicle may store the last items of a datagram and ACK at once, and a lost request must not
  turn its ACK into a lost one); an ACCEPTED before that is stale and ignored. An ACCEPTED while some item
  was never sent, or was jumped over before we sent it, is a MissionProtocolError naming those seqs
  (the vehicle cannot hold them: it may hold a mix of old and new items).
- After the final-item retries the outcome is a timeout with ``ack_lost=True``: the vehicle may hold
  the new mission (ArduPilot never repeats a final ACK). mission.py then verifies by download.
- Overall deadline: an upload ends after DEADLINE_BASE_S + DEADLINE_PER_ITEM_S x items
  (20 s + 1 s per item: 1000 items on a 0.5 s round-trip radio with two in flight take ~250 s) however
  busy the vehicle keeps it, e.g. one that re-requests item 0 for ever (each request resets the
  inactivity timer). A download gets the same bound from the vehicle's MISSION_COUNT (a vehicle
  that answers each request only on its last retry would hold it for hours). Giving up sends
  MISSION_ACK(OPERATION_CANCELLED).
- The transfer is bound to its peer: it takes only frames addressed to our sysid *and* compid (or
  broadcast), of its mission type. A request that goes back to an item the vehicle asked for long
  ago (more than max(RESTART_WINDOW_S, 4 x smoothed RTT): no delayed duplicate is that late) means
  the vehicle started another session: both autopilots only ever (re-)request the item they wait
  for, which never decreases within one session (ArduPilot ``request_i``, PX4 ``_transfer_seq``), and
  ArduPilot lets a MISSION_COUNT from the same sysid/compid restart an upload
  (MissionItemProtocol::handle_mission_count). That is another GCS using our ids: the upload ends
  with MissionProtocolError and sends nothing more, so it never feeds items into the other session.
  Likewise, before the first request a request for any item but the first answers someone else's
  MISSION_COUNT (a session starts at item 0, or start_index) and is ignored. Two GCSs with the same
  ids that start within one round trip of each other cannot be told apart on the wire: the fix is
  distinct ids (``--gcs-sysid``), with which both autopilots refuse the second uploader.
- Inactivity timeout INACTIVITY_TIMEOUT_S = 10 s (> ArduPilot's 8 s, so the vehicle's own
  OPERATION_CANCELLED normally arrives first and is reported as such). On any timeout we send
  MISSION_ACK(OPERATION_CANCELLED) so the vehicle drops its half of the session.
- Downloads re-request the next item after an adaptive timeout (4 x RTT within 0.25..1.5 s),
  DOWNLOAD_RETRIES = 8 times per item (the spec's 5 fails ~4 % of 20-item downloads at 20 % loss
  each way); legacy float MISSION_ITEM answers are accepted and converted.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from enum import Enum, auto

from pymavlink.dialects.v20 import ardupilotmega as mavlink

from gcs_planner.mavlink.errors import (
    MissionError,
    MissionInputError,
    MissionProtocolError,
    MissionTimeoutError,
    error_for_result,
    mission_type_name,
)
from gcs_planner.wire.enums import MissionResult
from gcs_planner.wire.types import MissionItem, MissionType

__all__ = [
    "COUNT_RETRIES",
    "COUNT_RETRY_S",
    "DEADLINE_BASE_S",
    "DEADLINE_PER_ITEM_S",
    "DOWNLOAD_RETRIES",
    "DUPLICATE_WINDOW_S",
    "FINAL_ITEM_RETRIES",
    "INACTIVITY_TIMEOUT_S",
    "ClearTransfer",
    "DownloadTransfer",
    "Outcome",
    "SetCurrentTransfer",
    "Timing",
    "Transfer",
    "UploadTransfer",
]

log = logging.getLogger(__name__)

COUNT_RETRY_S = 1.5  # MISSION_COUNT / REQUEST_LIST / CLEAR_ALL resend period until the first answer [s]
COUNT_RETRIES = 5  # resends of those before giving up
DUPLICATE_WINDOW_S = 0.15  # a request for an item sent more recently than this is a duplicate [s]
FINAL_ITEM_RETRIES = 5  # resends of the last item while waiting for MISSION_ACK
INACTIVITY_TIMEOUT_S = 10.0  # no message from the vehicle for this long ends the transfer [s]
DOWNLOAD_RETRIES = 8  # re-requests of one item during a download
DEADLINE_BASE_S = 20.0  # an upload ends after this [s] ...
DEADLINE_PER_ITEM_S = 1.0  # ... plus this per item [s], however busy the vehicle keeps it
RESTART_WINDOW_S = 0.25  # a request this much older than its first copy is a new session [s]
INITIAL_RTT_S = 0.1  # round-trip guess before the first measurement [s]
_REQUESTS = frozenset({"MISSION_REQUEST_INT", "MISSION_REQUEST"})
_ITEMS = frozenset({"MISSION_ITEM_INT", "MISSION_ITEM"})


@dataclass(frozen=True)
class Timing:
    """Timeouts and retries of one transfer; defaults follow the module docstring [s]."""

    count_retry_s: float = COUNT_RETRY_S
    count_retries: int = COUNT_RETRIES
    duplicate_window_s: float = DUPLICATE_WINDOW_S
    final_item_retries: int = FINAL_ITEM_RETRIES
    inactivity_timeout_s: float = INACTIVITY_TIMEOUT_S
    download_retries: int = DOWNLOAD_RETRIES
    initial_rtt_s: float = INITIAL_RTT_S
    ack_timeout_min_s: float = 0.3
    ack_timeout_max_s: float = 1.5
    item_timeout_min_s: float = 0.25
    item_timeout_max_s: float = 1.5
    push_ahead: bool = True  # False: wait for the vehicle's re-requests (the spec-literal client)
    push_rounds: int = 3
    push_timeout_min_s: float = 0.05
    push_timeout_max_s: float = 0.5
    push_rtts: float = 1.5  # a request this many smoothed RTTs overdue starts a push
    window: int = 16  # items in flight during an upload: 1 = answer each request only (the spec)
    batch: int = 8  # items per datagram: a wider window leaves in several, worked on in turn
    deadline_base_s: float = DEADLINE_BASE_S
    deadline_per_item_s: float = DEADLINE_PER_ITEM_S
    restart_window_s: float = RESTART_WINDOW_S
    # after an upload's ACK, how long to listen for the autopilot's own refusal (verdict.py);
    # None: as long as its autopilot may take (AutopilotQuirks.verdict_after_ack_s)
    verdict_s: float | None = None

    def bound_s(self, entries: int) -> float:
        """The overall deadline of a transfer of ``entries`` items [s] (module docstring)."""
        return self.deadline_base_s + self.deadline_per_item_s * entries

    def __post_init__(self) -> None:
        if self.window < 1:
            raise ValueError(f"Timing.window is {self.window}: at least one item must be in flight")
        if self.batch < 1:
            raise ValueError(f"Timing.batch is {self.batch}: a datagram holds at least one item")


@dataclass
class Stats:
    """What a transfer sent and ignored; tests count retries with it."""

    sent: dict[str, int] = field(default_factory=dict)
    duplicates_ignored: int = 0
    invalid_sequence_acks: int = 0
    rtt_s: float = 0.0

    def count(self, msgs: list[mavlink.MAVLink_message]) -> list[mavlink.MAVLink_message]:
        for m in msgs:
            name = m.get_type()
            self.sent[name] = self.sent.get(name, 0) + 1
        return msgs


@dataclass(frozen=True)
class Outcome:
    """How a transfer ended: ``error`` is None on success."""

    error: MissionError | None
    items: list[MissionItem] | None = None  # download result
    opaque_id: int = 0  # from the final MISSION_ACK (upload) or MISSION_COUNT (download)
    ack_lost: bool = False  # upload: every item sent, no MISSION_ACK came back


class Phase(Enum):
    START = auto()
    COUNT = auto()  # waiting for the first answer to COUNT / REQUEST_LIST / CLEAR_ALL / SET_CURRENT
    ITEMS = auto()
    FINAL_ACK = auto()  # upload: last item sent, waiting for MISSION_ACK
    DONE = auto()


class Transfer:
    """Shared machinery: target filter, deadline, RTT estimate, the single exit."""

    operation = "transfer"
    _accepted_types: frozenset[str] = frozenset()

    def __init__(
        self,
        sysid: int,
        compid: int = 1,
        mission_type: int = MissionType.MISSION,
        *,
        gcs_sysid: int = 255,
        gcs_compid: int = 190,
        timing: Timing | None = None,
    ) -> None:
        self.sysid = sysid
        self.compid = compid
        self.mission_type = int(mission_type)
        self.gcs = (gcs_sysid, gcs_compid)
        self.timing = timing or Timing()
        self.phase = Phase.START
        self.deadline_s: float | None = None
        self.outcome: Outcome | None = None
        self.stats = Stats()
        self._srtt_s = self.timing.initial_rtt_s
        self._rtt_measured = False
        self._retries = 0

    @property
    def done(self) -> bool:
        return self.phase is Phase.DONE

    def accepts(self, msg: mavlink.MAVLink_message) -> bool:
        """True for messages of this transfer: from the target, to us (or broadcast), same mission type."""
        return msg.get_type() in self._accepted_types and self._ours(
            (msg.get_srcSystem(), msg.get_srcComponent()),
            (getattr(msg, "target_system", 0), getattr(msg, "target_component", 0)),
            getattr(msg, "mission_type", self.mission_type),
        )

    def _ours(self, source: tuple[int, int], target: tuple[int, int], mission_type: int) -> bool:
        """From the target vehicle, to us (or broadcast), of this transfer's mission type."""
        if source != (self.sysid, self.compid):
            return False
        if target[0] not in (0, self.gcs[0]) or target[1] not in (0, self.gcs[1]):
            return False  # another GCS with our sysid: its requests and ACKs are not ours
        return mission_type == self.mission_type

    def start(self, now_s: float) -> list[mavlink.MAVLink_message]:
        raise NotImplementedError

    def on_message(self, msg: mavlink.MAVLink_message, now_s: float) -> list[mavlink.MAVLink_message]:
        if self.done or not self.accepts(msg):
            return []
        return self.stats.count(self._handle(msg, now_s))

    def on_timeout(self, now_s: float) -> list[mavlink.MAVLink_message]:
        if self.done or self.deadline_s is None or now_s < self.deadline_s:
            return []
        return self.stats.count(self._timeout(now_s))

    def cancel(self, now_s: float) -> list[mavlink.MAVLink_message]:
        """Abort on the user's request: tell the vehicle, end with a MissionError (OPERATION_CANCELLED)."""
        if self.done:
            return []
        what = mission_type_name(self.mission_type)
        msg = f"{self.operation} of the {what} on vehicle {self.sysid} cancelled"
        cancelled = MissionResult.OPERATION_CANCELLED
        self._finish(MissionError(msg, sysid=self.sysid, mission_type=self.mission_type, result=cancelled))
        return self.stats.count([self._ack(MissionResult.OPERATION_CANCELLED)])

    # ----------------------------------------------------------------- for subclasses
    def _handle(self, msg: mavlink.MAVLink_message, now_s: float) -> list[mavlink.MAVLink_message]:
        raise NotImplementedError

    def _timeout(self, now_s: float) -> list[mavlink.MAVLink_message]:
        raise NotImplementedError

    def _finish(self, error: MissionError | None = None, **kwargs: object) -> None:
        """The one exit: runs once, later calls are ignored."""
        if self.done:
            return
        self.phase = Phase.DONE
        self.deadline_s = None
        self.outcome = Outcome(error, **kwargs)  # type: ignore[arg-type]
        self.stats.rtt_s = self._srtt_s

    def _fail_timeout(self, what: str) -> list[mavlink.MAVLink_message]:
        kind = mission_type_name(self.mission_type)
        msg = f"vehicle {self.sysid}: {kind} {self.operation} timed out ({what})"
        self._finish(MissionTimeoutError(msg, sysid=self.sysid, mission_type=self.mission_type))
        return [self._ack(MissionResult.OPERATION_CANCELLED)]

    def _fail_result(self, result: int) -> None:
        self._finish(
            error_for_result(
                result, sysid=self.sysid, mission_type=self.mission_type, operation=self.operation
            )
        )

    def _ack(self, result: MissionResult) -> mavlink.MAVLink_message:
        return mavlink.MAVLink_mission_ack_message(self.sysid, self.compid, result, self.mission_type)

    def _rtt_sample(self, sample_s: float) -> None:
        """Smoothed RTT as TCP keeps it (RFC 6298): the first sample replaces the initial guess."""
        sample_s = max(sample_s, 0.0)
        self._srtt_s = 0.875 * self._srtt_s + 0.125 * sample_s if self._rtt_measured else sample_s
        self._rtt_measured = True

    def _adaptive(self, low_s: float, high_s: float, rtts: float = 4.0) -> float:
        return min(high_s, max(low_s, rtts * self._srtt_s))


class UploadTransfer(Transfer):
    """MISSION_COUNT -> answer requests with MISSION_ITEM_INT -> MISSION_ACK(ACCEPTED).

    ``partial=True``: MISSION_WRITE_PARTIAL_LIST instead of MISSION_COUNT, replacing the vehicle's
    items ``items[0].seq .. items[-1].seq`` only (ArduPilot supports it, PX4 answers UNSUPPORTED).
    Internally every position is an index into ``items``; ``first`` maps it to the wire seq.
    """

    operation = "upload"
    _accepted_types = frozenset({*_REQUESTS, "MISSION_ACK"})

    def __init__(
        self,
        sysid: int,
        items: Sequence[MissionItem],
        compid: int = 1,
        mission_type: int = MissionType.MISSION,
        *,
        partial: bool = False,
        **kwargs,
    ) -> None:
        super().__init__(sysid, compid, mission_type, **kwargs)
        self.items = tuple(items)
        self.partial = partial
        if partial:
            self.operation = "partial upload"
        if partial and not self.items:
            raise MissionInputError("a partial write needs at least one item", sysid=sysid)
        self.first = self.items[0].seq if partial else 0
        for index, item in enumerate(self.items):
            if item.seq != self.first + index:
                raise MissionInputError(
                    f"item {index}: seq is {item.seq}, expected {self.first + index}", sysid=sysid
                )
            if item.mission_type != self.mission_type:
                raise MissionInputError(
                    f"item {index}: mission_type is {item.mission_type}, transfer is for {self.mission_type}",
                    sysid=sysid,
                )
        if len(self.items) > 65535:
            raise MissionInputError(
                f"{len(self.items)} items: MISSION_COUNT holds at most 65535", sysid=sysid
            )
        self._sent_at = [math.nan] * len(self.items)
        self._first_request_s = [math.nan] * len(self.items)
        self._give_up_s = math.inf  # the overall deadline, set by start()
        self._last_request_s = 0.0
        self._count_sent_s = 0.0
        self._highest_sent = -1  # indexes into items from here on
        self._requested = -1  # the highest item the vehicle asked for
        self._pushes = 0  # push-ahead rounds since the last request
        self._skipped: set[int] = set()  # items the vehicle went past before we ever sent them
        self._stray: int | None = None  # the last request for an item outside this upload
        self._top_up = max(1, min(self.timing.batch, self.timing.window // 2))

    @property
    def never_requested(self) -> bool:
        """The vehicle never asked for an item of this upload (it stored nothing of it)."""
        return self._requested < 0

    @property
    def ack_lost_possible(self) -> bool:
        """Every item went out: the vehicle may have completed the upload (the ACK went missing)."""
        return self._highest_sent == len(self.items) - 1 >= 0

    def start(self, now_s: float) -> list[mavlink.MAVLink_message]:
        self.phase = Phase.COUNT
        self._retries = 0
        self._give_up_s = now_s + self.give_up_after_s
        self.deadline_s = min(now_s + self.timing.count_retry_s, self._give_up_s)
        self._count_sent_s = now_s
        return self.stats.count([self._count()])

    @property
    def give_up_after_s(self) -> float:
        """The overall deadline: Timing.deadline_base_s + deadline_per_item_s per item [s]."""
        return self.timing.bound_s(len(self.items))

    def on_message(self, msg: mavlink.MAVLink_message, now_s: float) -> list[mavlink.MAVLink_message]:
        out = super().on_message(msg, now_s)
        self._clamp()
        return out

    def on_timeout(self, now_s: float) -> list[mavlink.MAVLink_message]:
        out = super().on_timeout(now_s)
        self._clamp()
        return out

    def on_request(
        self, seq: int, source: tuple[int, int], target: tuple[int, int], mission_type: int, now_s: float
    ) -> list[int]:
        """A MISSION_REQUEST(_INT) given by its fields, for a caller that reads them from the frame
        without a message (mission.py): the indexes of the items to answer with, MISSION_ITEM_INT of
        ``items[k]`` each - what ``on_message`` answers the same request with, with the same checks."""
        if self.done or not self._ours(source, target, mission_type):
            return []
        due = self._on_request(seq, now_s)
        if due:
            self.stats.sent["MISSION_ITEM_INT"] = self.stats.sent.get("MISSION_ITEM_INT", 0) + len(due)
        self._clamp()
        return due

    def _clamp(self) -> None:
        if not self.done and self.deadline_s is not None:
            self.deadline_s = min(self.deadline_s, self._give_up_s)

    def _count(self) -> mavlink.MAVLink_message:
        if self.partial:
            return mavlink.MAVLink_mission_write_partial_list_message(
                self.sysid, self.compid, self.first, self.first + len(self.items) - 1, self.mission_type
            )
        return mavlink.MAVLink_mission_count_message(
            self.sysid, self.compid, len(self.items), self.mission_type
        )

    def _handle(self, msg: mavlink.MAVLink_message, now_s: float) -> list[mavlink.MAVLink_message]:
        if msg.get_type() == "MISSION_ACK":
            return self._on_ack(msg)
        return [self._item(k) for k in self._on_request(msg.seq, now_s)]

    def _on_request(self, seq: int, now_s: float) -> list[int]:
        """The vehicle asked for item ``seq``: the indexes of the items to send."""
        i = seq - self.first
        if not 0 <= i < len(self.items):
            log.warning("vehicle %d requested item %d, not in this upload: ignored", self.sysid, seq)
            self._stray = seq
            return []
        if self.phase is Phase.COUNT and i != 0:
            return []  # a session starts at its first item: this request answers someone else's COUNT
        first_s = self._first_request_s[i]
        if i < self._requested and now_s - first_s > max(self.timing.restart_window_s, 4 * self._srtt_s):
            what = mission_type_name(self.mission_type)
            text = (
                f"vehicle {self.sysid} went back to item {seq} after asking for item"
                f" {self._requested + self.first}: another GCS with our ids ({self.gcs[0]}/{self.gcs[1]})"
                f" restarted the {what} upload; give each GCS its own --gcs-sysid / --gcs-compid"
            )
            self._finish(MissionProtocolError(text, sysid=self.sysid, mission_type=self.mission_type))
            return []  # not ours any more: feed nothing into the other GCS's session
        if math.isnan(first_s):
            self._first_request_s[i] = now_s
        if self.phase is Phase.COUNT and self._retries == 0:  # unambiguous: COUNT went out once
            self._rtt_sample(now_s - self._count_sent_s)
        self._last_request_s = now_s
        self._pushes = 0
        if i > self._requested and i > 0 and not math.isnan(self._sent_at[i - 1]):
            self._rtt_sample(now_s - self._sent_at[i - 1])  # the first ask for i answers item i - 1
        # a request may skip items only where a lost request's item was already in flight: one never
        # sent cannot be stored, so the vehicle jumped past it (unless it comes back for it)
        sent_at = self._sent_at
        if i > self._requested + 1:
            self._skipped.update(k for k in range(self._requested + 1, i) if math.isnan(sent_at[k]))
        self._skipped.discard(i)
        self._requested = max(self._requested, i)
        window = range(i, min(i + self.timing.window, len(self.items)))
        if now_s - sent_at[i] < max(self.timing.duplicate_window_s, 2 * self._srtt_s):  # i is on its way
            if 0 < window.stop - 1 - self._highest_sent < self._top_up and window.stop < len(self.items):
                due = []  # the window is topped up a whole batch at a time
            else:
                due = [k for k in window if math.isnan(sent_at[k])]
                if not due:
                    self.stats.duplicates_ignored += 1
        else:  # i was never sent or was lost; what went after it was dropped: send the window again
            due = list(window)
        return self._send(due, now_s)

    def _send(self, sent: list[int], now_s: float) -> list[int]:
        """Items ``sent`` (ascending; returned), then the timer of the phase that follows.

        The final-ACK phase starts once the vehicle asked for the last item or a push sent it: a
        last item merely sent ahead in the window may still wait for a lost earlier one, which is
        the push timer's job, not the final-item timer's."""
        for k in sent:
            self._sent_at[k] = now_s
        last = len(self.items) - 1
        if sent:
            self._highest_sent = max(self._highest_sent, sent[-1])
        if self._highest_sent == last and (self._requested == last or self._pushes > 0):
            self.phase = Phase.FINAL_ACK
            self._retries = 0  # the vehicle is alive: the final-item retries start again
            self.deadline_s = now_s + self._adaptive(
                self.timing.ack_timeout_min_s, self.timing.ack_timeout_max_s
            )
        else:
            self.phase = Phase.ITEMS
            self.deadline_s = now_s + self.timing.inactivity_timeout_s
            if self._pushes < self.timing.push_rounds and self.timing.push_ahead:
                push_s = self._adaptive(
                    self.timing.push_timeout_min_s, self.timing.push_timeout_max_s, self.timing.push_rtts
                )
                self.deadline_s = min(self.deadline_s, now_s + push_s * 2**self._pushes)
        return sent

    def _on_ack(self, msg: mavlink.MAVLink_message) -> list[mavlink.MAVLink_message]:
        result = msg.type
        if result == MissionResult.ACCEPTED:
            if self.ack_lost_possible or (not self.items and self.phase is Phase.COUNT):
                missing = self._missing()
                if missing:
                    self._finish(
                        MissionProtocolError(
                            f"vehicle {self.sysid} ACKed the {mission_type_name(self.mission_type)} upload"
                            f" ACCEPTED without items {_seq_ranges([k + self.first for k in missing])}"
                            f" (never requested or never sent): it may hold a mix of old and new items",
                            sysid=self.sysid,
                            mission_type=self.mission_type,
                        )
                    )
                    return []
                self._finish(None, opaque_id=getattr(msg, "opaque_id", 0))
            return []  # before the last item went out: stale (e.g. a re-ack of an earlier upload)
        if result == MissionResult.INVALID_SEQUENCE:  # before our first item it is not about ours
            self.stats.invalid_sequence_acks += 1
            return []
        if result == MissionResult.ERROR and self._highest_sent == len(self.items) - 1 >= 0:
            # ArduPilot's answer to an item that arrives once the upload is complete (the last item
            # resent after a lost ACK, or a duplicate): the mission may be stored; mission.py reads
            # it back to know
            error = error_for_result(
                result, sysid=self.sysid, mission_type=self.mission_type, operation=self.operation
            )
            self._finish(error, ack_lost=True)
            return []
        self._fail_result(result)
        if self._requested >= 0 and result != MissionResult.OPERATION_CANCELLED:
            # the vehicle may still be inside the session (PX4 answers a second MISSION_COUNT of the
            # same ids with ERROR and keeps receiving): end it
            return [self._ack(MissionResult.OPERATION_CANCELLED)]
        return []

    def _missing(self) -> list[int]:
        """Items the vehicle cannot hold: skipped before we sent them, or never sent at all."""
        never = (k for k, t in enumerate(self._sent_at) if math.isnan(t))
        return sorted(self._skipped.union(never))

    def _timeout(self, now_s: float) -> list[mavlink.MAVLink_message]:
        if now_s >= self._give_up_s:
            return self._fail_timeout(
                f"not done within {self.give_up_after_s:g} s, the bound for {len(self.items)} items"
                f" ({self.timing.deadline_base_s:g} s + {self.timing.deadline_per_item_s:g} s per item)"
            )
        if self.phase is Phase.COUNT:
            if self._retries >= self.timing.count_retries:
                what = "MISSION_WRITE_PARTIAL_LIST" if self.partial else "MISSION_COUNT"
                if self._stray is not None:
                    return self._fail_timeout(
                        f"{what} sent {self._retries + 1} times; the vehicle asked only for items outside"
                        f" this upload's {self.first}-{self.first + len(self.items) - 1}, e.g. {self._stray}"
                    )
                return self._fail_timeout(f"no answer to {what} sent {self._retries + 1} times")
            self._retries += 1
            self.deadline_s = now_s + self.timing.count_retry_s
            return [self._count()]
        if self.phase is Phase.FINAL_ACK:
            if self._retries >= self.timing.final_item_retries:
                sends = self._retries + 1
                msg = f"vehicle {self.sysid}: no MISSION_ACK after the last item (sent {sends} times)"
                self._finish(
                    MissionTimeoutError(msg, sysid=self.sysid, mission_type=self.mission_type), ack_lost=True
                )
                return [self._ack(MissionResult.OPERATION_CANCELLED)]  # in case it still waits for it
            self._retries += 1
            last, r = len(self.items) - 1, self._requested
            resent = range(r, min(r + self.timing.window, last + 1)) if r < last else (last,)
            for k in resent:
                self._sent_at[k] = now_s
            self.deadline_s = now_s + self._adaptive(
                self.timing.ack_timeout_min_s, self.timing.ack_timeout_max_s
            )
            return [self._item(k) for k in resent]
        idle = now_s - self._last_request_s
        if (
            idle < self.timing.inactivity_timeout_s
            and self._pushes < self.timing.push_rounds
            and self.timing.push_ahead
        ):
            self._pushes += 1
            r = self._requested  # resend it and what followed it (dropped), and push ``pushes`` more
            end = min(r + self.timing.window + self._pushes, len(self.items))
            return [self._item(k) for k in self._send(list(range(r, end)), now_s)]
        if idle < self.timing.inactivity_timeout_s:  # pushes spent: wait for the vehicle
            self.deadline_s = self._last_request_s + self.timing.inactivity_timeout_s
            return []
        return self._fail_timeout(f"no request for {idle:.1f} s")

    def _item(self, i: int) -> mavlink.MAVLink_message:
        return mavlink.MAVLink_mission_item_int_message(self.sysid, self.compid, *self.items[i].fields())


def _seq_ranges(seqs: list[int], limit: int = 8) -> str:
    """Sorted seqs as "3-28, 30" (at most ``limit`` runs, then a count), to keep an error one short line."""
    runs: list[list[int]] = []
    for s in seqs:
        if runs and s == runs[-1][1] + 1:
            runs[-1][1] = s
        else:
            runs.append([s, s])
    text = ", ".join(f"{a}-{b}" if b > a else str(a) for a, b in runs[:limit])
    return text + (f" and {len(runs) - limit} more runs" if len(runs) > limit else "")


class DownloadTransfer(Transfer):
    """MISSION_REQUEST_LIST -> MISSION_COUNT -> MISSION_REQUEST_INT per item -> MISSION_ACK(ACCEPTED)."""

    operation = "download"
    _accepted_types = frozenset({"MISSION_COUNT", *_ITEMS, "MISSION_ACK"})

    def __init__(
        self, sysid: int, compid: int = 1, mission_type: int = MissionType.MISSION, **kwargs
    ) -> None:
        super().__init__(sysid, compid, mission_type, **kwargs)
        self._count = 0
        self._opaque_id = 0
        self._items: list[MissionItem] = []
        self._requested_at = 0.0
        self._give_up_s = math.inf  # the overall deadline, set by the vehicle's MISSION_COUNT

    def start(self, now_s: float) -> list[mavlink.MAVLink_message]:
        self.phase = Phase.COUNT
        self.deadline_s = now_s + self.timing.count_retry_s
        self._requested_at = now_s
        return self.stats.count([self._request_list()])

    def _request_list(self) -> mavlink.MAVLink_message:
        return mavlink.MAVLink_mission_request_list_message(self.sysid, self.compid, self.mission_type)

    def _handle(self, msg: mavlink.MAVLink_message, now_s: float) -> list[mavlink.MAVLink_message]:
        kind = msg.get_type()
        if kind == "MISSION_ACK":
            if msg.type != MissionResult.ACCEPTED:
                self._fail_result(msg.type)
            return []
        if kind == "MISSION_COUNT":
            if self.phase is not Phase.COUNT:
                return []  # duplicate COUNT
            self._rtt_sample(now_s - self._requested_at)
            self._count, self._opaque_id = msg.count, getattr(msg, "opaque_id", 0)
            self._give_up_s = now_s + self.timing.bound_s(self._count)
            if self._count == 0:
                self._finish(None, items=[], opaque_id=self._opaque_id)
                return [self._ack(MissionResult.ACCEPTED)]
            self.phase = Phase.ITEMS
            return [self._request_next(now_s)]
        if self.phase is not Phase.ITEMS or msg.seq != len(self._items):
            return []  # duplicate, stale or a seq we did not ask for: the timer re-requests
        if self._retries == 0:
            self._rtt_sample(now_s - self._requested_at)
        try:
            self._items.append(MissionItem.from_message(msg, self.mission_type))
        except ValueError as exc:  # a legacy float item MISSION_ITEM_INT cannot hold
            self._finish(MissionProtocolError(f"vehicle {self.sysid}: {exc}", sysid=self.sysid))
            return [self._ack(MissionResult.OPERATION_CANCELLED)]
        if len(self._items) == self._count:
            self._finish(None, items=list(self._items), opaque_id=self._opaque_id)
            return [self._ack(MissionResult.ACCEPTED)]
        return [self._request_next(now_s)]

    def _request_next(self, now_s: float) -> mavlink.MAVLink_message:
        self._retries = 0
        self._requested_at = now_s
        self._set_item_deadline(now_s)
        return self._request(len(self._items))

    def _set_item_deadline(self, now_s: float) -> None:
        """The next re-request, never after the overall deadline (a vehicle that answers each
        request just before its last retry would otherwise hold the download for hours)."""
        item_s = self._adaptive(self.timing.item_timeout_min_s, self.timing.item_timeout_max_s)
        self.deadline_s = min(now_s + item_s, self._give_up_s)

    def _request(self, seq: int) -> mavlink.MAVLink_message:
        return mavlink.MAVLink_mission_request_int_message(self.sysid, self.compid, seq, self.mission_type)

    def _timeout(self, now_s: float) -> list[mavlink.MAVLink_message]:
        if self.phase is Phase.COUNT:
            if self._retries >= self.timing.count_retries:
                return self._fail_timeout(f"no MISSION_COUNT after {self._retries + 1} requests")
            self._retries += 1
            self.deadline_s = now_s + self.timing.count_retry_s
            return [self._request_list()]
        if now_s >= self._give_up_s:
            limit_s = self.timing.bound_s(self._count)
            return self._fail_timeout(f"{len(self._items)} of {self._count} items in {limit_s:g} s")
        if self._retries >= self.timing.download_retries:
            return self._fail_timeout(
                f"item {len(self._items)} not received after {self._retries + 1} requests"
            )
        self._retries += 1
        self._set_item_deadline(now_s)
        return [self._request(len(self._items))]


class ClearTransfer(Transfer):
    """MISSION_CLEAR_ALL -> MISSION_ACK; mission_type ALL (255) clears the three lists."""

    operation = "clear"
    _accepted_types = frozenset({"MISSION_ACK"})

    def start(self, now_s: float) -> list[mavlink.MAVLink_message]:
        self.phase = Phase.COUNT
        self.deadline_s = now_s + self.timing.count_retry_s
        return self.stats.count([self._clear()])

    def _clear(self) -> mavlink.MAVLink_message:
        return mavlink.MAVLink_mission_clear_all_message(self.sysid, self.compid, self.mission_type)

    def _handle(self, msg: mavlink.MAVLink_message, now_s: float) -> list[mavlink.MAVLink_message]:
        if msg.type == MissionResult.ACCEPTED:
            self._finish(None)
        else:
            self._fail_result(msg.type)
        return []

    def _timeout(self, now_s: float) -> list[mavlink.MAVLink_message]:
        if self._retries >= self.timing.count_retries:
            return self._fail_timeout(f"no MISSION_ACK to MISSION_CLEAR_ALL sent {self._retries + 1} times")
        self._retries += 1
        self.deadline_s = now_s + self.timing.count_retry_s
        return [self._clear()]


class SetCurrentTransfer(Transfer):
    """Legacy MISSION_SET_CURRENT, confirmed by a MISSION_CURRENT carrying the new seq."""

    operation = "set-current"
    _accepted_types = frozenset({"MISSION_CURRENT"})

    def __init__(self, sysid: int, seq: int, compid: int = 1, **kwargs) -> None:
        super().__init__(sysid, compid, MissionType.MISSION, **kwargs)
        self.seq = seq

    def start(self, now_s: float) -> list[mavlink.MAVLink_message]:
        self.phase = Phase.COUNT
        self.deadline_s = now_s + self.timing.count_retry_s
        return self.stats.count([self._set()])

    def _set(self) -> mavlink.MAVLink_message:
        return mavlink.MAVLink_mission_set_current_message(self.sysid, self.compid, self.seq)

    def _handle(self, msg: mavlink.MAVLink_message, now_s: float) -> list[mavlink.MAVLink_message]:
        if msg.seq == self.seq:
            self._finish(None)
        return []

    def _timeout(self, now_s: float) -> list[mavlink.MAVLink_message]:
        if self._retries >= self.timing.count_retries:
            self._fail_timeout(f"MISSION_CURRENT never showed seq {self.seq}")
            return []
        self._retries += 1
        self.deadline_s = now_s + self.timing.count_retry_s
        return [self._set()]
