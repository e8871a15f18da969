"""Import the logs users have into the MCAP flight-log layout, the format told by its bytes.

- .tlog (8-byte big-endian Unix time [us] + frame): gcs_planner.telemetry.tlog, frames exact.
- Raw MAVLink capture (frames back to back, no times): each frame at the last boot time seen in
  the stream (``time_boot_ms`` / ``time_usec``); the logger maps that clock onto the wall clock.
- ArduPilot DataFlash (.bin, or the text .log): pymavlink's DFReader; its Unix times come from
  the GPS messages.
- PX4 ULog (.ulg): pyulog; Unix time from the GPS's ``time_utc_usec``, else time since boot.

DataFlash and ULog hold no MAVLink frames. Every record goes to a JSON channel of its own
(``/dataflash/{TYPE}``, ``/ulog/{topic}``, with a schema from the log's own field list), mode
changes and text messages become ``/events``, and the vehicle's position and attitude are written
as the MAVLink GLOBAL_POSITION_INT and ATTITUDE frames a GCS would have received (sysid 1), so
the LocationFix channel, Rerun replay and MAVLink replay work as for a flown log. The metadata
``gcs_planner.import`` says the format and which frames were made from which records.
"""

from __future__ import annotations

import contextlib
import io
import logging
import math
import os
import re
import struct
from dataclasses import dataclass, field
from pathlib import Path

from gcs_planner.core.errors import UserError
from gcs_planner.core.geo import Origin
from gcs_planner.model.plan import Plan
from gcs_planner.wire.units import reports_no_fix

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import DFReader  # noqa: E402
from pymavlink.dialects.v20 import ardupilotmega as mavlink  # noqa: E402

__all__ = ["FORMATS", "ImportResult", "detect_format", "import_log"]

log = logging.getLogger(__name__)

FORMATS = ("tlog", "mavlink", "dataflash", "dataflash-text", "ulog")
ULOG_MAGIC = b"ULog\x01\x12\x35"
MCAP_MAGIC = b"\x89MCAP0\r\n"
DF_HEAD = b"\xa3\x95\x80"  # HEAD1, HEAD2, then the first record: FMT (type 128)
UNIX_2000_US, UNIX_2100_US = 946_684_800_000_000, 4_102_444_800_000_000
VEHICLE_SYSID = 1  # DataFlash and ULog are one vehicle's own log
IMPORT_FLUSH_INTERVAL_S = 3600.0  # imports flush every max_pending frames in their thread: errors raise there
POSITION_TOPICS = ("vehicle_global_position", "vehicle_gps_position", "sensor_gps")  # ULog, best first


@dataclass
class ImportResult:
    """What an import wrote: the format, the records per type (as the format's reader counts
    them) and the MAVLink frames logged (kept or made)."""

    format: str
    records: dict[str, int] = field(default_factory=dict)
    frames: int = 0


def detect_format(path: str | Path) -> str:
    """One of FORMATS, from the file's first bytes; UserError naming what the file is otherwise."""
    path = Path(path)
    try:
        with open(path, "rb") as f:
            head = f.read(4096)
    except FileNotFoundError:
        raise UserError(f"{path}: no such file") from None
    except OSError as exc:
        raise UserError(f"{path}: cannot read: {exc}") from None
    if head.startswith(ULOG_MAGIC):
        return "ulog"
    if head.startswith(DF_HEAD):
        return "dataflash"
    if head.startswith(b"FMT, "):
        return "dataflash-text"
    if _looks_like_tlog(head):
        return "tlog"
    if head[:1] in (b"\xfd", b"\xfe") and _frames_at_start(head) >= 2:
        return "mavlink"
    raise UserError(f"{path}: not a telemetry log ({_what_it_is(head)})")


def _looks_like_tlog(head: bytes) -> bool:
    """An 8-byte time + a MAVLink frame with a valid CRC at the start, or several such records
    framed by their headers of which some have a valid CRC (an older dialect fails some)."""
    records = list(_tlog_records(head, byteorder=">"))[:4]
    if not records:
        return False
    return records[0][1] is not None or (len(records) >= 2 and any(msg is not None for _, msg, _ in records))


