"""Rerun views of a flight, live or from a log, through the Rerun SDK (pinned: rerun-sdk 0.41).

Rerun's own MCAP import does not show our JSON channels, so the views are logged through the
SDK. One timeline, ``flight``: seconds of flight since the first frame (``rr.set_time("flight",
duration=...)`` / ``rr.TimeColumn("flight", duration=...)``), i.e. receive time since the first
frame times the clock rate (seconds of flight per second of receive time). Receive times are the
one clock every frame and event shares, whatever the vehicles' boot clocks; the rate scales them:

- a log: ``Flight.clock_rate`` (telemetry.reader): the ``clock_rate`` that ``fly`` records in the
  MCAP metadata (1 in lockstep, where the receive time already is the virtual flight time, and
  for real vehicles; the speed-up of a paced mock or a SITL, whose frames carry wall time); for a
  log without it (older logs, ``watch``, imports) the rate of the vehicles' own time_boot_ms
  against the receive time, else 1. The recorded rate comes first: it is exact, and ``fly``
  refuses connected vehicles whose clocks run off it; time_boot_ms serves where nothing was
  recorded (boot clocks of real vehicles differ, so they are used for a rate, not as the
  timeline).
- live (``fly --live`` / ``--serve-web``): the vehicles' rate, ``VehicleSource.speedup``;
  ``watch``: 1 (its vehicles' rate is not known; its .rrd, from the log, is estimated as above).

Each .rrd and live view is its own recording: its id is the log's file name plus a uuid4
(``recording_id``), so two runs, or two replays of one log, opened together do not merge.
Entity layout:

- ``map/...`` (map view, EPSG:4326): ``map/plan/{sysid}`` planned route (GeoLineStrings, static),
  ``map/track/{sysid}`` flown track, ``map/vehicle/{sysid}`` the vehicle now (GeoPoints),
  ``map/obstacles`` obstacle footprints. Colours per vehicle (telemetry.colors).
- ``world/...`` (3-D, local ENU metres about the scenario origin, z up): planned paths and flown
  tracks (LineStrips3D), vehicles (Points3D), obstacle cylinders (Cylinders3D), radar
  hemispheres and an optional terrain surface (Mesh3D).
- ``series/{altitude_m,ground_speed_mps,mission_item,link_loss}/{sysid}`` (Scalars): altitude
  above home, ground speed, current mission item, and the fraction of frames lost per second
  (MAVLink sequence gaps).
- ``events`` (TextLog) planner and flight events.

The same ``FlightViews`` methods serve both modes: a log sends whole columns at once
(``send_columns``), the live logger sends one-row columns as frames arrive. A default blueprint
lays out map, 3-D view, the time series and the events (a text log).
"""

from __future__ import annotations

import contextlib
import logging
import tomllib
import uuid
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from gcs_planner.core.geo import Origin, enu_to_geodetic, geodetic_to_enu
from gcs_planner.core.validation import atomic_write
from gcs_planner.model.plan import Plan
from gcs_planner.model.scenario import Scenario, ScenarioError
from gcs_planner.planning import parse_scenario
from gcs_planner.telemetry.colors import vehicle_color
from gcs_planner.telemetry.reader import Flight
from gcs_planner.wire.units import reports_no_fix

__all__ = [
    "FlightViews",
    "LiveRerunLogger",
    "flight_blueprint",
    "log_flight_to_rerun",
    "recording_id",
    "rrd_recording",
]

log = logging.getLogger(__name__)

APPLICATION_ID = "gcs-planner"
TIMELINE = "flight"
EVENTS = "events"  # the entity of the events' text log
SERIES = ("altitude_m", "ground_speed_mps", "mission_item", "link_loss")
_UNBOUNDED_CYLINDER_TOP_M = 150.0  # drawn height of a cylinder with no z_max
_TRACK_REFRESH_S = 1.0  # live: redraw the flown track this often per vehicle


def flight_blueprint() -> rrb.Blueprint:
    """Map and 3-D view side by side, the four time series and the events below."""
    return rrb.Blueprint(
        rrb.Vertical(
            rrb.Horizontal(
                rrb.MapView(origin="map", name="map: planned vs flown"),
                rrb.Spatial3DView(origin="world", name="local ENU [m]"),
            ),
            rrb.Horizontal(
                *(rrb.TimeSeriesView(origin=f"series/{name}", name=name) for name in SERIES),
                rrb.TextLogView(origin=EVENTS, name="events"),
            ),
            row_shares=[3, 2],
        ),
        collapse_panels=True,
    )


