"""Async mission client: upload, download, clear and set-current for one vehicle over a MavlinkLink.

A thin wrapper around the I/O-free state machines in transfer.py: the response matcher is
subscribed before the first message is sent, replies are sent from inside the link's receive
callback (no task hop), and the only awaits are on the transfer's next deadline. One transfer per
(link, vehicle, mission type) at a time; a second one raises BusyError instead of interleaving.

Choices:
- Lost final ACK: when every item went out but no MISSION_ACK came back (ArduPilot never repeats
  it), the client downloads the list and reports success only if it matches what was sent
  (``UploadResult.ack_lost``); otherwise the timeout is raised.
- Verify-by-download compares through the autopilot's read-back model (readback.py: what it
  stores of each item, e.g. ArduPilot's cm altitude, its frame numbers, the params it drops) and
  otherwise exactly; on ArduPilot seq 0 is the vehicle's home and is not compared.
- Lost final ACK: ArduPilot answers a resent last item of a finished upload with
  MISSION_ACK(ERROR) (no upload in progress); after a resend that ERROR is read back like a
  missing ACK (transfer.py marks it ``ack_lost``), never reported as a refusal.
- Items in flight and push-ahead (transfer.py) send items the vehicle has not asked for, relying on
  the vehicle to drop an item whose seq it does not wait for. ArduPilot and PX4 do (their sources);
  MAVSDK's MissionRawServer stores every MISSION_ITEM_INT it receives, whatever its seq
  (``ReceiveIncomingMission::process_mission_item_int``), so a surplus copy on a lossy link would
  become a second item. The client therefore uses them only with vehicles whose HEARTBEAT says
  ArduPilot or PX4 (``AutopilotQuirks.pipelined``); with any other, or before a HEARTBEAT, it answers each
  request once (``Timing(push_ahead=False, window=1)``, the spec-literal client).
- clear(): MISSION_CLEAR_ALL; ALL list by list where the vehicle does not take mission_type 255
  (ArduPilot: UNSUPPORTED); when the vehicle answers ERROR or DENIED (ArduPilot in AUTO cannot
  clear) that is raised, and only ``force=True`` uploads an empty list instead (ArduPilot accepts it).
- A failed upload's error ends with what the vehicle holds now: unchanged when it refused
  the MISSION_COUNT, its previous list on an autopilot that switches lists on completion (PX4),
  otherwise what a read-back shows (ArduPilot writes items as they arrive).
- An upload answers requests without message objects: the link hands it MISSION_REQUEST(_INT)
  frames undecoded (``MavlinkLink.take``, once CRC and signature are checked), the transfer reads
  the seq, ids and mission type from them (``UploadTransfer.on_request``, the checks of
  ``accepts``), and each item's MISSION_ITEM_INT payload, packed once per upload, goes out with
  only its header, CRC and signature made per frame (``send_payload``): the same frames as the
  message path, about a third of its CPU per item (benchmarks/upload_hot_path.py).
- set_current(): MAV_CMD_DO_SET_MISSION_CURRENT first; if the vehicle does not support it (or never
  answers) the legacy MISSION_SET_CURRENT, confirmed by MISSION_CURRENT.
"""

from __future__ import annotations

import asyncio
import logging
import math
import weakref
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from typing import TypeVar

from pymavlink.dialects.v20 import ardupilotmega as mavlink

from gcs_planner.autopilots import GENERIC, AutopilotQuirks, quirks_for
from gcs_planner.core.fleet_ids import wire_sysid
from gcs_planner.core.lockstep import now_s
from gcs_planner.mavlink.errors import (
    BusyError,
    CommandError,
    CommandTimeoutError,
    MissionError,
    MissionInputError,
    MissionProtocolError,
    MissionRejectedError,
    VerifyError,
    mission_type_name,
)
from gcs_planner.mavlink.link import MavlinkLink
from gcs_planner.mavlink.transfer import (
    ClearTransfer,
    DownloadTransfer,
    Outcome,
    SetCurrentTransfer,
    Stats,
    Timing,
    Transfer,
    UploadTransfer,
)
from gcs_planner.mavlink.verdict import VerdictWatch
from gcs_planner.wire import codec
from gcs_planner.wire.enums import CommandResult, MissionResult
from gcs_planner.wire.types import MissionItem, MissionType

