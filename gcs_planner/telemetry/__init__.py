"""Telemetry: MCAP flight logs, .tlog import/export, replay to MAVLink, Rerun views.

Public API (see docs/telemetry.md):
- ``FlightLogger(path, origin, plan=None, scenario_text=None, tlog_path=None)``: context manager,
  ``on_frame(msg, raw, t_s)`` (MavlinkLink.subscribe callback), ``log_event(dict)``.
- ``read_flight(path) -> Flight``: positions per sysid, raw frames, decoded messages, plan,
  scenario, metadata, events; reads truncated files up to the last complete chunk.
- ``replay_to_mavlink(flight, "udpout:HOST:PORT", speed)``; ``import_tlog(tlog, mcap)``.
- ``log_flight_to_rerun(flight, rrd_path)``; ``LiveRerunLogger`` for live views.
Rerun is imported lazily (only the Rerun functions need it).
"""

from gcs_planner.telemetry.mcap_log import FlightLogger
from gcs_planner.telemetry.reader import Flight, RawFrame, Track, read_flight
from gcs_planner.telemetry.replay import replay_to_mavlink
from gcs_planner.telemetry.tlog import import_tlog, iter_tlog, write_tlog

__all__ = [
    "Flight",
    "FlightLogger",
    "LiveRerunLogger",
    "RawFrame",
    "Track",
    "import_tlog",
    "iter_tlog",
    "log_flight_to_rerun",
    "read_flight",
    "replay_to_mavlink",
    "write_tlog",
]


def __getattr__(name: str):
    if name in ("log_flight_to_rerun", "LiveRerunLogger", "FlightViews", "flight_blueprint"):
        from gcs_planner.telemetry import rerun_views

        return getattr(rerun_views, name)
    raise AttributeError(f"module 'gcs_planner.telemetry' has no attribute {name!r}")
