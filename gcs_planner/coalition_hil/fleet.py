"""The mock fleet of a coalition HIL run, in its own process.

Every awarded vehicle is a mock fixed wing. Its home is south of its first mission's start by the
take-off's ground run (the mock climbs heading north), so the climb ends where the route starts.
Take-off climbs at ``TAKEOFF_CLIMB_MPS`` (the climb is not part of the measurement and a real
fleet would be airborne before the scenario starts). The airframe is tuned like fly._airframe_for,
with bank for the minimum turn radius at the schedule keeper's top speed (CATCH_UP_FACTOR x
cruise), so catching up does not widen turns.
"""

from __future__ import annotations

import multiprocessing
from dataclasses import replace

import numpy as np

from gcs_planner.coalition_hil.missions import VehicleSchedule
from gcs_planner.errors import UserError
from gcs_planner.fly import CATCH_UP_FACTOR, G_MPS2, MAX_WALL_TELEMETRY_HZ, MOCK_TELEMETRY_HZ, _airframe_for
from gcs_planner.geo import Origin, enu_to_geodetic
from sitl_mock.flight import ALT_TOL_M, KP_ALT

__all__ = ["FleetProcess", "mock_fleet"]

TAKEOFF_CLIMB_MPS = 40.0  # mock climb rate for the take-off only
FLEET_START_S = 30.0  # the mock fleet's process must be serving within this [s]


def _serve_fleet(conn, kwargs: dict) -> None:
    """Child process: run a MockFleet, send its addresses, run until told to stop, send its lag count."""
    from sitl_mock import MockFleet

    with MockFleet(**kwargs) as fleet:
        conn.send(fleet.addresses)
        conn.recv()
        lag = fleet.lag_events
    conn.send(lag)


class FleetProcess:
    """The mock fleet in its own process. In the GCS's process the fleet's thread shares the GIL,
    so the simulation, telemetry parsing, planning and uploads all ran on one core; at speed-up 20
    with 26 vehicles that core was saturated and an upload of 50 items took 10 s of flight time."""

    def __init__(self, **kwargs) -> None:
        self.kwargs = kwargs
        self.addresses: list[tuple[str, int]] = []
        self.lag_events = 0

    def __enter__(self) -> FleetProcess:
        ctx = multiprocessing.get_context("spawn")
        self._conn, child = ctx.Pipe()
        self._proc = ctx.Process(target=_serve_fleet, args=(child, self.kwargs), daemon=True)
        self._proc.start()
        if not self._conn.poll(FLEET_START_S):
            self._proc.terminate()
            raise UserError(f"the mock fleet process did not start within {FLEET_START_S} s")
        self.addresses = self._conn.recv()
        return self

    def __exit__(self, *exc: object) -> None:
        try:
            self._conn.send("stop")
            if self._conn.poll(10.0):
                self.lag_events = int(self._conn.recv())
        except (BrokenPipeError, EOFError):
            pass
        self._proc.join(10.0)
        if self._proc.is_alive():
            self._proc.terminate()


def mock_fleet(schedules: list[VehicleSchedule], origin: Origin, speedup: float) -> FleetProcess:
    """The (not yet started) fleet process: one mock fixed wing per schedule, homed for its climb."""
    specs = []
    for s in schedules:
        vp = s.initial
        frame = _airframe_for(vp)
        run_m = _climb_run_m(float(vp.speeds_mps[0]), TAKEOFF_CLIMB_MPS, float(vp.waypoints[0, 2]))
        lat, lon, alt = enu_to_geodetic(vp.waypoints[0, 0], vp.waypoints[0, 1] - run_m, 0.0, origin)
        fast = CATCH_UP_FACTOR * float(vp.speeds_mps[0])
        bank = float(np.arctan(fast**2 / vp.turn_radius_m / G_MPS2))
        frame = replace(frame, max_bank_rad=max(frame.max_bank_rad, bank), climb_rate_mps=TAKEOFF_CLIMB_MPS)
        specs.append(
            dict(
                sysid=vp.sysid,
                home=Origin(lat, lon, alt),
                vehicle_type="fixed_wing",
                profile="ardupilot",
                airframe=frame,
            )
        )
    rate_hz = min(MOCK_TELEMETRY_HZ * speedup, MAX_WALL_TELEMETRY_HZ)
    return FleetProcess(vehicles=specs, speedup=speedup, home=origin, rate_hz=rate_hz)


def _climb_run_m(speed_mps: float, climb_mps: float, alt_m: float, dt_s: float = 0.05) -> float:
    """Ground run [m] of the mock fixed wing's take-off climb (north, at cruise speed, vz = KP_ALT x
    error clipped to the climb rate and 0.9 v), so that its home can be placed that far south of
    where the route starts."""
    z, run = 0.0, 0.0
    while z < alt_m - ALT_TOL_M:
        vz = min(KP_ALT * (alt_m - z), climb_mps, 0.9 * speed_mps)
        z += vz * dt_s
        run += float(np.sqrt(speed_mps**2 - vz**2)) * dt_s
    return run
