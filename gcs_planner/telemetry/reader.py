"""read_flight: load a flight log (MCAP from FlightLogger or import-tlog) into arrays.

The file is read sequentially (``mcap.stream_reader.StreamReader``), not through the summary,
so a file whose writer was killed is read up to its last complete chunk: reading stops quietly
at the first incomplete or corrupt record, ``Flight.truncated`` is set and
``Flight.recovered_messages`` says how many messages were read. A complete file gives the same
result as an indexed read. Our writer ends the file with a footer without summary after every
flush (mcap_writer) and with the summary only at close, so a log of ours that ends in a
summary-less footer is one whose writer did not close it: ``truncated`` too (another writer's
summary-less file is complete). Damage inside the file is skipped and counted, not read: a chunk
whose content fails the CRC its writer recorded (``Flight.damaged_chunks``), and messages whose log
time is more than MAX_SPREAD_S from the log's median frame time (``Flight.misplaced_messages``: one
flipped bit put a frame in 1970 or past 2^63 ns, and replay slept for decades or ran out of memory).

Positions, ground speed and mission progress are decoded from the raw frames (the lossless
channel) with pymavlink's own payload structs, so they do not depend on the JSON channels; the
JSON channels are kept as bytes and decoded on demand by ``Flight.messages``.

Flight time: receive times are the log's time base. ``Flight.clock_rate`` (seconds of flight per
second of receive time) turns them into flight time: the ``clock_rate`` the log's metadata
records (``fly`` writes the vehicles' rate: 1 in lockstep and for real vehicles, the speed-up of a
paced mock or a SITL), else, for logs without it (older logs, ``watch``, imports), the rate of the
vehicles' own ``time_boot_ms`` against the receive time (the median over vehicles), else 1.
"""

from __future__ import annotations

import json
import logging
import math
import os
import struct
import zlib
from collections import defaultdict
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import zstandard
from mcap.opcode import Opcode
from mcap.records import Attachment, Channel, Chunk, Footer, Header, Message, Metadata
from mcap.stream_reader import CRCValidationError, StreamReader, breakup_chunk

from gcs_planner.core.errors import UserError
from gcs_planner.core.geo import Origin
from gcs_planner.core.validation import load_json
from gcs_planner.model.plan import Plan
from gcs_planner.wire.units import no_fix, off_the_globe

os.environ.setdefault("MAVLINK20", "1")
from pymavlink.dialects.v20 import ardupilotmega as mavlink  # noqa: E402

__all__ = ["Flight", "RawFrame", "Track", "boot_clock_rate", "frame_msgid", "read_flight"]

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class RawFrame:
    """One received MAVLink frame: receive time [ns since Unix epoch], system id, exact bytes."""

    t_ns: int
    sysid: int
    data: bytes


@dataclass
class Track:
    """One vehicle's GLOBAL_POSITION_INT stream, as arrays of equal length.

    t_s: receive time [s, Unix]; lat_deg / lon_deg [deg]; alt_m [m AMSL]; rel_alt_m [m above
    home]; ground_speed_mps from vx, vy [m/s]; heading_deg [deg] (nan if unknown); time_boot_s:
    the vehicle's own clock (time_boot_ms) [s].
    """

    t_s: np.ndarray
    lat_deg: np.ndarray
    lon_deg: np.ndarray
    alt_m: np.ndarray
    rel_alt_m: np.ndarray
    ground_speed_mps: np.ndarray
    heading_deg: np.ndarray
    time_boot_s: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.t_s)