__all__ = ["MissionClient", "UploadResult", "compare_items"]

_active: weakref.WeakKeyDictionary[MavlinkLink, set[tuple[int, int]]] = weakref.WeakKeyDictionary()
_REQUESTS = (mavlink.MAVLINK_MSG_ID_MISSION_REQUEST_INT, mavlink.MAVLINK_MSG_ID_MISSION_REQUEST)
_REQUEST_FIELDS = mavlink.MAVLink_mission_request_int_message.unpacker  # seq, targets, type: both
_ITEM_INT = codec.packer(mavlink.MAVLink_mission_item_int_message)
T = TypeVar("T")

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class UploadResult:
    """A successful upload: the vehicle's plan id and how it went."""

    opaque_id: int  # 0 when the vehicle does not support plan ids
    count: int
    mission_type: int
    elapsed_s: float
    verified: bool = False  # read back and compared equal
    ack_lost: bool = False  # no MISSION_ACK came, the read-back proved the upload
    stats: Stats = field(default_factory=Stats)


class MissionClient:
    """Mission protocol with one vehicle (``sysid``/``compid``) over ``link``."""

    def __init__(
        self,
        link: MavlinkLink,
        sysid: int,
        compid: int = 1,
        *,
        timing: Timing | None = None,
    ) -> None:
        self.link = link
        self.sysid = sysid
        self.compid = compid
        self.timing = timing or Timing()

    # ----------------------------------------------------------------- operations
    async def upload(
        self,
        items: Sequence[MissionItem],
        mission_type: int = MissionType.MISSION,
        *,
        verify: bool = False,
        partial: bool = False,
    ) -> UploadResult:
        """Send ``items`` as the vehicle's list of ``mission_type``; returns once it said ACCEPTED.

        ``partial``: replace only the vehicle's items ``items[0].seq .. items[-1].seq`` (consecutive
        seqs) with MISSION_WRITE_PARTIAL_LIST, e.g. the legs ahead of a flying vehicle; a vehicle
        without partial writes (PX4) raises UnsupportedError and keeps its mission.

        Raises a MissionError subclass naming the vehicle's MAV_MISSION_RESULT, MissionTimeoutError,
        MissionInputError (malformed items, nothing sent), VerifyError (``verify`` and the read-back
        differs) or DuplicateSysidError.
        """
        items = list(items)
        t0 = now_s()
        transfer = self._transfer(UploadTransfer, items=items, mission_type=mission_type, partial=partial)
        judged = self.quirks if mission_type == MissionType.MISSION else GENERIC
        watch = VerdictWatch(self.link, self.sysid, judged, self.timing.verdict_s)
        try:
            outcome = await self._run(transfer)
            written = written_slice(transfer, items, partial)
            result = await self._accepted(transfer, outcome, items, written, verify, t0)
            rejection = await watch.rejection()
        finally:
            watch.close()
        if rejection is not None:
            raise MissionRejectedError(
                f"vehicle {self.sysid} REJECTED the mission after its ACK: {rejection!r}; it holds the"
                " mission but will not fly it",
                sysid=self.sysid,
                mission_type=mission_type,
            )
        return result

    async def _accepted(
        self, transfer: UploadTransfer, outcome: Outcome, items: list[MissionItem], written: slice,
        verify: bool, t0: float,
    ) -> UploadResult:  # fmt: skip
        """The transfer's outcome as an UploadResult, proved by a read-back where the ACK was lost
        or ``verify`` asks; raises what went wrong, with what the vehicle holds now."""
        mission_type = transfer.mission_type
        opaque_id, ack_lost, verified = outcome.opaque_id, False, False
        if outcome.error is not None:
            if not outcome.ack_lost:
                raise await self._what_it_holds(outcome.error, transfer, items, written)
            back, opaque_id, problem = await self._try_read_back(mission_type)
            if back is None or self._difference(items, back[written]) is not None:
                raise await self._what_it_holds(outcome.error, transfer, items, written, back, problem)
            ack_lost = verified = True
        if verify and not verified:
            back, _ = await self._read_back(mission_type, None)
            problem = self._difference(items, back[written])
            if problem is not None:
                raise VerifyError(
                    f"vehicle {self.sysid}: read-back differs: {problem}",
                    sysid=self.sysid,
                    mission_type=mission_type,
                )
            verified = True
        return UploadResult(
            opaque_id,
            len(items),
            int(mission_type),
            now_s() - t0,
            verified,
            ack_lost,
            transfer.stats,
        )

    async def download(self, mission_type: int = MissionType.MISSION) -> list[MissionItem]:
        """The vehicle's list of ``mission_type`` (as it stores it: rounded, home at seq 0 on ArduPilot)."""
        items, _ = await self.download_with_id(mission_type)
        return items

    async def download_with_id(
        self, mission_type: int = MissionType.MISSION
    ) -> tuple[list[MissionItem], int]:
        """(items, opaque_id from MISSION_COUNT; 0 if unsupported). A download during which the
        link had to reconnect (a SITL restarted, a vehicle rebooted) may hold items of two lists: it
        is made again from the start, once; never such a list."""
        for _ in range(2):
            reconnects = self.link.reconnects
            outcome = await self._run(self._transfer(DownloadTransfer, mission_type=mission_type))
            if outcome.error is not None:
                raise outcome.error
            if self.link.reconnects == reconnects:
                break
            log.warning("vehicle %d: the connection was made again during the download: again", self.sysid)
        else:
            raise MissionProtocolError(
                f"vehicle {self.sysid}: the connection was lost and made again during two"
                f" {mission_type_name(mission_type)} downloads, so their items may come from two lists",
                sysid=self.sysid,
                mission_type=mission_type,
            )
        return list(outcome.items or []), outcome.opaque_id

    async def clear(self, mission_type: int = MissionType.MISSION, *, force: bool = False) -> list[str]:
        """Empty the list (MissionType.ALL: all three); returns one note per list that needed the
        fallback below ([] when MISSION_CLEAR_ALL did it).

        ALL goes list by list to a vehicle that does not take mission_type 255 in one
        MISSION_CLEAR_ALL (ArduPilot answers UNSUPPORTED). A refusal (ERROR / DENIED: ArduPilot
        in AUTO) is raised, naming it; only with ``force`` is the list replaced by an empty upload
        instead (which ArduPilot accepts in AUTO), and the note says so."""
        types = (MissionType.MISSION, MissionType.FENCE, MissionType.RALLY)
        if mission_type == MissionType.ALL and not self.quirks.clear_all_at_once:
            return [note for t in types for note in await self.clear(t, force=force)]
        outcome = await self._run(self._transfer(ClearTransfer, mission_type=mission_type))
        error = outcome.error
        if error is None:
            return []
        result = getattr(error, "result", None)
        if mission_type == MissionType.ALL and result == MissionResult.UNSUPPORTED:
            return [note for t in types for note in await self.clear(t, force=force)]
        if result not in (MissionResult.ERROR, MissionResult.DENIED):
            raise error
        if not force:
            error.args = (
                f"{error}; the list is unchanged (e.g. ArduPilot refuses MISSION_CLEAR_ALL while it"
                " flies the mission in AUTO); --force uploads an empty list instead",
            )
            raise error
        notes = []
        for t in types if mission_type == MissionType.ALL else (mission_type,):
            await self.upload([], mission_type=t)
            notes.append(
                f"{mission_type_name(t)}: MISSION_CLEAR_ALL refused ({result.name}); cleared by uploading"
                " an empty list (--force)"
            )
        return notes

    async def set_current(self, seq: int) -> None:
        """Make mission item ``seq`` current (DO_SET_MISSION_CURRENT, else MISSION_SET_CURRENT)."""
        from gcs_planner.mavlink.command import CommandClient  # command.py imports this module

        try:
            await CommandClient(self.link, self.sysid, self.compid).set_mission_current(seq)
            return
        except CommandError as exc:
            if exc.result not in (CommandResult.UNSUPPORTED, CommandResult.COMMAND_INT_ONLY):
                raise
        except CommandTimeoutError:
            pass
        outcome = await self._run(self._transfer(SetCurrentTransfer, seq=seq))
        if outcome.error is not None:
            raise outcome.error

    # ----------------------------------------------------------------- machinery
    @property
    def quirks(self) -> AutopilotQuirks:
        """The vehicle's autopilot entry (GENERIC before its HEARTBEAT)."""
        info = self.link.vehicles.get(self.sysid)
        return GENERIC if info is None else quirks_for(info.autopilot, info.mav_type)

    def _transfer(self, cls: type[Transfer], **kwargs) -> Transfer:
        timing = self.timing
        if not self.quirks.pipelined:  # see the module docstring
            timing = replace(timing, push_ahead=False, window=1)
        return cls(
            self.sysid,
            compid=self.compid,
            gcs_sysid=self.link.sysid,
            gcs_compid=self.link.compid,
            timing=timing,
            **kwargs,
        )

    async def _run(self, transfer: Transfer) -> Outcome:
        """Drive one transfer to its end on the link; cancelling the task cancels the transfer."""
        self.link.check_target(self.sysid)
        key = (self.sysid, transfer.mission_type)
        active = _active.setdefault(self.link, set())
        if key in active:
            raise BusyError(
                f"vehicle {self.sysid}: a {mission_type_name(transfer.mission_type)} transfer is running",
                sysid=self.sysid,
                mission_type=transfer.mission_type,
            )
        loop = asyncio.get_running_loop()
        send = _in_batches(self.link.send, self.link.flush, transfer.timing.batch)
        wakeup = loop.create_future()
        armed_s = math.inf  # the deadline the waiting loop below wakes up at

        def due_s() -> float:
            return math.inf if transfer.deadline_s is None else transfer.deadline_s

        def rearm() -> None:
            if (transfer.done or due_s() < armed_s) and not wakeup.done():
                wakeup.set_result(None)  # finished, or a timer moved earlier: re-arm

        def on_frame(msg, raw: bytes, t_s: float) -> None:
            send(transfer.on_message(msg, loop.time()))  # [] for frames of other transfers
            rearm()

        active.add(key)
        unsubscribe = self.link.subscribe(on_frame, self.sysid)  # exists before the first send
        if isinstance(transfer, UploadTransfer):
            release = self.link.take(self.sysid, _REQUESTS, self._request_path(transfer, rearm), on_frame)
            unsubscribe = _both(release, unsubscribe)
        try:
            send(transfer.start(loop.time()))
            while not transfer.done:
                armed_s = due_s()
                delay = armed_s - loop.time()
                if delay > 0:
                    wakeup = loop.create_future()
                    await asyncio.wait([wakeup], timeout=delay)
                    continue
                with self.link.corked():  # a push's window leaves in batches, as answers do
                    send(transfer.on_timeout(loop.time()))
        except asyncio.CancelledError:
            send(transfer.cancel(loop.time()))
            raise
        finally:
            unsubscribe()
            active.discard(key)
        assert transfer.outcome is not None
        return transfer.outcome

    def _request_path(
        self, transfer: UploadTransfer, rearm: Callable[[], None]
    ) -> Callable[[bytes, float], None]:
        """The upload's answer to a MISSION_REQUEST(_INT) frame (module docstring)."""
        loop = asyncio.get_running_loop()
        send_payload = self.link.send_payload
        target = transfer.sysid
        wire = wire_sysid(target)  # its system id on its own network (a fleet id past network 0)
        payloads = [_ITEM_INT.pack(wire, transfer.compid, *item.fields()) for item in transfer.items]
        send_items = _in_batches(
            lambda k: send_payload(target, _ITEM_INT, payloads[k]), self.link.flush, transfer.timing.batch
        )

        def on_request(frame: bytes, t_s: float) -> None:
            seq, target_system, target_component, mission_type = codec.fields(frame, _REQUEST_FIELDS)
            source = (target, frame[6])  # the link takes the frames of the target's system only
            to = (target_system, target_component)
            send_items(transfer.on_request(seq, source, to, mission_type, loop.time()))
            rearm()

        return on_request

    async def _try_read_back(
        self, mission_type: int, attempts: int = 2
    ) -> tuple[list[MissionItem] | None, int, str | None]:
        """(items, opaque_id, None), or (None, 0, why) when every attempt failed."""
        problem = None
        for _ in range(attempts):
            try:
                items, opaque_id = await self.download_with_id(mission_type)
                return items, opaque_id, None
            except MissionError as exc:
                problem = str(exc)
        return None, 0, problem

    async def _what_it_holds(
        self,
        error: MissionError,
        transfer: UploadTransfer,
        items: Sequence[MissionItem],
        written: slice,
        back: list[MissionItem] | None = None,
        problem: str | None = None,
    ) -> MissionError:
        """``error`` with what the vehicle holds now appended: never a silent mix."""
        if isinstance(error, MissionInputError):
            return error
        q = self.quirks
        result = getattr(error, "result", None)
        if transfer.never_requested and result not in (None, MissionResult.OPERATION_CANCELLED):
            # both autopilots check a MISSION_COUNT before they truncate or store anything
            holds = "the vehicle's list is unchanged (it refused before asking for an item)"
        elif transfer.mission_type not in q.stores_as_received and not transfer.ack_lost_possible:
            holds = f"the vehicle keeps its previous list ({q.name} replaces a list only on completion)"
        else:
            if back is None and problem is None:
                back, _, problem = await self._try_read_back(transfer.mission_type)
            holds = _describe(items, None if back is None else back[written], q, problem)
        error.args = (f"{error}; {holds}",)
        error.holds = holds  # type: ignore[attr-defined]
        return error

    async def _read_back(
        self, mission_type: int, original: MissionError | None
    ) -> tuple[list[MissionItem], int]:
        try:
            return await self.download_with_id(mission_type)
        except MissionError:
            if original is not None:
                raise original from None
            raise

    def _difference(self, sent: Sequence[MissionItem], got: Sequence[MissionItem]) -> str | None:
        q = self.quirks
        return compare_items(sent, got, q.readback_model(), skip_home=q.home_at_seq0)


