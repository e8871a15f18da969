"""Many mock vehicles in one process: one asyncio loop, one tick drives them all.

Each tick (every ``tick_s`` of wall time) the fleet
1. advances the simulation in fixed steps of ``physics_dt_s`` until simulated time has caught up
   with ``speedup`` x elapsed wall time, dispatching arrivals, navigator timers and scripted
   events after every step (numpy over all vehicles; Python only for vehicles with an event),
2. runs the mission servers' re-request/timeout timers (wall clock, the GCS's clock),
3. sends the telemetry that is due (positions for all due vehicles converted to geodetic in one
   pyproj call); each vehicle's frames of the tick leave as one datagram, as ArduPilot's UDP
   driver sends what its buffer holds (sitl_mock/link.py ``batching``), or one datagram a frame
   where the profile says so (PX4: ``AutopilotProfile.frame_per_datagram``).

If the process cannot keep up (more than ``MAX_CATCH_UP_WALL_S`` behind), simulated time slips
instead of bursting: the lag is logged and counted in ``lag_events``.

Use it as a context manager in synchronous code (the loop runs in a daemon thread; the public
methods marshal into it), with ``async with`` inside an existing loop, or ``await serve()``.
Positions are ENU [m] about the fleet ``home`` (the frame origin; up = altitude above it).
"""

from __future__ import annotations

import asyncio
import contextlib
import heapq
import itertools
import logging
import math
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from sitl_mock import telemetry
from sitl_mock.faults import LinkFaults
from sitl_mock.geodesy import HomeLike, to_enu, to_geodetic
from sitl_mock.mission_server import Failure
from sitl_mock.vehicle import DEFAULT_HOME, MockVehicle, VehicleState
from sitl_mock.world import World

__all__ = ["MockFleet", "VehicleSnapshot"]

log = logging.getLogger(__name__)

MAX_CATCH_UP_WALL_S = 0.25
_POSITION, _ATTITUDE = 33, 30  # GLOBAL_POSITION_INT, ATTITUDE message ids
_NO_FIX = (0.0, 0.0, 0.0, 0.0, (0.0, 0.0, 0.0))  # lat, lon, alt, rel, vel before a position fix


@dataclass(frozen=True)
class VehicleSnapshot:
    """Position and progress of one vehicle at one simulated time."""

    state: VehicleState
    enu_m: tuple[float, float, float]
    lat_deg: float
    lon_deg: float
    alt_amsl_m: float
    vel_enu_mps: tuple[float, float, float]
    heading_rad: float  # CCW from east