@dataclass
class Flight:
    """Everything read from one flight log; times are Unix seconds unless named otherwise."""

    path: Path
    metadata: dict[str, dict[str, str]] = field(default_factory=dict)
    plan: Plan | None = None
    scenario_text: str | None = None
    attachments: dict[str, bytes] = field(default_factory=dict)
    positions: dict[int, Track] = field(default_factory=dict)
    frames: list[RawFrame] = field(default_factory=list)
    events: list[tuple[float, dict]] = field(default_factory=list)
    mission_current: dict[int, tuple[np.ndarray, np.ndarray]] = field(default_factory=dict)
    recovered_messages: int = 0
    truncated: bool = False
    error: str | None = None
    damaged_chunks: int = 0
    misplaced_messages: int = 0
    _json: dict[tuple[int, str], list[tuple[int, bytes]]] = field(default_factory=dict, repr=False)
    _by_sysid: dict[int, list[RawFrame]] | None = field(default=None, repr=False)

    @property
    def origin(self) -> Origin | None:
        meta = self.metadata.get("gcs_planner")
        if meta and "origin" in meta:
            return Origin(**json.loads(meta["origin"]))
        return self.plan.origin if self.plan is not None else None

    @property
    def sysids(self) -> list[int]:
        """Vehicles seen in the log (any frame, ground stations excluded), ascending."""
        self.frames_of(0)
        return sorted(set(self._by_sysid) - set(self.gcs_sysids))

    @property
    def gcs_sysids(self) -> list[int]:
        """Ground stations in the log: systems whose HEARTBEAT says MAV_TYPE_GCS, and system 255
        (every GCS's default id) when it sent no HEARTBEAT at all. Kept, never replayed."""
        self.frames_of(0)
        kinds = {sysid: _heartbeat_type(frames) for sysid, frames in self._by_sysid.items()}
        gcs = mavlink.MAV_TYPE_GCS
        return sorted(
            s for s, kind in kinds.items() if kind == gcs or (kind is None and s == GCS_DEFAULT_SYSID)
        )

    @property
    def vehicle_frames(self) -> list[RawFrame]:
        """The frames of the vehicles, in receive order: what replay sends."""
        gcs = set(self.gcs_sysids)
        return self.frames if not gcs else [f for f in self.frames if f.sysid not in gcs]

    @property
    def start_time_s(self) -> float:
        """Time of the first frame [s, Unix] (0 for an empty log); flight time counts from here."""
        return self.frames[0].t_ns * 1e-9 if self.frames else 0.0

    @property
    def end_time_s(self) -> float:
        return self.frames[-1].t_ns * 1e-9 if self.frames else 0.0

    @property
    def clock_rate(self) -> float:
        """Seconds of flight per second of receive time (module docstring): the metadata's
        ``clock_rate``, else estimated from the vehicles' time_boot_ms, else 1."""
        recorded = self.metadata.get("gcs_planner", {}).get("clock_rate")
        if recorded is not None:
            try:
                rate = float(recorded)
            except ValueError:
                rate = 0.0
            if math.isfinite(rate) and rate > 0:
                return rate
            log.warning("%s: clock_rate %r in the metadata ignored", self.path, recorded)
        rate = boot_clock_rate(self.positions.values())
        return 1.0 if rate is None else rate

    def flight_time_s(self, t_s):
        """Receive time(s) [s, Unix] -> seconds of flight since the first frame (``clock_rate``)."""
        return (np.asarray(t_s, dtype=float) - self.start_time_s) * self.clock_rate

    def messages(self, msg_type: str, sysid: int | None = None) -> list[tuple[float, int, dict]]:
        """Decoded messages of one MAVLink type as (t_s, sysid, fields), in log order."""
        out = []
        for (sid, name), rows in self._json.items():
            if name == msg_type and (sysid is None or sid == sysid):
                out.extend((t_ns * 1e-9, sid, json.loads(data)) for t_ns, data in rows)
        out.sort(key=lambda r: r[0])
        return out

    def frames_of(self, sysid: int) -> list[RawFrame]:
        """One vehicle's raw frames in receive order (indexed once, on first use)."""
        if self._by_sysid is None:
            self._by_sysid = defaultdict(list)
            for f in self.frames:
                self._by_sysid[f.sysid].append(f)
        return self._by_sysid.get(sysid, [])

    def message_types(self) -> set[str]:
        return {name for _, name in self._json}

    def link_loss(self, sysid: int, window_s: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
        """Fraction of frames lost per window, from MAVLink sequence-number gaps per component.

        Returns (window end times [s, Unix], lost / expected in [0, 1]). Duplicates and
        reordering count as received (sequence wraps at 256).
        """
        last_seq: dict[int, int] = {}
        times, expected = [], []
        for f in self.frames_of(sysid):
            if len(f.data) < 7:
                continue
            v2 = f.data[0] == 0xFD
            seq, compid = (f.data[4], f.data[6]) if v2 else (f.data[2], f.data[4])
            gap = 1
            if compid in last_seq:
                gap = (seq - last_seq[compid]) % 256
                gap = gap if 0 < gap < 128 else 1
            last_seq[compid] = seq
            times.append(f.t_ns * 1e-9)
            expected.append(gap)
        received = np.ones(len(times))
        if not times:
            return np.zeros(0), np.zeros(0)
        t = np.asarray(times)
        bins = np.floor((t - t[0]) / window_s).astype(int)
        rec = np.bincount(bins, weights=received)
        exp = np.bincount(bins, weights=expected)
        keep = exp > 0
        ends = t[0] + (np.arange(len(rec)) + 1) * window_s
        return ends[keep], 1.0 - rec[keep] / exp[keep]


GCS_DEFAULT_SYSID = 255
MAX_SPREAD_S = 30 * 86_400.0  # a message this far from the log's median frame time is damage [s]
BOOT_RATE_MIN_SPAN_S = 1.0  # vehicle time (time_boot_ms) a vehicle's clock rate is estimated over [s]
BOOT_RATE_REAL_TIME = 0.05  # an estimate within 5 % of 1 is real time (link jitter, clock drift)


def boot_clock_rate(tracks) -> float | None:
    """The vehicles' clock rate against the receive time: the median over ``tracks`` (Track) of
    time_boot span / receive span, from each vehicle's first to last position report. A vehicle
    whose clock restarts (a reboot), or with under BOOT_RATE_MIN_SPAN_S of its own time in
    reports, is left out; None without one. Within BOOT_RATE_REAL_TIME of 1 it is taken as 1."""
    rates = []
    for track in tracks:
        boot = track.time_boot_s
        if boot is None or len(boot) < 2 or np.any(np.diff(boot) < 0):
            continue
        span_s = track.t_s[-1] - track.t_s[0]
        if boot[-1] - boot[0] >= BOOT_RATE_MIN_SPAN_S and span_s > 0:
            rates.append((boot[-1] - boot[0]) / span_s)
    if not rates:
        return None
    rate = float(np.median(rates))
    return 1.0 if abs(rate - 1.0) <= BOOT_RATE_REAL_TIME else rate


def _heartbeat_type(frames: list[RawFrame]) -> int | None:
    """MAV_TYPE of a system's first HEARTBEAT frame (payload byte 4), None without one."""
    for f in frames:
        raw = f.data
        if frame_msgid(raw) == mavlink.MAVLINK_MSG_ID_HEARTBEAT:
            start = 10 if raw[0] == 0xFD else 6
            if len(raw) > start + 4:
                return raw[start + 4]
    return None


def frame_msgid(raw: bytes) -> int:
    """Message id from a MAVLink 2 or 1 frame header (-1 if too short)."""
    if len(raw) >= 10 and raw[0] == 0xFD:
        return raw[7] | (raw[8] << 8) | (raw[9] << 16)
    return raw[5] if len(raw) >= 6 else -1


def read_flight(path: str | Path) -> Flight:
    """Read a flight log; never raises on a truncated or corrupt tail (see module docstring)."""
    path = Path(path)
    collector = _Collector(Flight(path=path))
    flight = collector.flight
    with open(path, "rb") as stream:
        try:
            for record in StreamReader(stream, emit_chunks=True, record_size_limit=1 << 31).records:
                if not isinstance(record, Chunk):
                    collector.record(record)
                    continue
                try:
                    rows = _chunk_messages(record)
                    inner = breakup_chunk(record, validate_crc=True) if rows is None else []
                except (CRCValidationError, zstandard.ZstdError, struct.error):
                    flight.damaged_chunks += 1
                    continue
                for channel_id, log_time, data in rows or []:
                    collector.message(channel_id, log_time, data)
                for each in inner:  # not only messages inside (another writer): the generic path
                    collector.record(each)
        except Exception as exc:  # noqa: BLE001 - a cut tail raises EndOfFile, struct, zstd or CRC errors
            flight.error = f"{type(exc).__name__}: {exc}"
    flight.truncated = not collector.complete or flight.error is not None
    if flight.truncated:
        log.info(
            "%s: truncated log; recovered %d messages (%s)", path, flight.recovered_messages, flight.error
        )
    _drop_misplaced(flight, collector)
    flight.frames.sort(key=lambda f: f.t_ns)
    flight._json = dict(collector.json_rows)
    _read_attachments(flight)
    _decode_positions(flight)
    return flight


def _drop_misplaced(flight: Flight, collector: _Collector) -> None:
    """Leave out frames, JSON messages and events more than MAX_SPREAD_S from the median frame time."""
    if not flight.frames:
        return
    times = sorted(f.t_ns for f in flight.frames)
    middle, spread = times[len(times) // 2], int(MAX_SPREAD_S * 1e9)
    frames = [f for f in flight.frames if abs(f.t_ns - middle) <= spread]
    dropped = len(flight.frames) - len(frames)
    flight.frames = frames
    for key, rows in collector.json_rows.items():
        kept = [r for r in rows if abs(r[0] - middle) <= spread]
        dropped += len(rows) - len(kept)
        collector.json_rows[key] = kept
    events = [e for e in flight.events if abs(e[0] - middle * 1e-9) <= MAX_SPREAD_S]
    flight.misplaced_messages = dropped + len(flight.events) - len(events)
    flight.events = events


def _read_attachments(flight: Flight) -> None:
    """The plan and scenario attachments; a damaged one is left out with a warning, not raised."""
    if "plan.json" in flight.attachments:
        try:
            text = flight.attachments["plan.json"].decode("utf-8")
            flight.plan = Plan.from_dict(load_json(text, "plan.json attachment"))
        except (UnicodeDecodeError, UserError) as exc:
            log.warning("%s: plan.json attachment ignored: %s", flight.path, exc)
    if "scenario.toml" in flight.attachments:
        try:
            flight.scenario_text = flight.attachments["scenario.toml"].decode("utf-8")
        except UnicodeDecodeError:
            log.warning("%s: scenario.toml attachment ignored: not UTF-8", flight.path)


class _Collector:
    """Sorts records of a flight log into a Flight as they are read."""

    def __init__(self, flight: Flight) -> None:
        self.flight = flight
        self.channels: dict[int, Channel] = {}
        self.raw_channels: dict[int, int] = {}
        self.json_channels: dict[int, tuple[int, str]] = {}
        self.event_channel = -1
        self.json_rows: dict[tuple[int, str], list[tuple[int, bytes]]] = defaultdict(list)
        self.complete = False
        self.ours = False  # written by gcs-planner's ChunkedMcapWriter (summary written at close)

    def message(self, channel_id: int, log_time: int, data: bytes) -> None:
        flight = self.flight
        flight.recovered_messages += 1
        sysid = self.raw_channels.get(channel_id)
        if sysid is not None:
            flight.frames.append(RawFrame(log_time, sysid, data))
        elif channel_id in self.json_channels:
            self.json_rows[self.json_channels[channel_id]].append((log_time, data))
        elif channel_id == self.event_channel:
            flight.events.append((log_time * 1e-9, json.loads(data)))

    def record(self, record) -> None:
        if isinstance(record, Message):
            self.message(record.channel_id, record.log_time, record.data)
        elif isinstance(record, Channel):
            if record.id in self.channels:
                return
            self.channels[record.id] = record
            parts = record.topic.split("/")
            if len(parts) == 4 and parts[1] == "mavlink":
                if parts[3] == "raw":
                    self.raw_channels[record.id] = int(parts[2])
                else:
                    self.json_channels[record.id] = (int(parts[2]), parts[3])
            elif record.topic == "/events":
                self.event_channel = record.id
        elif isinstance(record, Attachment):
            self.flight.attachments[record.name] = record.data
        elif isinstance(record, Metadata):
            self.flight.metadata.setdefault(record.name, {}).update(record.metadata)
        elif isinstance(record, Header):
            self.ours = record.library.startswith("gcs-planner")
        elif isinstance(record, Footer):
            # ours without summary: the provisional end of a log whose writer was killed
            self.complete = record.summary_start != 0 or not self.ours


_RECORD_HEAD = struct.Struct("<BQ")  # opcode, record length
_MESSAGE_HEAD = struct.Struct("<HIQ")  # channel id, sequence, log time (publish time follows)


def _chunk_messages(chunk: Chunk) -> list[tuple[int, int, bytes]] | None:
    """(channel id, log time, data) of a zstd/uncompressed chunk holding only messages, else None.

    The fast path for our own logs: no mcap Message object is built per record.
    """
    if chunk.compression == "zstd":
        data = zstandard.ZstdDecompressor().decompress(chunk.data, max_output_size=chunk.uncompressed_size)
    elif chunk.compression == "":
        data = chunk.data
    else:
        return None
    if chunk.uncompressed_crc and zlib.crc32(data) != chunk.uncompressed_crc:  # 0: none recorded
        raise CRCValidationError(expected=chunk.uncompressed_crc, actual=zlib.crc32(data), record=chunk)
    rows = []
    append = rows.append
    record_head, message_head = _RECORD_HEAD.unpack_from, _MESSAGE_HEAD.unpack_from
    pos, end = 0, len(data)
    while pos < end:
        opcode, length = record_head(data, pos)
        if opcode != Opcode.MESSAGE:
            return None
        channel_id, _, log_time = message_head(data, pos + 9)
        append((channel_id, log_time, data[pos + 9 + 22 : pos + 9 + length]))
        pos += 9 + length
    return rows


def _payload(raw: bytes, size: int) -> bytes | None:
    """A frame's payload padded to ``size`` (MAVLink 2 trims trailing zero bytes), or None if short.

    The CRC is not checked again: the raw channel holds frames the link already accepted.
    """
    start = 10 if raw[0] == 0xFD else 6
    payload = raw[start : start + raw[1]]
    if len(raw) < start + raw[1] + 2:
        return None
    return payload + bytes(size - len(payload)) if len(payload) < size else payload[:size]


_GPI = mavlink.MAVLink_global_position_int_message
_MISSION_CURRENT = mavlink.MAVLink_mission_current_message
_MISSION_SEQ = _MISSION_CURRENT.ordered_fieldnames.index("seq")


def _decode_positions(flight: Flight) -> None:
    """GLOBAL_POSITION_INT and MISSION_CURRENT from the raw frames, unpacked with pymavlink's structs."""
    gpi_unpack, gpi_size = _GPI.unpacker.unpack, _GPI.unpacker.size
    mc_unpack, mc_size = _MISSION_CURRENT.unpacker.unpack, _MISSION_CURRENT.unpacker.size
    gpi_index = [_GPI.ordered_fieldnames.index(n) for n in _GPI.fieldnames]
    rows: dict[int, list[tuple]] = defaultdict(list)
    mission: dict[int, list[tuple[float, int]]] = defaultdict(list)
    for f in flight.frames:
        msgid = frame_msgid(f.data)
        if msgid == 33:
            payload = _payload(f.data, gpi_size)
            if payload is not None:
                values = gpi_unpack(payload)
                rows[f.sysid].append((f.t_ns, *(values[i] for i in gpi_index)))
        elif msgid == 42:
            payload = _payload(f.data, mc_size)
            if payload is not None:
                mission[f.sysid].append((f.t_ns * 1e-9, mc_unpack(payload)[_MISSION_SEQ]))
    for sysid, r in rows.items():
        # columns: t_ns, time_boot_ms, lat, lon, alt, relative_alt, vx, vy, vz, hdg
        a = np.asarray(r, dtype=np.int64)
        a = a[~(no_fix(a[:, 2] * 1e-7, a[:, 3] * 1e-7) | off_the_globe(a[:, 2], a[:, 3]))]  # no position
        if not len(a):
            continue
        hdg = a[:, 9].astype(float)
        flight.positions[sysid] = Track(
            t_s=a[:, 0] * 1e-9,
            lat_deg=a[:, 2] * 1e-7,
            lon_deg=a[:, 3] * 1e-7,
            alt_m=a[:, 4] * 1e-3,
            rel_alt_m=a[:, 5] * 1e-3,
            ground_speed_mps=np.hypot(a[:, 6], a[:, 7]) * 1e-2,
            heading_deg=np.where(hdg == 65535, np.nan, hdg / 100.0),
            time_boot_s=a[:, 1] * 1e-3,
        )
    for sysid, m in mission.items():
        a = np.asarray(m, dtype=float)
        flight.mission_current[sysid] = (a[:, 0], a[:, 1].astype(int))