def _tlog_records(data: bytes, byteorder: str):
    """(time field, decoded message or None when its CRC fails, frame bytes) of consecutive
    timestamped records from byte 0, framed by their headers; stops where no frame starts."""
    parser = mavlink.MAVLink(None)
    i = 0
    while True:
        size = _frame_size(data, i + 8)
        if size is None or i + 8 + size > len(data):
            return
        (t,) = struct.unpack_from(f"{byteorder}Q", data, i)
        frame = data[i + 8 : i + 8 + size]
        try:
            msg = parser.decode(bytearray(frame))
        except (mavlink.MAVError, struct.error, IndexError, KeyError, TypeError):
            msg = None
        yield t, msg, bytes(frame)
        i += 8 + size


def _frame_size(data: bytes, i: int) -> int | None:
    """Length of the MAVLink frame starting at ``data[i]`` (by its header), None if none starts there."""
    if i + 2 > len(data):
        return None
    if data[i] == 0xFE:
        return 8 + data[i + 1]
    if data[i] == 0xFD and i + 3 <= len(data):
        return 12 + data[i + 1] + (13 if data[i + 2] & 1 else 0)
    return None


def _frames_at_start(head: bytes) -> int:
    """How many MAVLink frames with a valid CRC follow each other from byte 0."""
    parser = mavlink.MAVLink(None)
    i = n = 0
    while n < 3:
        size = _frame_size(head, i)
        if size is None or i + size > len(head):
            break
        try:
            parser.decode(bytearray(head[i : i + size]))
        except (mavlink.MAVError, struct.error, IndexError, KeyError, TypeError):
            break
        i, n = i + size, n + 1
    return n


def _what_it_is(head: bytes) -> str:
    text = head.lstrip()
    if head.startswith(MCAP_MAGIC):
        return "an MCAP file: already a flight log, replay it"
    if text.startswith(b"QGC WPL"):
        return "a QGC WPL mission file"
    if text.startswith(b"{"):
        return "JSON text"
    if not head:
        return "an empty file"
    return f"unknown content starting {head[:8].hex(' ')}"


def import_log(
    path: str | Path,
    mcap_path: str | Path,
    origin: Origin | None = None,
    plan: Plan | None = None,
    scenario_text: str | None = None,
) -> ImportResult:
    """Convert any supported log into a FlightLogger MCAP file (written to a temporary name and
    renamed when complete, so a failed import leaves nothing)."""
    fmt = detect_format(path)
    mcap_path = Path(mcap_path)
    tmp = mcap_path.with_name(mcap_path.name + ".part")
    try:
        result = _IMPORTERS[fmt](Path(path), tmp, origin, plan, scenario_text)
        if result.frames == 0 and not result.records:
            raise UserError(f"{path}: a {fmt} log with nothing in it")
        tmp.replace(mcap_path)
    except OSError as exc:  # a full disk, a read-only folder: one line, nothing at mcap_path
        if exc.filename is not None and str(exc.filename) == str(path):
            raise UserError(f"log {str(path)!r}: cannot read: {exc.strerror or exc}") from None
        raise UserError(f"cannot write {str(mcap_path)!r}: {exc.strerror or exc}") from None
    finally:
        tmp.unlink(missing_ok=True)
    return result


def _logger(mcap_path: Path, origin: Origin | None, plan: Plan | None, scenario_text: str | None):
    from gcs_planner.telemetry.mcap_log import FlightLogger

    origin = origin or (plan.origin if plan is not None else Origin(0.0, 0.0, 0.0))
    return FlightLogger(mcap_path, origin, plan=plan, scenario_text=scenario_text, max_pending=50_000,
                        flush_interval_s=IMPORT_FLUSH_INTERVAL_S)  # fmt: skip


def _import_tlog(path, mcap_path, origin, plan, scenario_text) -> ImportResult:
    """Big-endian Unix times (MAVProxy, Mission Planner, QGC) through mavutil, which resynchronises
    on damage; little-endian ones (pymavlink's old captures) and times since boot read here."""
    from gcs_planner.telemetry.tlog import import_tlog

    data = path.read_bytes()
    sample = [t for t, _, _ in _first(_tlog_records(data, ">"), 20)]
    big = sum(_unix(t) for t in sample)
    little = sum(_unix(_swapped(t)) for t in sample)
    if big and big >= little:
        frames = import_tlog(path, mcap_path, origin=origin, plan=plan, scenario_text=scenario_text)
        return ImportResult("tlog", frames=frames)
    little = little > 0
    rows = list(_tlog_records(data, "<" if little else ">"))
    usable = _unix if little else (lambda t: t < UNIX_2000_US)  # since boot: under 30 years
    records = [(t * 1e-6, msg, raw) for t, msg, raw in rows if msg is not None and usable(t)]
    if origin is None and plan is None:
        origin = _origin_from_frames(records)
    with _logger(mcap_path, origin, plan, scenario_text) as logger:
        time_base = "little-endian Unix us" if little else "time since boot (mapped onto the import's clock)"
        dropped = len(rows) - len(records)
        logger.add_metadata(
            "gcs_planner.import",
            {
                "format": "tlog",
                "time": time_base,
                "dropped": f"{dropped} frames whose CRC fails in this dialect",
            },
        )
        for t, msg, raw in records:
            logger.on_frame(msg, raw, t)
    return ImportResult("tlog", frames=len(records))


