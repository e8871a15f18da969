"""Classic telemetry logs (.tlog) and their import into the MCAP flight-log layout.

A .tlog is what MAVProxy, Mission Planner and QGroundControl write and what mavlogdump and
MAVExplorer read: for each frame an 8-byte big-endian Unix time [us] followed by the raw frame,
nothing else. Reading goes through pymavlink's own .tlog reader (``mavutil.mavlogfile``; not
``mavlink_connection``, which picks a reader by the file's extension),
which resynchronises on garbage; each frame keeps its exact bytes (``msg.get_msgbuf()``).

Import picks the origin from ``--origin`` or else from the first GLOBAL_POSITION_INT (its
position at altitude ``alt - relative_alt``, i.e. home AMSL), so the map and ENU views work.
"""

from __future__ import annotations

import logging
import os
import struct
from collections.abc import Iterable, Iterator
from pathlib import Path

from gcs_planner.core.errors import UserError
from gcs_planner.core.geo import Origin
from gcs_planner.model.plan import Plan
from gcs_planner.telemetry.reader import RawFrame
from gcs_planner.wire.units import reports_no_fix

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavutil  # noqa: E402

__all__ = ["import_tlog", "iter_tlog", "write_tlog"]

_TIME = struct.Struct(">Q")
MAX_TIME_S = 4_102_444_800.0  # 2100-01-01: a later tlog timestamp is damage
log = logging.getLogger(__name__)


def write_tlog(frames: Iterable[RawFrame | tuple[int, bytes]], path: str | Path) -> int:
    """Write (t_ns [Unix ns], raw frame) pairs, e.g. ``Flight.frames``, as a .tlog; returns the count.

    Times are rounded to the microsecond and their two low bits cleared, as mavutil does (they
    carry the link number in MAVProxy logs), so tlog -> MCAP -> tlog is byte-identical.
    """
    n = 0
    with open(path, "wb") as f:
        for frame in frames:
            t_ns, raw = (frame.t_ns, frame.data) if isinstance(frame, RawFrame) else frame
            f.write(_TIME.pack(((t_ns + 500) // 1000) & ~3) + bytes(raw))
            n += 1
    return n


def iter_tlog(path: str | Path) -> Iterator[tuple[float, object, bytes]]:
    """Yield (t_s [Unix], decoded message, exact frame bytes) for every valid frame of a .tlog."""
    path = Path(path)
    if not path.is_file():
        raise UserError(f"tlog {str(path)!r}: no such file")
    mavutil.set_dialect("ardupilotmega")
    # the streaming .tlog reader whatever the file's name: mavlink_connection picks a reader by
    # extension (a .bin becomes DataFlash), and its default for files (mavmmaplog) indexes the
    # whole file on open and fails on damaged frames instead of skipping them
    conn = mavutil.mavlogfile(str(path), robust_parsing=True)
    skipped = 0
    try:
        while True:
            try:
                msg = conn.recv_msg()
            except Exception as exc:  # noqa: BLE001 - pymavlink raises many kinds on damaged bytes
                raise UserError(f"tlog {str(path)!r}: unreadable at byte {conn.f.tell()}: {exc}") from None
            if msg is None:
                break
            if msg.get_type() == "BAD_DATA":
                continue
            t_s = msg._timestamp
            if not 0.0 <= t_s <= MAX_TIME_S:  # a damaged timestamp: the frame cannot be placed
                skipped += 1
                continue
            yield t_s, msg, bytes(msg.get_msgbuf())
    finally:
        conn.close()
        if skipped:
            log.warning("tlog %s: %d frames with a timestamp outside 1970..2100 skipped", path, skipped)


def import_tlog(
    tlog_path: str | Path,
    mcap_path: str | Path,
    origin: Origin | None = None,
    plan: Plan | None = None,
    scenario_text: str | None = None,
) -> int:
    """Convert a .tlog into a FlightLogger MCAP file; returns the number of frames imported."""
    from gcs_planner.telemetry.mcap_log import FlightLogger

    if origin is None:
        origin = plan.origin if plan is not None else _origin_from_tlog(tlog_path)
    with FlightLogger(
        mcap_path,
        origin,
        plan=plan,
        scenario_text=scenario_text,
        max_pending=50_000,
        flush_interval_s=3600.0,  # an import flushes every max_pending frames, in this thread
    ) as logger:
        for t_s, msg, raw in iter_tlog(tlog_path):
            logger.on_frame(msg, raw, t_s)
    return logger.frames_logged


def _origin_from_tlog(path: str | Path) -> Origin:
    for _, msg, _ in iter_tlog(path):
        if msg.get_type() == "GLOBAL_POSITION_INT" and not reports_no_fix(msg):
            return Origin(msg.lat * 1e-7, msg.lon * 1e-7, (msg.alt - msg.relative_alt) * 1e-3)
    return Origin(0.0, 0.0, 0.0)