def recording_id(name: str) -> str:
    """A recording id of its own: ``name`` (the log's file name) plus a uuid4, so that two runs, or
    two replays of one log, opened together in one viewer stay apart."""
    return f"{name}-{uuid.uuid4()}"


class FlightViews:
    """Log a flight's views into a Rerun recording. Times are Unix seconds of receive time,
    shown as seconds of flight: (t - ``t0_s``) x ``rate`` (seconds of flight per second of
    receive time, module docstring)."""

    def __init__(self, rec: rr.RecordingStream, origin: Origin, t0_s: float, rate: float = 1.0) -> None:
        if not rate > 0:
            raise ValueError(f"rate must be > 0, got {rate}")
        self.rec = rec
        self.origin = origin
        self.t0_s = t0_s
        self.rate = float(rate)
        self._styled: set[tuple[str, int]] = set()

    def flight_s(self, t_s):
        """Receive time(s) [s, Unix] -> seconds of flight on the timeline."""
        return (np.asarray(t_s, dtype=float) - self.t0_s) * self.rate

    def _time(self, t_s) -> rr.TimeColumn:
        return rr.TimeColumn(TIMELINE, duration=self.flight_s(t_s))

    def log_scene(
        self,
        plan: Plan | None = None,
        scenario: Scenario | None = None,
        terrain: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
    ) -> None:
        """Static content: planned routes, obstacles, terrain (x [m], y [m], heights (ny, nx) [m])."""
        rec = self.rec
        rec.log("world", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
        if plan is not None:
            for v in plan.vehicles:
                path = v.path if len(v.path) else v.waypoints
                color = vehicle_color(v.sysid)
                lat, lon, _ = _to_geodetic(path, self.origin)
                rec.log(
                    f"map/plan/{v.sysid}",
                    rr.GeoLineStrings(
                        lat_lon=[np.column_stack([lat, lon])], colors=[color], radii=rr.Radius.ui_points(1.5)
                    ),
                    static=True,
                )
                rec.log(
                    f"world/plan/{v.sysid}",
                    rr.LineStrips3D([path], colors=[color], labels=[v.vehicle_id]),
                    static=True,
                )
                rec.log(
                    f"world/plan/{v.sysid}/waypoints",
                    rr.Points3D(v.waypoints, colors=[color], radii=rr.Radius.ui_points(3.0)),
                    static=True,
                )
        if scenario is not None:
            self._log_obstacles(scenario)
        if terrain is not None:
            self._log_terrain(*terrain)

    def _log_obstacles(self, scenario: Scenario) -> None:
        rec = self.rec
        angles = np.linspace(0.0, 2.0 * np.pi, 49)
        rings = []
        if scenario.cylinders:
            cyl = scenario.cylinders
            top = [c.z_max_m if np.isfinite(c.z_max_m) else _UNBOUNDED_CYLINDER_TOP_M for c in cyl]
            rec.log(
                "world/obstacles/cylinders",
                rr.Cylinders3D(
                    centers=[(c.x, c.y, 0.5 * (c.z_min_m + t)) for c, t in zip(cyl, top, strict=True)],
                    lengths=[t - c.z_min_m for c, t in zip(cyl, top, strict=True)],
                    radii=[c.radius_m for c in cyl],
                    colors=[(214, 39, 40, 140)],
                    fill_mode="solid",
                ),
                static=True,
            )
            rings += [(c.x, c.y, c.radius_m + c.buffer_m) for c in cyl]
        for i, h in enumerate(scenario.hemispheres):
            vertices, triangles = _hemisphere_mesh((h.x, h.y, h.z), h.radius_m)
            rec.log(
                f"world/obstacles/radars/{i}",
                rr.Mesh3D(
                    vertex_positions=vertices, triangle_indices=triangles, albedo_factor=(255, 127, 14, 90)
                ),
                static=True,
            )
            rings.append((h.x, h.y, h.radius_m))
        if rings:
            strings = []
            for x, y, r in rings:
                east, north = x + r * np.cos(angles), y + r * np.sin(angles)
                lat, lon, _ = _to_geodetic(np.column_stack([east, north, np.zeros_like(east)]), self.origin)
                strings.append(np.column_stack([lat, lon]))
            rec.log(
                "map/obstacles",
                rr.GeoLineStrings(lat_lon=strings, colors=[(214, 39, 40)], radii=rr.Radius.ui_points(1.0)),
                static=True,
            )

    def _log_terrain(self, xs: np.ndarray, ys: np.ndarray, heights: np.ndarray) -> None:
        gx, gy = np.meshgrid(xs, ys)
        vertices = np.column_stack([gx.ravel(), gy.ravel(), np.asarray(heights, dtype=float).ravel()])
        nx = len(xs)
        i, j = np.meshgrid(np.arange(len(ys) - 1), np.arange(nx - 1), indexing="ij")
        a = (i * nx + j).ravel()
        triangles = np.concatenate(
            [np.column_stack([a, a + 1, a + nx]), np.column_stack([a + 1, a + nx + 1, a + nx])]
        )
        self.rec.log(
            "world/terrain",
            rr.Mesh3D(
                vertex_positions=vertices, triangle_indices=triangles, albedo_factor=(120, 160, 90, 255)
            ),
            static=True,
        )

    def log_positions(self, sysid: int, t_s, lat_deg, lon_deg, alt_m, rel_alt_m, ground_speed_mps) -> None:
        """Vehicle position samples (arrays, any length >= 1): map marker, 3-D point, series."""
        t = self._time(t_s)
        color = vehicle_color(sysid)
        lat, lon = np.asarray(lat_deg, dtype=float), np.asarray(lon_deg, dtype=float)
        n = len(lat)
        self.rec.send_columns(
            f"map/vehicle/{sysid}",
            indexes=[t],
            columns=rr.GeoPoints.columns(
                positions=np.column_stack([lat, lon]), colors=np.tile(color, (n, 1))
            ),
        )
        east, north, up = geodetic_to_enu(lat, lon, np.asarray(alt_m, dtype=float), self.origin)
        self.rec.send_columns(
            f"world/vehicle/{sysid}",
            indexes=[t],
            columns=rr.Points3D.columns(
                positions=np.column_stack([east, north, up]), colors=np.tile(color, (n, 1))
            ),
        )
        self.log_series("altitude_m", sysid, t_s, rel_alt_m)
        self.log_series("ground_speed_mps", sysid, t_s, ground_speed_mps)

    def log_track(self, sysid: int, lat_deg, lon_deg, alt_m, t_s: float | None = None) -> None:
        """The flown track so far (static when t_s is None, i.e. a whole log)."""
        if len(lat_deg) < 2:
            return
        color = vehicle_color(sysid)
        track = np.column_stack([lat_deg, lon_deg])
        enu = np.column_stack(
            geodetic_to_enu(np.asarray(lat_deg), np.asarray(lon_deg), np.asarray(alt_m), self.origin)
        )
        static = t_s is None
        if not static:
            self.rec.set_time(TIMELINE, duration=float(self.flight_s(t_s)))
        self.rec.log(
            f"map/track/{sysid}",
            rr.GeoLineStrings(lat_lon=[track], colors=[color], radii=rr.Radius.ui_points(2.5)),
            static=static,
        )
        self.rec.log(f"world/track/{sysid}", rr.LineStrips3D([enu], colors=[color]), static=static)

    def log_series(self, name: str, sysid: int, t_s, values) -> None:
        """One time series (``name`` in SERIES) for one vehicle."""
        path = f"series/{name}/{sysid}"
        if (name, sysid) not in self._styled:
            self._styled.add((name, sysid))
            self.rec.log(
                path, rr.SeriesLines(colors=[vehicle_color(sysid)], names=[f"vehicle {sysid}"]), static=True
            )
        self.rec.send_columns(
            path,
            indexes=[self._time(t_s)],
            columns=rr.Scalars.columns(scalars=np.asarray(values, dtype=float)),
        )

    def log_event(self, t_s: float, event: dict) -> None:
        """An event as one text line, named by its "type" (or "event") key."""
        self.rec.set_time(TIMELINE, duration=float(self.flight_s(t_s)))
        key = "type" if "type" in event else "event"
        details = ", ".join(f"{k}={v}" for k, v in event.items() if k != key)
        self.rec.log(EVENTS, rr.TextLog(f"{event.get(key, 'event')}: {details}"))


def log_flight_to_rerun(
    flight: Flight,
    rrd_path: str | Path | None = None,
    rec: rr.RecordingStream | None = None,
    terrain: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
) -> rr.RecordingStream:
    """Render a whole flight log into ``rrd_path`` (headless) or into ``rec`` (e.g. a spawned viewer).

    With ``rrd_path`` the file is complete when this returns (the recording is flushed and
    disconnected); with ``rec`` the caller owns the recording.
    """
    if rec is None:
        if rrd_path is None:
            raise ValueError("log_flight_to_rerun needs rrd_path or rec")
        with rrd_recording(rrd_path, recording_id(flight.path.name)) as rec:
            _log_flight(flight, rec, terrain)
        return rec
    _log_flight(flight, rec, terrain)
    return rec


@contextlib.contextmanager
def rrd_recording(rrd_path: str | Path, recording_id: str) -> Iterator[rr.RecordingStream]:
    """A recording (with the flight blueprint as default) saved to ``rrd_path`` when the block ends.

    Encoded in memory and written here through atomic_write, not by Rerun's file sink, which on a
    full disk logs multi-line errors and can hang its flush: a failed write is one line (UserError
    naming the path and the OS reason) and leaves no partial .rrd at ``rrd_path``.
    """
    rec = rr.RecordingStream(APPLICATION_ID, recording_id=recording_id)
    stream = rec.binary_stream()
    rec.send_blueprint(flight_blueprint(), make_active=False, make_default=True)
    try:
        yield rec
        rec.flush()
        data = stream.read(flush=True) or b""
    finally:
        rec.disconnect()
    with atomic_write(rrd_path) as tmp, open(tmp, "wb") as f:
        f.write(data)


def _log_flight(flight: Flight, rec: rr.RecordingStream, terrain) -> None:
    origin = flight.origin or _origin_from_flight(flight)
    views = FlightViews(rec, origin, flight.start_time_s, flight.clock_rate)
    views.log_scene(flight.plan, scenario_from_text(flight.scenario_text), terrain)
    for sysid, track in flight.positions.items():
        views.log_positions(
            sysid,
            track.t_s,
            track.lat_deg,
            track.lon_deg,
            track.alt_m,
            track.rel_alt_m,
            track.ground_speed_mps,
        )
        views.log_track(sysid, track.lat_deg, track.lon_deg, track.alt_m)
    for sysid, (t, seq) in flight.mission_current.items():
        views.log_series("mission_item", sysid, t, seq)
    for sysid in flight.sysids:
        t, loss = flight.link_loss(sysid)
        if len(t):  # the last window is cut short by the log's end: stamped at its last frame
            views.log_series("link_loss", sysid, np.minimum(t, flight.end_time_s), loss)
    for t_s, event in flight.events:
        views.log_event(t_s, event)
    rec.flush()


class LiveRerunLogger:
    """Live views while flying: ``on_frame(msg, raw, t_s)`` matches MavlinkLink.subscribe.

    Call ``start(plan, scenario)`` once, then feed frames. Uses the same FlightViews methods and
    entity paths as a log, so a live session and a replayed log look the same. ``rate``: seconds
    of flight per second of receive time (the vehicles' speed-up where frames carry wall time).
    The link-loss window is one second of receive time, as in a log.
    """

    def __init__(self, rec: rr.RecordingStream, origin: Origin, t0_s: float, rate: float = 1.0) -> None:
        self.views = FlightViews(rec, origin, t0_s, rate)
        self._tracks: dict[int, list[tuple[float, float, float]]] = {}
        self._last_track_s: dict[int, float] = {}
        self._last_seq: dict[tuple[int, int], int] = {}
        self._window: dict[int, list[float]] = {}  # sysid -> [window start, received, expected]

    def start(self, plan: Plan | None = None, scenario: Scenario | None = None, terrain=None) -> None:
        self.views.log_scene(plan, scenario, terrain)

    def on_frame(self, msg, raw: bytes, t_s: float) -> None:
        """Update the views from one received frame (a MavlinkLink subscriber)."""
        if msg.get_type() == "BAD_DATA":
            return
        sysid = msg.get_srcSystem()
        self._count_link(sysid, msg.get_srcComponent(), msg.get_seq(), t_s)
        msg_id = msg.get_msgId()
        if msg_id == 33 and not reports_no_fix(msg):  # GLOBAL_POSITION_INT with a position
            lat, lon, alt = msg.lat * 1e-7, msg.lon * 1e-7, msg.alt * 1e-3
            speed = float(np.hypot(msg.vx, msg.vy)) * 1e-2
            self.views.log_positions(sysid, [t_s], [lat], [lon], [alt], [msg.relative_alt * 1e-3], [speed])
            track = self._tracks.setdefault(sysid, [])
            track.append((lat, lon, alt))
            if t_s - self._last_track_s.get(sysid, -np.inf) >= _TRACK_REFRESH_S:
                self._last_track_s[sysid] = t_s
                a = np.asarray(track)
                self.views.log_track(sysid, a[:, 0], a[:, 1], a[:, 2], t_s=t_s)
        elif msg_id == 42:  # MISSION_CURRENT
            self.views.log_series("mission_item", sysid, [t_s], [msg.seq])

    def log_event(self, event: dict, t_s: float) -> None:
        self.views.log_event(t_s, event)

    def _count_link(self, sysid: int, compid: int, seq: int, t_s: float) -> None:
        key = (sysid, compid)
        gap = 1
        if key in self._last_seq:
            gap = (seq - self._last_seq[key]) % 256
            gap = gap if 0 < gap < 128 else 1
        self._last_seq[key] = seq
        window = self._window.setdefault(sysid, [t_s, 0.0, 0.0])
        if t_s - window[0] >= 1.0:
            if window[2] > 0:
                self.views.log_series("link_loss", sysid, [t_s], [1.0 - window[1] / window[2]])
            window[:] = [t_s, 0.0, 0.0]
        window[1] += 1
        window[2] += gap


def _to_geodetic(enu: np.ndarray, origin: Origin):
    return enu_to_geodetic(enu[:, 0], enu[:, 1], enu[:, 2], origin)


def _hemisphere_mesh(center, radius_m: float, n: int = 16) -> tuple[np.ndarray, np.ndarray]:
    """Upper half of a UV sphere: (vertices (V, 3), triangles (T, 3))."""
    polar = np.linspace(0.0, 0.5 * np.pi, n // 2 + 1)  # from the top down to the equator
    azimuth = np.linspace(0.0, 2.0 * np.pi, n, endpoint=False)
    p, a = np.meshgrid(polar, azimuth, indexing="ij")
    vertices = np.column_stack(
        [np.sin(p).ravel() * np.cos(a).ravel(), np.sin(p).ravel() * np.sin(a).ravel(), np.cos(p).ravel()]
    ) * radius_m + np.asarray(center, dtype=float)
    rows, cols = len(polar), len(azimuth)
    i, j = np.meshgrid(np.arange(rows - 1), np.arange(cols), indexing="ij")
    a0 = (i * cols + j).ravel()
    a1 = (i * cols + (j + 1) % cols).ravel()
    b0, b1 = a0 + cols, a1 + cols
    triangles = np.concatenate([np.column_stack([a0, b0, a1]), np.column_stack([a1, b0, b1])])
    return vertices, triangles


def scenario_from_text(text: str | None) -> Scenario | None:
    """Parse a scenario attachment for drawing, with its planner's own tables (a coalition's
    targets, the 4-D planner's traffic); None (with a warning) if absent or invalid. A ``[site]``'s
    map files are not in the log, so its zones are not drawn from it."""
    if not text:
        return None
    try:
        return parse_scenario(tomllib.loads(text), where="scenario.toml attachment")
    except (tomllib.TOMLDecodeError, ScenarioError) as exc:
        log.warning("scenario attachment not drawn: %s", exc)
        return None


def _origin_from_flight(flight: Flight) -> Origin:
    for track in flight.positions.values():
        if len(track):
            return Origin(track.lat_deg[0], track.lon_deg[0], track.alt_m[0] - track.rel_alt_m[0])
    return Origin(0.0, 0.0, 0.0)