def _unix(t_us: int) -> bool:
    return UNIX_2000_US <= t_us <= UNIX_2100_US


def _swapped(t: int) -> int:
    return int.from_bytes(t.to_bytes(8, "big"), "little")


def _first(rows, n: int) -> list:
    out = []
    for row in rows:
        out.append(row)
        if len(out) == n:
            break
    return out


def _import_capture(path, mcap_path, origin, plan, scenario_text) -> ImportResult:
    parser = mavlink.MAVLink(None)
    parser.robust_parsing = True
    frames: list[tuple[float, object, bytes]] = []
    t_s = 0.0
    for msg in parser.parse_buffer(path.read_bytes()) or []:
        if msg.get_type() == "BAD_DATA":
            continue
        boot_s = _boot_time_s(msg)
        t_s = max(t_s, boot_s) if boot_s is not None else t_s
        frames.append((t_s, msg, bytes(msg.get_msgbuf())))
    if origin is None and plan is None:
        origin = _origin_from_frames(frames)
    with _logger(mcap_path, origin, plan, scenario_text) as logger:
        logger.add_metadata("gcs_planner.import", {"format": "mavlink", "time": "the stream's boot clock"})
        for t, msg, raw in frames:
            logger.on_frame(msg, raw, t)
    return ImportResult("mavlink", frames=len(frames))


def _boot_time_s(msg) -> float | None:
    if hasattr(msg, "time_boot_ms"):
        return msg.time_boot_ms * 1e-3
    if hasattr(msg, "time_usec") and msg.get_type() != "SYSTEM_TIME":
        return msg.time_usec * 1e-6
    return None


def _origin_from_frames(frames) -> Origin:
    for _, msg, _ in frames:
        if msg.get_type() == "GLOBAL_POSITION_INT" and not reports_no_fix(msg):
            return Origin(msg.lat * 1e-7, msg.lon * 1e-7, (msg.alt - msg.relative_alt) * 1e-3)
    return Origin(0.0, 0.0, 0.0)


class _Frames:
    """MAVLink frames made from a log's records, as the vehicle would have sent them."""

    def __init__(self) -> None:
        self.mav = mavlink.MAVLink(None, srcSystem=VEHICLE_SYSID, srcComponent=1)
        self.home_alt_m: float | None = None

    def position(self, t_boot_ms: int, lat: float, lon: float, alt_m: float, vel=(0.0, 0.0, 0.0), hdg=None):
        if self.home_alt_m is None:
            self.home_alt_m = alt_m
        heading = 65535 if hdg is None or not math.isfinite(hdg) else int(hdg % 360 * 100)
        vx, vy, vz = (max(-32768, min(32767, int(v * 100))) if math.isfinite(v) else 0 for v in vel)
        msg = self.mav.global_position_int_encode(
            t_boot_ms & 0xFFFFFFFF, round(lat * 1e7), round(lon * 1e7), round(alt_m * 1000),
            round((alt_m - self.home_alt_m) * 1000), vx, vy, vz, heading,
        )  # fmt: skip
        return msg, bytes(msg.pack(self.mav))

    def attitude(self, t_boot_ms: int, roll: float, pitch: float, yaw: float):
        msg = self.mav.attitude_encode(t_boot_ms & 0xFFFFFFFF, roll, pitch, yaw, 0.0, 0.0, 0.0)
        return msg, bytes(msg.pack(self.mav))