def _in_batches(
    send: Callable[[T], None], flush: Callable[[], None], batch: int
) -> Callable[[list[T]], None]:
    """``send`` for a transfer's replies, with a datagram boundary (``flush``) after every ``batch``
    while the link corks: an upload's window leaves in batches (transfer.py, items in flight)."""

    def send_all(replies: list[T]) -> None:
        for n, reply in enumerate(replies):
            if n and n % batch == 0:
                flush()
            send(reply)

    return send_all


def _both(first: Callable[[], None], second: Callable[[], None]) -> Callable[[], None]:
    def both() -> None:
        first()
        second()

    return both


def written_slice(transfer: UploadTransfer, items: Sequence[MissionItem], partial: bool) -> slice:
    """The part of the vehicle's list an upload writes: all of it, or a partial write's seqs."""
    return slice(transfer.first, transfer.first + len(items)) if partial else slice(None)


def _describe(
    sent: Sequence[MissionItem], got: Sequence[MissionItem] | None, q: AutopilotQuirks, problem: str | None
) -> str:
    """What the vehicle holds, in words, from a read-back ``got`` of the upload ``sent``."""
    if got is None:
        return f"what the vehicle holds is unknown: the read-back failed ({problem})"
    if compare_items(sent, got, q.readback_model(), skip_home=q.home_at_seq0) is None:
        return f"the vehicle holds this upload's {len(sent)} items (it stores items as they arrive)"
    real = [it for it in got if not (q.home_at_seq0 and it.seq == 0)]
    if not real:
        return "the vehicle now holds no items" + (" (only its home at seq 0)" if got else "")
    same = 0
    for a, b in zip(sent, got, strict=False):
        if compare_items([a], [b], q.readback_model(), skip_home=q.home_at_seq0) is not None:
            break
        same += 1
    home = 1 if q.home_at_seq0 and sent and sent[0].seq == 0 else 0
    start = sent[0].seq if sent else 0
    if same == len(got) < len(sent):
        return (
            f"the vehicle now holds only the first {same - home} of this upload's {len(sent) - home} items"
            " (it stores items as they arrive)"
        )
    if same - home > 0:
        kept = f"seq {start + home}-{start + same - 1} as sent, {len(got) - same} not from this upload"
    else:
        kept = "none of them from this upload"
    return f"the vehicle now holds a mixed list of {len(got)} items: {kept} (it stores items as they arrive)"


