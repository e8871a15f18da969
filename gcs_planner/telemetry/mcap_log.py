"""FlightLogger: record a flight's MAVLink traffic, plan and scenario to one MCAP file.

Layout (topics; ``{sysid}`` is the vehicle's MAVLink system id; in a flight over several networks
its fleet id, network x 256 + sysid (mavlink/networks.py), while its raw frames keep the system id
they had on their network):

- ``/mavlink/{sysid}/raw``: every frame exactly as received (encoding "mavlink", no schema);
  log time = receive time. This is the lossless record that replay re-emits byte for byte.
- ``/mavlink/{sysid}/{MSG_NAME}``: the decoded message as JSON (schema "mavlink.MSG_NAME",
  generated from pymavlink's definitions, see gcs_planner.telemetry.schemas).
- ``/vehicle/{sysid}/location``: foxglove.LocationFix from each GLOBAL_POSITION_INT
  (altitude AMSL, see schemas.ALTITUDE_DATUMS), colour per vehicle.
- ``/plan/routes`` and ``/scenario/obstacles``: foxglove.GeoJSON, written once at the start.
- ``/events``: planner/flight events from ``log_event`` (JSON objects).
- Attachments ``plan.json`` and ``scenario.toml``; metadata ``gcs_planner`` (tool version,
  origin, vehicles, altitude datums, time base, and ``clock_rate`` when the caller knows it) at
  the start and ``gcs_planner.summary`` (frames per vehicle) at close.

Hot path: ``on_frame`` only appends to a list under a lock. The list is encoded (JSON from
per-type templates, see encode.py), written into the open chunk and flushed as a zstd chunk by a
background thread every ``flush_interval_s`` (default 0.5 s, so chunks reach the disk at least
once a second), or by the caller when ``max_pending`` frames are waiting. Nothing is dropped:
the pending list is unbounded in time but bounded in size by the synchronous drain.

Time base: ``t_s`` is the receive time [s]. Unix time is expected (``time.time()``); a clock
that is clearly not Unix time (< 1e9 s, e.g. ``loop.time()`` or a test's fake clock) is shifted
once by a constant offset so that its first value maps to the wall clock at that moment.
MCAP log times are integer nanoseconds since the Unix epoch, rounded to whole microseconds: a
float Unix time resolves only ~0.24 us, .tlog stores microseconds, and the sub-microsecond
digits would be incompressible noise in every record header.

``clock_rate``: seconds of flight (the vehicles' clocks) per second of receive time, as the
flight assumed it: 1 in lockstep (the receive time is already the virtual flight time) and for
real vehicles, the speed-up of a paced mock or a SITL (wall-clock receive times). Readers turn
receive times into flight time with it (``Flight.clock_rate``, the Rerun timeline).
"""

from __future__ import annotations

import json
import logging
import struct
import threading
import time
import tomllib
from collections.abc import Callable
from pathlib import Path
from typing import IO

import numpy as np

from gcs_planner import __version__
from gcs_planner.core.fleet_ids import network_of
from gcs_planner.core.geo import Origin, enu_to_geodetic
from gcs_planner.core.lockstep import unix_s
from gcs_planner.model.plan import Plan
from gcs_planner.telemetry.colors import vehicle_color
from gcs_planner.telemetry.encode import json_encoder
from gcs_planner.telemetry.mcap_writer import (
    MESSAGE_FIXED_LEN,
    MESSAGE_HEADER,
    MESSAGE_OPCODE,
    ChunkedMcapWriter,
)
from gcs_planner.telemetry.schemas import (
    ALTITUDE_DATUMS,
    EVENT_SCHEMA,
    GEOJSON_SCHEMA,
    LOCATION_FIX_SCHEMA,
    mavlink_json_schema,
    record_json_schema,
    schema_bytes,
)
from gcs_planner.wire.units import reports_no_fix

__all__ = ["FlightLogger", "tlog_network_path"]

log = logging.getLogger(__name__)

_TLOG_TIME = struct.Struct(">Q")
_UNIX_TIME_MIN_S = 1e9  # 2001-09-09: anything smaller is a monotonic or fake clock
_COVARIANCE_ZERO = "[0,0,0,0,0,0,0,0,0]"
_CIRCLE_POINTS = 48