def _import_dataflash(path, mcap_path, origin, plan, scenario_text, text: bool = False) -> ImportResult:
    reader_cls = DFReader.DFReader_text if text else DFReader.DFReader_binary
    skipped = _Skipped()
    try:
        with contextlib.redirect_stderr(skipped):
            reader = reader_cls(str(path), zero_time_base=False)
    except Exception as exc:  # noqa: BLE001 - DFReader raises anything on a damaged header
        raise UserError(f"{path}: cannot read the DataFlash log: {exc}") from None
    made = _Frames()
    records: dict[str, int] = {}
    with _logger(mcap_path, origin, plan, scenario_text) as logger:
        fmt = "dataflash-text" if text else "dataflash"
        logger.add_metadata(
            "gcs_planner.import",
            {"format": fmt, "frames": "GLOBAL_POSITION_INT from GPS, ATTITUDE from ATT (sysid 1)"},
        )
        misplaced = 0
        while True:
            try:
                with contextlib.redirect_stderr(skipped):
                    m = reader.recv_msg()
            except Exception as exc:  # noqa: BLE001 - a damaged record ends the readable part
                logger.log_event({"kind": "import", "text": f"log damaged after here: {exc}"})
                break
            if m is None:
                break
            kind = m.get_type()
            records[kind] = records.get(kind, 0) + 1
            t_s = getattr(m, "_timestamp", math.nan)  # DFReader sets none on some damaged records
            if not _placed(t_s):
                misplaced += 1
                continue
            fields = {k: v for k, v in m.to_dict().items() if k != "mavpackettype"}
            logger.log_record(f"/dataflash/{kind}", f"dataflash.{kind}", fields, t_s)
            t_ms = int(fields.get("TimeUS", 0) // 1000) if isinstance(fields.get("TimeUS"), int) else 0
            if (
                kind == "GPS"
                and _value(fields, "Status") >= 3
                and all(math.isfinite(_value(fields, k, math.nan)) for k in ("Lat", "Lng", "Alt"))
            ):  # a damaged FMT may name other columns
                vel = _ned(_value(fields, "Spd"), _value(fields, "GCrs"), _value(fields, "VZ"))
                logger.on_frame(*made.position(t_ms, fields["Lat"], fields["Lng"], fields["Alt"], vel,
                                               fields.get("GCrs")), t_s)  # fmt: skip
            elif kind == "ATT":
                angles = (math.radians(_value(fields, k)) for k in ("Roll", "Pitch", "Yaw"))
                logger.on_frame(*made.attitude(t_ms, *angles), t_s)
            elif kind == "MODE":
                logger.log_event(
                    {"kind": "mode", "mode": fields.get("Mode"), "number": fields.get("ModeNum")}, t_s
                )
            elif kind == "MSG":
                logger.log_event({"kind": "statustext", "text": fields.get("Message", "")}, t_s)
        _say_damage(logger, path, skipped.count, misplaced)
    return ImportResult(fmt, records, logger.frames_logged)


class _Skipped(io.TextIOBase):
    """A stderr that adds up DFReader's "Skipped N bad bytes" lines instead of printing them (its
    compiled indexer's own "bad header" lines go to the process's stdout and cannot be caught)."""

    count = 0

    def write(self, text: str) -> int:
        self.count += sum(int(n) for n in re.findall(r"Skipped (\d+) bad bytes", text))
        return len(text)


def _value(fields: dict, key: str, missing: float = 0.0) -> float:
    """A record's number; ``missing`` where the column is absent or not a finite number (damage)."""
    v = fields.get(key)
    return float(v) if isinstance(v, int | float) and math.isfinite(v) else missing


def _placed(t_s: float) -> bool:
    """A record time an MCAP log can hold: since boot or Unix, up to 2100; NaN or later is damage."""
    return 0.0 <= t_s <= UNIX_2100_US * 1e-6


def _say_damage(logger, path, bytes_skipped: int, misplaced: int) -> None:
    """One warning (and one event in the log) for what a damaged log lost."""
    lost = [f"{bytes_skipped} damaged bytes"] * bool(bytes_skipped) + [
        f"{misplaced} records with a damaged time"
    ] * bool(misplaced)
    if lost:
        text = " and ".join(lost) + " skipped"
        logger.log_event({"kind": "import", "text": text})
        log.warning("%s: %s", path, text)


def _ned(speed: float, course_deg: float, vz: float) -> tuple[float, float, float]:
    c = math.radians(course_deg)
    return speed * math.cos(c), speed * math.sin(c), vz


def _import_ulog(path, mcap_path, origin, plan, scenario_text) -> ImportResult:
    import numpy as np
    from pyulog import ULog

    try:
        ulog = ULog(str(path))
    except Exception as exc:  # noqa: BLE001 - pyulog raises anything on a damaged file
        raise UserError(f"{path}: cannot read the ULog: {exc}") from None
    offset_s = _ulog_unix_offset_s(ulog)
    made = _Frames()
    records: dict[str, int] = {}
    misplaced = 0
    with _logger(mcap_path, origin, plan, scenario_text) as logger:
        logger.add_metadata(
            "gcs_planner.import",
            {"format": "ulog", "time": "Unix from GPS time_utc_usec" if offset_s else "time since boot",
             "frames": "GLOBAL_POSITION_INT from vehicle_global_position or vehicle_gps_position, "
                       "ATTITUDE from vehicle_attitude (sysid 1)"},
        )  # fmt: skip
        for d in ulog.data_list:
            name = d.name if d.multi_id == 0 else f"{d.name}/{d.multi_id}"
            columns = {k: v for k, v in d.data.items()}
            if "timestamp" not in columns:  # a damaged format: rows without a time
                misplaced += len(next(iter(columns.values()), ()))
                continue
            n = len(columns["timestamp"])
            records[name] = n
            keys = list(columns)
            for i in range(n):
                row = {k: _plain(columns[k][i]) for k in keys}
                t_s = offset_s + row["timestamp"] * 1e-6
                if not _placed(t_s):
                    misplaced += 1
                    continue
                logger.log_record(f"/ulog/{name}", f"ulog.{d.name}", row, t_s)
        for t_s, msg, raw in _ulog_frames(ulog, made, offset_s, np):
            if _placed(t_s):
                logger.on_frame(msg, raw, t_s)
        for m in ulog.logged_messages:
            if _placed(t_s := offset_s + m.timestamp * 1e-6):
                logger.log_event({"kind": "statustext", "text": m.message, "level": m.log_level_str()}, t_s)
        _say_damage(logger, path, 0, misplaced)
    return ImportResult("ulog", records, logger.frames_logged)


def _plain(value):
    """A numpy scalar as a JSON number (NaN -> None)."""
    v = value.item() if hasattr(value, "item") else value
    return None if isinstance(v, float) and not math.isfinite(v) else v


def _ulog_unix_offset_s(ulog) -> float:
    """Unix time minus boot time [s], from the first GPS sample with a UTC time; 0 without one."""
    for d in ulog.data_list:
        if (
            d.name in ("vehicle_gps_position", "sensor_gps")
            and {"time_utc_usec", "timestamp"} <= d.data.keys()
        ):
            utc, boot = d.data["time_utc_usec"], d.data["timestamp"]
            valid = utc > UNIX_2000_US
            if valid.any():
                k = int(valid.argmax())
                return (int(utc[k]) - int(boot[k])) * 1e-6
    return 0.0


def _ulog_frames(ulog, made: _Frames, offset_s: float, np):
    topics = {d.name: d for d in ulog.data_list if d.multi_id == 0}
    out = []
    usable = [topics[n] for n in POSITION_TOPICS if n in topics]
    pos = next((d for d in usable if {"timestamp", "lat", "lon", "alt"} <= d.data.keys()), None)
    if pos is not None:
        lat, lon, alt = (np.asarray(pos.data[k], dtype=float) for k in ("lat", "lon", "alt"))
        if np.nanmax(np.abs(lat)) > 1000:  # vehicle_gps_position: degE7 and mm
            lat, lon, alt = lat * 1e-7, lon * 1e-7, alt * 1e-3
        for t_us, a, b, h in zip(pos.data["timestamp"], lat, lon, alt, strict=True):
            if math.isfinite(a) and (a or b):
                out.append((offset_s + int(t_us) * 1e-6, *made.position(int(t_us) // 1000, a, b, h)))
    att = topics.get("vehicle_attitude")
    if att is not None and {"timestamp", "q[0]", "q[1]", "q[2]", "q[3]"} <= att.data.keys():
        q = [np.asarray(att.data[f"q[{k}]"], dtype=float) for k in range(4)]
        w, x, y, z = q
        roll = np.arctan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y))
        pitch = np.arcsin(np.clip(2 * (w * y - z * x), -1, 1))
        yaw = np.arctan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
        for t_us, r, p, yw in zip(att.data["timestamp"], roll, pitch, yaw, strict=True):
            out.append(
                (
                    offset_s + int(t_us) * 1e-6,
                    *made.attitude(int(t_us) // 1000, float(r), float(p), float(yw)),
                )
            )
    out.sort(key=lambda row: row[0])
    return out


_IMPORTERS = {
    "tlog": _import_tlog,
    "mavlink": _import_capture,
    "dataflash": _import_dataflash,
    "dataflash-text": lambda *a: _import_dataflash(*a, text=True),
    "ulog": _import_ulog,
}