def compare_items(
    sent: Sequence[MissionItem],
    got: Sequence[MissionItem],
    model=None,
    skip_home: bool = False,
) -> str | None:
    """None if ``got`` is what an autopilot storing items as ``model`` returns for ``sent``, else
    the first difference in words. The model maps each item sent to the item the autopilot returns
    for it (in its own float32 / integer arithmetic); every field of the item downloaded must then
    equal it exactly, both rounded to what the wire carries (params and z float32). A NaN sent or
    expected ("use the default") accepts any value. ``model``: a readback.Model (default GENERIC)."""
    from gcs_planner.autopilots import readback  # numpy: loaded only when a list is compared

    model = readback.GENERIC if model is None else model
    home_only = skip_home and not sent and len(got) == 1  # ArduPilot keeps home after an empty upload
    if len(sent) != len(got) and not home_only:
        return f"{len(got)} items, expected {len(sent)}"
    for a, b in zip(sent, got, strict=False):
        if skip_home and a.seq == 0:
            continue
        want, b = model(a), readback.wire(b)
        for name in ("seq", "command", "frame", "x", "y", "autocontinue"):
            if getattr(want, name) != getattr(b, name):
                got_v, want_v, sent_v = getattr(b, name), getattr(want, name), getattr(a, name)
                return f"item {a.seq}: {name} is {got_v}, expected {want_v} (sent {sent_v})"
        for name in ("param1", "param2", "param3", "param4", "z"):
            sent_v, want_v, got_v = getattr(a, name), getattr(want, name), getattr(b, name)
            if not _close(sent_v, want_v, got_v):
                return f"item {a.seq}: {name} is {_full(got_v)}, expected {_full(want_v)} (sent {sent_v!r})"
    return None


def _close(sent: float, want: float, got: float) -> bool:
    """``got`` (float32) is ``want`` (float32) exactly; NaN sent or expected: any value."""
    if math.isnan(sent) or math.isnan(want):
        return True  # NaN means "use the default": the autopilot may store any value
    return got == want


def _full(v: float) -> str:
    """A float32 value at full precision: 65.36999511718750."""
    if v == 0 or not math.isfinite(v) or 1e-3 <= abs(v) < 1e9:
        return f"{v:.14f}" if math.isfinite(v) else repr(v)
    return f"{v:.17g}"