class MockFleet:
    """Vehicles with system ids 1..count (or as given), each on its own UDP port.

    Each vehicle's transport (sitl_mock/link.py) is ``transport`` / ``gcs`` for the whole fleet or
    its spec's own keys: ``{"sysid": 3, "profile": "px4", "transport": "tcp", "port": 5760}`` listens
    on TCP 5760 (ArduPilot SITL's default); ``{"transport": "udpclient", "gcs": ("127.0.0.1", 14550)}``
    sends from an ephemeral port to a GCS listening there (PX4 SITL, ArduPilot ``udpclient``), so
    several vehicles share one GCS port; the default ``"udpin"`` binds ``port`` and answers whoever
    sent first. A spec's other keys are MockVehicle's arguments."""

    def __init__(
        self,
        count: int | None = None,
        vehicles: list[dict[str, Any] | MockVehicle] | None = None,
        base_port: int = 0,
        speedup: float = 1.0,
        home: HomeLike = DEFAULT_HOME,
        *,
        profile: str = "ardupilot",
        vehicle_type: str = "multirotor",
        host: str = "127.0.0.1",
        faults: LinkFaults | None = None,
        rate_hz: float = 10.0,
        status_rate_hz: float = 1.0,
        home_rate_hz: float = 0.2,
        physics_dt_s: float = 0.05,
        tick_s: float = 0.02,
        signing_key: bytes | None = None,
        flight: dict | None = None,
        clock_zero_s: float | None = None,
        transport: str = "udpin",
        gcs: tuple[str, int] | None = None,
        batch_frames: bool = True,
    ) -> None:
        """``flight``: FlightRules fields to override for every vehicle (e.g. ``{"arm_ready_s": 0}`` in
        a test about something else); the profile's real behaviour is the default. ``clock_zero_s``:
        the time.monotonic() (one clock for every process of the machine) at which simulated time
        is 0, so that fleets in several processes share one simulated clock (default: the start).
        ``batch_frames``: each vehicle's frames of a tick leave in one datagram (False: one each, as a
        profile with ``frame_per_datagram`` always sends them)."""
        if (count is None) == (vehicles is None):
            raise ValueError("MockFleet needs exactly one of count= or vehicles=")
        if count is not None and not (isinstance(count, int) and 1 <= count <= 254):
            raise ValueError(f"MockFleet count must be an integer in 1..254, got {count!r}")
        if not (isinstance(base_port, int) and 0 <= base_port <= 65535):
            raise ValueError(f"MockFleet base_port must be in 0..65535, got {base_port!r}")
        for name, value in (("speedup", speedup), ("physics_dt_s", physics_dt_s), ("tick_s", tick_s)):
            if not (isinstance(value, int | float) and math.isfinite(value) and value > 0):
                raise ValueError(f"MockFleet {name} must be a finite number > 0, got {value!r}")
        specs: list[dict[str, Any] | MockVehicle] = (
            [{} for _ in range(count)] if count is not None else list(vehicles or [])
        )
        self.home = home
        self.host = host
        self.vehicles: list[MockVehicle] = []
        for k, spec in enumerate(specs):
            if isinstance(spec, MockVehicle):
                self.vehicles.append(spec)
                continue
            port = base_port + k if base_port else 0
            kwargs = {"sysid": k + 1, "profile": profile, "vehicle_type": vehicle_type, "home": home,
                      "port": port, "faults": faults, "host": host, "signing_key": signing_key,
                      "flight": flight, "transport": transport, "gcs": gcs, **spec}  # fmt: skip
            self.vehicles.append(MockVehicle(**kwargs))
        sysids = [v.sysid for v in self.vehicles]
        if len(set(sysids)) != len(sysids):
            log.warning("MockFleet: duplicate system ids %s (on purpose, to test a GCS?)", sysids)
        homes = [v.home for v in self.vehicles]
        ground = np.column_stack(to_enu(
            np.array([h.lat_deg for h in homes]), np.array([h.lon_deg for h in homes]),
            np.array([h.alt_m for h in homes]), home,
        ))  # fmt: skip
        self.world = World(home, [v.airframe for v in self.vehicles], ground)
        for i, v in enumerate(self.vehicles):
            v.attach(self.world, i, ground[i])
        self.speedup = float(speedup)
        self.physics_dt_s = float(physics_dt_s)
        self.tick_s = float(tick_s)
        self.rates_hz = (rate_hz, status_rate_hz, home_rate_hz)
        self.lag_events = 0
        self.ticks = 0
        self.clock_zero_s = clock_zero_s
        self.batch_frames = batch_frames
        self._script: list[tuple[float, int, Callable[[MockFleet], None]]] = []
        self._script_counter = itertools.count()
        self._task: asyncio.Task | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._thread: threading.Thread | None = None

    # --- running -----------------------------------------------------------------------------
    async def start(self) -> None:
        """Open every vehicle's socket and start ticking in the running loop."""
        self._loop = asyncio.get_running_loop()
        try:
            for v in self.vehicles:
                await v.start()
        except OSError as exc:
            self._close_links()
            raise OSError(f"MockFleet: cannot bind vehicle port: {exc}") from exc
        self._task = asyncio.create_task(self._run(), name="sitl-mock-fleet")

    async def stop(self) -> None:
        if self._task is not None:
            self._task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._task
            self._task = None
        self._close_links()

    async def serve(self) -> None:
        """Run until cancelled (the CLI's Ctrl-C)."""
        await self.start()
        try:
            await asyncio.Event().wait()
        finally:
            await self.stop()

    async def __aenter__(self) -> MockFleet:
        await self.start()
        return self

    async def __aexit__(self, *exc: object) -> None:
        await self.stop()

    def __enter__(self) -> MockFleet:
        started = threading.Event()
        failure: list[BaseException] = []

        def run() -> None:
            loop = asyncio.new_event_loop()
            self._loop = loop
            try:
                loop.run_until_complete(self.start())
            except BaseException as exc:  # noqa: BLE001 - handed to the caller's thread
                failure.append(exc)
                started.set()
                loop.close()
                return
            started.set()
            loop.run_forever()
            loop.run_until_complete(self.stop())
            loop.close()

        self._thread = threading.Thread(target=run, name="sitl-mock", daemon=True)
        self._thread.start()
        started.wait()
        if failure:
            raise failure[0]
        return self

    def __exit__(self, *exc: object) -> None:
        if self._loop is not None and self._thread is not None:
            self._loop.call_soon_threadsafe(self._loop.stop)
            self._thread.join(timeout=5.0)
            self._thread = None

    def _close_links(self) -> None:
        for v in self.vehicles:
            v.close()

    # --- queries -----------------------------------------------------------------------------
    @property
    def addresses(self) -> list[tuple[str, int]]:
        return [v.address for v in self.vehicles]

    @property
    def sim_time_s(self) -> float:
        return self.world.sim_time_s

    def vehicle(self, sysid: int) -> MockVehicle:
        for v in self.vehicles:
            if v.sysid == sysid:
                return v
        raise KeyError(
            f"no vehicle with sysid {sysid} in this fleet (have {[v.sysid for v in self.vehicles]})"
        )

    def positions_enu(self) -> np.ndarray:
        """(N, 3) reported positions [m] ENU about the fleet home, in vehicle order."""
        return self.call(lambda: self.world.kin.reported_pos().copy())

    def snapshot(self) -> list[VehicleSnapshot]:
        """Position, velocity, heading and mission progress of every vehicle, taken atomically."""
        return self.call(self._snapshot)

    def _snapshot(self) -> list[VehicleSnapshot]:
        kin = self.world.kin
        pos = kin.reported_pos()
        vel = kin.ground_vel()
        lat, lon, alt = to_geodetic(pos[:, 0], pos[:, 1], pos[:, 2], self.home)
        return [
            VehicleSnapshot(
                v.state,
                tuple(pos[i].tolist()),
                float(lat[i]),
                float(lon[i]),
                float(alt[i]),
                tuple(vel[i].tolist()),
                float(kin.psi[i]),
            )  # fmt: skip
            for i, v in enumerate(self.vehicles)
        ]

    def wait_until(
        self, predicate: Callable[[MockFleet], bool], timeout_s: float, poll_s: float = 0.05
    ) -> bool:
        """Block until ``predicate(fleet)`` holds (evaluated in the loop thread); False on timeout."""
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            if self.call(predicate, self):
                return True
            time.sleep(poll_s)
        return bool(self.call(predicate, self))

    # --- fault injection and scripting (thread-safe) -----------------------------------------
    def set_faults(self, sysid: int | None, faults: LinkFaults) -> None:
        """Replace the link faults of vehicle ``sysid`` (None: every vehicle)."""
        self.call(lambda: [v.set_faults(faults) for v in self._select(sysid)])

    def set_wind(self, sysid: int | None, east_mps: float, north_mps: float, up_mps: float = 0.0) -> None:
        """Wind [m/s] added to the vehicle's ground velocity while airborne (not compensated)."""
        self.call(self._set_rows, self.world.kin.wind, sysid, (east_mps, north_mps, up_mps))

    def set_drift(self, sysid: int | None, east_mps: float, north_mps: float, up_mps: float = 0.0) -> None:
        """Navigation drift [m/s]: the reported track walks away from the navigated one at this rate."""
        self.call(self._set_rows, self.world.kin.drift, sysid, (east_mps, north_mps, up_mps))

    def reboot(self, sysid: int | None) -> None:
        """Reboot vehicle(s) ``sysid`` (None: all)."""
        self.call(lambda: [v.reboot() for v in self._select(sysid)])

    def set_mission_failure(self, sysid: int | None, failure: Failure | str) -> None:
        """Scripted mission-protocol failure (QGC MockLink style) on vehicle(s) ``sysid`` (None: all)."""
        mode = Failure(failure)
        self.call(lambda: [setattr(v.mission_server, "failure", mode) for v in self._select(sysid)])

    def set_speedup(self, speedup: float) -> None:
        """Change the speed-up factor while running (simulated time continues from where it is)."""
        if not (isinstance(speedup, int | float) and math.isfinite(speedup) and speedup > 0):
            raise ValueError(f"MockFleet speedup must be a finite number > 0, got {speedup!r}")

        def rebase() -> None:
            if self._loop is not None and self._task is not None:
                self._wall_base, self._sim_base = self._loop.time(), self.world.sim_time_s
            self.speedup = float(speedup)

        self.call(rebase)

    def at(self, sim_time_s: float, action: Callable[[MockFleet], None]) -> None:
        """Run ``action(fleet)`` in the loop when simulated time reaches ``sim_time_s`` (fault scripts)."""
        self.call(lambda: heapq.heappush(self._script, (sim_time_s, next(self._script_counter), action)))

    def call(self, fn: Callable[..., Any], *args: Any) -> Any:
        """Run ``fn(*args)`` in the fleet's loop thread (directly when already there or not running)."""
        loop = self._loop
        if (
            loop is None
            or not loop.is_running()
            or self._thread is None
            or threading.current_thread() is self._thread
        ):
            return fn(*args)

        async def call_in_loop() -> Any:
            return fn(*args)

        return asyncio.run_coroutine_threadsafe(call_in_loop(), loop).result(timeout=10.0)

    def _select(self, sysid: int | None) -> list[MockVehicle]:
        """Every vehicle with ``sysid`` (duplicates included), all for None; KeyError if none."""
        if sysid is None:
            return list(self.vehicles)
        return [v for v in self.vehicles if v.sysid == sysid] or [self.vehicle(sysid)]

    def _set_rows(self, array: np.ndarray, sysid: int | None, value: tuple[float, float, float]) -> None:
        vec = np.asarray(value, dtype=float)
        if not np.all(np.isfinite(vec)):
            raise ValueError(f"wind/drift must be finite, got {value!r}")
        for v in self._select(sysid):
            array[v.index] = vec

    # --- the tick ----------------------------------------------------------------------------
    async def _run(self) -> None:
        loop = asyncio.get_running_loop()
        now = loop.time()
        n = len(self.vehicles)
        pos_rate, status_rate, home_rate = self.rates_hz
        streams = (
            telemetry.StreamSchedule(n, pos_rate, now),
            telemetry.StreamSchedule(n, status_rate, now),
            telemetry.StreamSchedule(n, home_rate, now),
        )
        self._wall_base, self._sim_base = now, self.world.sim_time_s
        if self.clock_zero_s is not None:  # on the ground until the first mission: nothing to step
            self._sim_base = self.speedup * (time.monotonic() - self.clock_zero_s)
            self.world.sim_time_s = max(0.0, self._sim_base)
        for v in self.vehicles:
            v.link.batching = self.batch_frames and not v.profile.frame_per_datagram
        while True:
            now = loop.time()
            self._advance(now)
            for v in self.vehicles:
                v.poll(now)
            self._stream(now, *streams)
            for v in self.vehicles:
                v.link.flush()
            self.ticks += 1
            await asyncio.sleep(max(0.0, self.tick_s - (loop.time() - now)))

    def _advance(self, wall_now_s: float) -> None:
        dt = self.physics_dt_s
        target = self._sim_base + self.speedup * (wall_now_s - self._wall_base)
        steps = int((target - self.world.sim_time_s) / dt + 1e-9)
        max_steps = max(1, math.ceil(self.speedup * MAX_CATCH_UP_WALL_S / dt))
        if steps > max_steps:
            self.lag_events += 1
            if self.lag_events in (1, 10, 100) or self.lag_events % 1000 == 0:
                log.warning("MockFleet cannot keep up with speed-up %.1f: simulated time slips (%d times)",
                            self.speedup, self.lag_events)  # fmt: skip
            steps = max_steps
            self._wall_base, self._sim_base = wall_now_s, self.world.sim_time_s + steps * dt
        for _ in range(steps):
            self._step(dt)

    def _step(self, dt: float) -> None:
        world = self.world
        world.step(dt)
        for i in np.flatnonzero(world.kin.arrived()):
            self.vehicles[i].nav.on_arrived()
        for i in np.flatnonzero(world.timers <= world.sim_time_s):
            world.timers[i] = np.inf
            self.vehicles[i].nav.on_timer()
        while self._script and self._script[0][0] <= world.sim_time_s:
            _, _, action = heapq.heappop(self._script)
            action(self)

    def _stream(
        self,
        now: float,
        positions: telemetry.StreamSchedule,
        status: telemetry.StreamSchedule,
        homes: telemetry.StreamSchedule,
    ) -> None:
        vehicles = self.vehicles
        due = positions.due(now).tolist()
        idx = [i for i in due if vehicles[i].link.peers and vehicles[i].wants(_POSITION)]
        if idx:
            kin = self.world.kin
            pos = kin.reported_pos()[idx]
            lat, lon, alt = to_geodetic(pos[:, 0], pos[:, 1], pos[:, 2], self.home)
            rel = (pos[:, 2] - kin.ground_z[idx]).tolist()
            vel = kin.ground_vel()[idx].tolist()
            psi, roll, pitch, rate = (a[idx].tolist() for a in (kin.psi, kin.roll, kin.pitch, kin.turn_rate))
            lat, lon, alt = lat.tolist(), lon.tolist(), alt.tolist()
            period_s = positions.period_s * self.speedup  # of vehicle time
            for k, i in enumerate(idx):
                v = vehicles[i]
                t_ms = v.time_boot_ms
                fix = (lat[k], lon[k], alt[k], rel[k], vel[k]) if v.has_position else _NO_FIX
                v.send(telemetry.global_position_int(t_ms, *fix, psi[k]))
                if v.wants(_ATTITUDE) and v.due(_ATTITUDE, period_s):
                    v.send(telemetry.attitude(t_ms, roll[k], pitch[k], psi[k], rate[k]))
        for i in status.due(now).tolist():
            if vehicles[i].link.peers:
                vehicles[i].send_status()
        for i in homes.due(now).tolist():
            if vehicles[i].link.peers:
                vehicles[i].stream_home()