class FlightLogger:
    """Context manager writing one flight's MCAP log (and optionally a classic .tlog).

    path: MCAP file path or a binary stream (closed only if we opened it).
    origin: the scenario origin (ENU frame of the plan and obstacles).
    plan / scenario_text: stored as attachments and drawn as GeoJSON on the map.
    tlog_path: also write the .tlog stream (8-byte big-endian Unix time [us] + raw frame). A tlog
    holds one MAVLink network, where system ids are unique: the frames of fleet ids on network
    n > 0 go to ``tlog_network_path(tlog_path, n)`` beside it.
    clock_rate: seconds of flight per second of receive time (module docstring), written to the
    ``gcs_planner`` metadata when given; None (unknown, e.g. ``watch``): not written.
    """

    def __init__(
        self,
        path: str | Path | IO[bytes],
        origin: Origin,
        plan: Plan | None = None,
        scenario_text: str | None = None,
        tlog_path: str | Path | None = None,
        flush_interval_s: float = 0.5,
        max_pending: int = 20_000,
        zstd_level: int = 3,
        clock_rate: float | None = None,
    ) -> None:
        if clock_rate is not None and not clock_rate > 0:
            raise ValueError(f"clock_rate must be > 0, got {clock_rate}")
        self.origin = origin
        self.clock_rate = clock_rate
        self.plan = plan
        self.scenario_text = scenario_text
        self.flush_interval_s = flush_interval_s
        self.max_pending = max_pending
        self._writer = ChunkedMcapWriter(path, zstd_level=zstd_level, library=f"gcs-planner {__version__}")
        self._tlog_path = Path(tlog_path) if tlog_path is not None else None
        self._tlogs: dict[int, IO[bytes]] = {}
        if self._tlog_path is not None:
            self._tlogs[0] = open(self._tlog_path, "wb")  # noqa: SIM115
        self._pending: list[tuple[float, object, bytes]] = []
        self._lock = threading.Lock()  # guards _pending
        self._write_lock = threading.Lock()  # guards the writers
        self._clock_offset_s: float | None = None
        self._raw_channels: dict[int, int] = {}
        self._json_channels: dict[tuple[int, type], tuple[int, Callable[[object], bytes] | None, bool]] = {}
        self._location_channels: dict[int, int] = {}
        self._fix_template: dict[int, str] = {}
        self._schema_ids: dict[type, int] = {}
        self._frames_per_sysid: dict[int, int] = {}
        self._event_channel = 0
        self._record_channels: dict[str, int] = {}
        self._closed = False
        self._stop = threading.Event()
        self._start_ns = time.time_ns()
        self._write_header()
        self._thread = threading.Thread(target=self._flush_loop, name="flight-logger", daemon=True)
        self._thread.start()

    # -- public API ------------------------------------------------------------------------------
    def __enter__(self) -> FlightLogger:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def on_frame(self, msg, raw: bytes, t_s: float) -> None:
        """Record one received frame; matches MavlinkLink.subscribe's callback (msg, raw, t_s).

        Thread-safe and cheap (queues only). Frames arriving after close() are ignored, so a link
        subscription may outlive the logger.
        """
        if self._closed:
            return
        with self._lock:
            self._pending.append((t_s, msg, raw))
            drain = len(self._pending) >= self.max_pending
        if drain:
            self.flush()

    def log_event(self, event: dict, t_s: float | None = None) -> None:
        """Record a planner/flight event (a JSON-serialisable dict) at ``t_s`` (default: now)."""
        if self._closed:
            raise RuntimeError("FlightLogger.log_event after close()")
        data = json.dumps(event, separators=(",", ":"), default=str).encode()
        t_ns = self._to_ns(unix_s() if t_s is None else t_s)
        with self._write_lock:
            self._writer.add_message(self._event_channel, t_ns, data)

    def log_record(self, topic: str, schema_title: str, fields: dict, t_s: float) -> None:
        """Record one non-MAVLink record (a DataFlash or ULog message) as JSON on ``topic``; the
        channel and a schema from the first record's fields are registered on first use."""
        channel = self._record_channels.get(topic)
        with self._write_lock:
            if channel is None:
                schema = record_json_schema(schema_title, fields)
                schema_id = self._writer.register_schema(schema_title, "jsonschema", schema_bytes(schema))
                channel = self._writer.register_channel(topic, "json", schema_id)
                self._record_channels[topic] = channel
            data = json.dumps(fields, separators=(",", ":"), default=str).encode()
            self._writer.add_message(channel, self._to_ns(t_s), data)

    def add_metadata(self, name: str, values: dict[str, str]) -> None:
        """An MCAP metadata record (string values), e.g. what an import made of its source."""
        with self._write_lock:
            self._writer.add_metadata(name, {k: str(v) for k, v in values.items()})

    def flush(self) -> None:
        """Encode pending frames and write them as one complete chunk (and to the .tlog)."""
        with self._lock:
            batch, self._pending = self._pending, []
        with self._write_lock:
            if batch:
                self._encode(batch)
            self._writer.flush()
            for tlog in self._tlogs.values():
                tlog.flush()

    @property
    def frames_logged(self) -> int:
        return sum(self._frames_per_sysid.values())

    def close(self) -> None:
        """Flush, write the summary and close; idempotent."""
        if self._closed:
            return
        self._closed = True
        self._stop.set()
        self._thread.join()
        self.flush()
        with self._write_lock:
            self._writer.add_metadata(
                "gcs_planner.summary",
                {
                    "frames_per_sysid": {str(k): v for k, v in sorted(self._frames_per_sysid.items())},
                    "end_time_ns": str(time.time_ns()),
                },
            )
            self._writer.finish()
            for tlog in self._tlogs.values():
                tlog.close()

    @property
    def tlog_paths(self) -> list[Path]:
        """The .tlog files written, network 0's first."""
        return [tlog_network_path(self._tlog_path, n) for n in sorted(self._tlogs)] if self._tlog_path else []

    # -- internals -------------------------------------------------------------------------------
    def _flush_loop(self) -> None:
        while not self._stop.wait(self.flush_interval_s):
            try:
                self.flush()
            except Exception:  # keep logging alive; the error is reported once per interval
                log.exception("flight logger flush failed")

    def _to_ns(self, t_s: float) -> int:
        if t_s < _UNIX_TIME_MIN_S:
            if self._clock_offset_s is None:
                self._clock_offset_s = unix_s() - t_s
            t_s += self._clock_offset_s
        return round(t_s * 1e6) * 1000

    def _encode(self, batch: list[tuple[float, object, bytes]]) -> None:
        """Encode a batch into the open chunk, records grouped by channel (better compression).

        Message records are packed here directly (header struct from mcap_writer) into one list
        per channel: no intermediate row tuples, no sort.
        """
        raw_channels = self._raw_channels
        json_channels = self._json_channels
        counts = self._frames_per_sysid
        buckets: dict[int, list[bytes]] = {}
        times: list[int] = []
        tlog_parts: dict[int, list[bytes]] = {}
        tlog = self._tlog_path is not None
        header = MESSAGE_HEADER.pack
        opcode, fixed = MESSAGE_OPCODE, MESSAGE_FIXED_LEN
        for t_s, msg, raw in batch:
            t_ns = round(t_s * 1e6) * 1000 if t_s >= _UNIX_TIME_MIN_S else self._to_ns(t_s)
            times.append(t_ns)
            raw = bytes(raw)
            if msg is not None:  # its fleet id (mavlink/networks.py) where several networks share a log
                sysid = msg.get_srcSystem()
            else:
                sysid = raw[5] if raw[0] == 0xFD and len(raw) > 5 else _frame_sysid(raw)
            channel = raw_channels.get(sysid)
            if channel is None:
                channel = self._add_vehicle(sysid)
            bucket = buckets.get(channel) or buckets.setdefault(channel, [])
            bucket.append(header(opcode, fixed + len(raw), channel, 0, t_ns, t_ns))
            bucket.append(raw)
            counts[sysid] += 1
            if tlog:
                network = network_of(sysid)
                parts = tlog_parts.get(network) or tlog_parts.setdefault(network, [])
                parts.append(_TLOG_TIME.pack((t_ns // 1000) & ~3))
                parts.append(raw)
            if msg is None:
                continue
            entry = json_channels.get((sysid, type(msg)))
            if entry is None:
                entry = self._add_json_channel(sysid, type(msg))
            channel, encoder, is_position = entry
            if encoder is None:
                continue
            data = encoder(msg)
            bucket = buckets.get(channel) or buckets.setdefault(channel, [])
            bucket.append(header(opcode, fixed + len(data), channel, 0, t_ns, t_ns))
            bucket.append(data)
            if is_position and not reports_no_fix(msg):  # (0, 0) before a fix: no place on a map
                channel = self._location_channels[sysid]
                data = self._location_fix(sysid, msg, t_ns)
                bucket = buckets.get(channel) or buckets.setdefault(channel, [])
                bucket.append(header(opcode, fixed + len(data), channel, 0, t_ns, t_ns))
                bucket.append(data)
        if times:
            self._writer.add_packed(buckets, min(times), max(times))
        for network, parts in tlog_parts.items():
            self._tlog(network).write(b"".join(parts))

    def _tlog(self, network: int) -> IO[bytes]:
        file = self._tlogs.get(network)
        if file is None:
            file = self._tlogs[network] = open(tlog_network_path(self._tlog_path, network), "wb")  # noqa: SIM115
        return file

    def _location_fix(self, sysid: int, msg, t_ns: int) -> bytes:
        """foxglove.LocationFix JSON; degE7 and mm printed with 7 and 3 decimals (exact)."""
        sec, nsec = divmod(t_ns, 1_000_000_000)
        values = (sec, nsec, msg.lat * 1e-7, msg.lon * 1e-7, msg.alt * 1e-3)
        return (self._fix_template[sysid] % values).encode()

    def _add_vehicle(self, sysid: int) -> int:
        w = self._writer
        channel = w.register_channel(f"/mavlink/{sysid}/raw", "mavlink", 0, {"sysid": str(sysid)})
        self._raw_channels[sysid] = channel
        self._frames_per_sysid[sysid] = 0
        r, g, b = vehicle_color(sysid)[:3]
        self._fix_template[sysid] = (
            f'{{"timestamp":{{"sec":%d,"nsec":%d}},"frame_id":"vehicle{sysid}",'
            f'"latitude":%.7f,"longitude":%.7f,"altitude":%.3f,'
            f'"position_covariance":{_COVARIANCE_ZERO},"position_covariance_type":0,'
            f'"color":{{"r":{r / 255:.3f},"g":{g / 255:.3f},"b":{b / 255:.3f},"a":1}}}}'
        )
        self._location_channels[sysid] = w.register_channel(
            f"/vehicle/{sysid}/location",
            "json",
            self._location_schema,
            {"sysid": str(sysid), "altitude_datum": ALTITUDE_DATUMS["foxglove.LocationFix.altitude"]},
        )
        return channel

    def _add_json_channel(self, sysid: int, cls: type) -> tuple[int, Callable[[object], bytes] | None, bool]:
        """(channel, encoder, is GLOBAL_POSITION_INT) of one vehicle's message type; no channel
        (encoder None) for pseudo-messages without fields such as pymavlink's BAD_DATA."""
        if not getattr(cls, "fieldnames", None) or not hasattr(cls, "msgname"):
            entry = self._json_channels[(sysid, cls)] = (0, None, False)
            return entry
        schema_id = self._schema_ids.get(cls)
        if schema_id is None:
            schema = mavlink_json_schema(cls)
            schema_id = self._writer.register_schema(schema["title"], "jsonschema", schema_bytes(schema))
            self._schema_ids[cls] = schema_id
        channel = self._writer.register_channel(
            f"/mavlink/{sysid}/{cls.msgname}", "json", schema_id, {"sysid": str(sysid)}
        )
        entry = self._json_channels[(sysid, cls)] = (
            channel,
            json_encoder(cls),
            cls.msgname == "GLOBAL_POSITION_INT",
        )
        return entry

    def _write_header(self) -> None:
        w = self._writer
        self._location_schema = w.register_schema(
            "foxglove.LocationFix", "jsonschema", schema_bytes(LOCATION_FIX_SCHEMA)
        )
        geojson_schema = w.register_schema("foxglove.GeoJSON", "jsonschema", schema_bytes(GEOJSON_SCHEMA))
        event_schema = w.register_schema("gcs_planner.Event", "jsonschema", schema_bytes(EVENT_SCHEMA))
        self._event_channel = w.register_channel("/events", "json", event_schema)
        o = self.origin
        planned = [v.sysid for v in self.plan.vehicles] if self.plan is not None else []
        rate = {} if self.clock_rate is None else {"clock_rate": repr(float(self.clock_rate))}
        w.add_metadata(
            "gcs_planner",
            {
                "tool": "gcs-planner",
                "tool_version": __version__,
                "origin": {"lat_deg": o.lat_deg, "lon_deg": o.lon_deg, "alt_m": o.alt_m},
                "vehicles": planned,
                "planner": self.plan.planner if self.plan is not None else "",
                "altitude_datums": ALTITUDE_DATUMS,
                "time_base": "MCAP log_time = receive time, ns since Unix epoch",
                "start_time_ns": str(self._start_ns),
                **rate,
            },
        )
        if self.plan is not None:
            w.add_attachment("plan.json", "application/json", self.plan.to_json().encode(), self._start_ns)
            routes = w.register_channel("/plan/routes", "json", geojson_schema)
            w.add_message(routes, self._start_ns, _geojson_message(_plan_geojson(self.plan, o)))
        if self.scenario_text is not None:
            w.add_attachment("scenario.toml", "application/toml", self.scenario_text.encode(), self._start_ns)
            features = _obstacle_features(self.scenario_text, o)
            if features:
                obstacles = w.register_channel("/scenario/obstacles", "json", geojson_schema)
                collection = {"type": "FeatureCollection", "features": features}
                w.add_message(obstacles, self._start_ns, _geojson_message(collection))
        w.flush()


def tlog_network_path(path: Path, network: int) -> Path:
    """Network 0's .tlog is ``path``; network n's is ``flight.net{n}.tlog`` beside it."""
    return path if network == 0 else path.with_name(f"{path.stem}.net{network}{path.suffix}")


def _frame_sysid(raw: bytes) -> int:
    """System id from a MAVLink 2 (0xFD) or 1 (0xFE) frame header; 0 if the frame is too short."""
    if len(raw) > 5 and raw[0] == 0xFD:
        return raw[5]
    return raw[3] if len(raw) > 3 else 0


def _geojson_message(collection: dict) -> bytes:
    return json.dumps({"geojson": json.dumps(collection, separators=(",", ":"))}).encode()


def _plan_geojson(plan: Plan, origin: Origin) -> dict:
    features = []
    for v in plan.vehicles:
        path = v.path if len(v.path) else v.waypoints
        lat, lon, alt = enu_to_geodetic(path[:, 0], path[:, 1], path[:, 2], origin)
        r, g, b = vehicle_color(v.sysid)[:3]
        features.append(
            {
                "type": "Feature",
                "geometry": {
                    "type": "LineString",
                    "coordinates": np.column_stack([lon, lat, alt]).round(8).tolist(),
                },
                "properties": {
                    "name": f"plan {v.vehicle_id}",
                    "vehicle_id": v.vehicle_id,
                    "sysid": v.sysid,
                    "style": {"color": f"#{r:02x}{g:02x}{b:02x}", "weight": 2, "dashArray": "4 4"},
                },
            }
        )
    return {"type": "FeatureCollection", "features": features}


def _obstacle_features(scenario_text: str, origin: Origin) -> list[dict]:
    """Cylinders and radar hemispheres as circle polygons (footprints) for the map."""
    try:
        data = tomllib.loads(scenario_text)
    except tomllib.TOMLDecodeError:
        log.warning("scenario text is not valid TOML; no obstacles drawn on the map")
        return []
    obstacles = data.get("obstacles", {})
    shapes = [
        ("cylinder", c, c.get("radius_m", 0) + c.get("buffer_m", 0)) for c in obstacles.get("cylinders", [])
    ]
    shapes += [("radar", h, h.get("radius_m", 0)) for h in obstacles.get("hemispheres", [])]
    angles = np.linspace(0.0, 2.0 * np.pi, _CIRCLE_POINTS + 1)
    features = []
    for kind, d, radius in shapes:
        east = d.get("x", 0.0) + radius * np.cos(angles)
        north = d.get("y", 0.0) + radius * np.sin(angles)
        lat, lon, _ = enu_to_geodetic(east, north, np.zeros_like(east), origin)
        ring = np.column_stack([lon, lat]).round(8).tolist()
        features.append(
            {
                "type": "Feature",
                "geometry": {"type": "Polygon", "coordinates": [ring]},
                "properties": {
                    "name": kind,
                    "radius_m": radius,
                    "style": {"color": "#d62728" if kind == "cylinder" else "#ff7f0e", "weight": 1},
                },
            }
        )
    return features
