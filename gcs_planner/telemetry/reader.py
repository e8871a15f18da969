"""read_flight: load a flight log (MCAP from FlightLogger or import-tlog) into arrays.

The file is read sequentially (``mcap.stream_reader.StreamReader``), not through the summary,
so a file whose writer was killed is read up to its last complete chunk: reading stops quietly
at the first incomplete or corrupt record, ``Flight.truncated`` is set and
``Flight.recovered_messages`` says how many messages were read. A complete file gives the same
result as an indexed read.

Positions, ground speed and mission progress are decoded from the raw frames (the lossless
channel) with pymavlink, so they do not depend on the JSON channels; the JSON channels are kept
as bytes and decoded on demand by ``Flight.messages``.
"""

from __future__ import annotations

import json
import logging
import os
from collections import defaultdict
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from mcap.records import Attachment, Channel, Footer, Message, Metadata
from mcap.stream_reader import StreamReader

from gcs_planner.geo import Origin
from gcs_planner.plan import Plan

os.environ.setdefault("MAVLINK20", "1")
from pymavlink.dialects.v20 import ardupilotmega as mavlink  # noqa: E402

__all__ = ["Flight", "RawFrame", "Track", "frame_msgid", "read_flight"]

log = logging.getLogger(__name__)

_POSITION_MSGIDS = {33, 42, 74}  # GLOBAL_POSITION_INT, MISSION_CURRENT, VFR_HUD


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
    home]; ground_speed_mps from vx, vy [m/s]; heading_deg [deg] (nan if unknown).
    """

    t_s: np.ndarray
    lat_deg: np.ndarray
    lon_deg: np.ndarray
    alt_m: np.ndarray
    rel_alt_m: np.ndarray
    ground_speed_mps: np.ndarray
    heading_deg: np.ndarray

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
        """Vehicles seen in the log (any frame), ascending."""
        self.frames_of(0)
        return sorted(self._by_sysid)

    @property
    def start_time_s(self) -> float:
        """Time of the first frame [s, Unix] (0 for an empty log); flight time counts from here."""
        return self.frames[0].t_ns * 1e-9 if self.frames else 0.0

    @property
    def end_time_s(self) -> float:
        return self.frames[-1].t_ns * 1e-9 if self.frames else 0.0

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


def frame_msgid(raw: bytes) -> int:
    """Message id from a MAVLink 2 or 1 frame header (-1 if too short)."""
    if len(raw) >= 10 and raw[0] == 0xFD:
        return raw[7] | (raw[8] << 8) | (raw[9] << 16)
    return raw[5] if len(raw) >= 6 else -1


def read_flight(path: str | Path) -> Flight:
    """Read a flight log; never raises on a truncated or corrupt tail (see module docstring)."""
    path = Path(path)
    flight = Flight(path=path)
    channels: dict[int, Channel] = {}
    raw_channels: dict[int, int] = {}
    json_channels: dict[int, tuple[int, str]] = {}
    event_channel = -1
    json_rows: dict[tuple[int, str], list[tuple[int, bytes]]] = defaultdict(list)
    complete = False
    with open(path, "rb") as stream:
        try:
            for record in StreamReader(stream, record_size_limit=1 << 31).records:
                if isinstance(record, Message):
                    flight.recovered_messages += 1
                    cid = record.channel_id
                    if cid in raw_channels:
                        flight.frames.append(RawFrame(record.log_time, raw_channels[cid], record.data))
                    elif cid in json_channels:
                        json_rows[json_channels[cid]].append((record.log_time, record.data))
                    elif cid == event_channel:
                        flight.events.append((record.log_time * 1e-9, json.loads(record.data)))
                elif isinstance(record, Channel):
                    if record.id in channels:
                        continue
                    channels[record.id] = record
                    parts = record.topic.split("/")
                    if len(parts) == 4 and parts[1] == "mavlink":
                        if parts[3] == "raw":
                            raw_channels[record.id] = int(parts[2])
                        else:
                            json_channels[record.id] = (int(parts[2]), parts[3])
                    elif record.topic == "/events":
                        event_channel = record.id
                elif isinstance(record, Attachment):
                    flight.attachments[record.name] = record.data
                elif isinstance(record, Metadata):
                    flight.metadata.setdefault(record.name, {}).update(record.metadata)
                elif isinstance(record, Footer):
                    complete = True
        except Exception as exc:  # noqa: BLE001 - a cut tail raises EndOfFile, struct, zstd or CRC errors
            flight.error = f"{type(exc).__name__}: {exc}"
    flight.truncated = not complete
    if flight.truncated:
        log.info(
            "%s: truncated log; recovered %d messages (%s)", path, flight.recovered_messages, flight.error
        )
    flight.frames.sort(key=lambda f: f.t_ns)
    flight._json = dict(json_rows)
    if "plan.json" in flight.attachments:
        flight.plan = Plan.from_dict(json.loads(flight.attachments["plan.json"]))
    if "scenario.toml" in flight.attachments:
        flight.scenario_text = flight.attachments["scenario.toml"].decode()
    _decode_positions(flight)
    return flight


def _decode_positions(flight: Flight) -> None:
    parser = mavlink.MAVLink(None)
    parser.robust_parsing = True
    rows: dict[int, list[tuple]] = defaultdict(list)
    mission: dict[int, list[tuple[float, int]]] = defaultdict(list)
    for f in flight.frames:
        msgid = frame_msgid(f.data)
        if msgid not in _POSITION_MSGIDS:
            continue
        try:
            msg = parser.decode(bytearray(f.data))
        except mavlink.MAVError:
            continue
        t_s = f.t_ns * 1e-9
        if msgid == 33:
            heading = msg.hdg / 100.0 if msg.hdg != 65535 else np.nan
            rows[f.sysid].append(
                (
                    t_s,
                    msg.lat * 1e-7,
                    msg.lon * 1e-7,
                    msg.alt * 1e-3,
                    msg.relative_alt * 1e-3,
                    float(np.hypot(msg.vx, msg.vy)) * 1e-2,
                    heading,
                )
            )
        elif msgid == 42:
            mission[f.sysid].append((t_s, msg.seq))
    for sysid, r in rows.items():
        a = np.asarray(r, dtype=float)
        flight.positions[sysid] = Track(*(a[:, i] for i in range(7)))
    for sysid, m in mission.items():
        a = np.asarray(m, dtype=float)
        flight.mission_current[sysid] = (a[:, 0], a[:, 1].astype(int))
