"""The mock fleet of a coalition HIL run (run in its own process by sitl_mock.process).

Every awarded vehicle is a mock fixed wing. Its home is south of its first mission's start by the
take-off's ground run (the mock climbs heading north), so the climb ends where the route starts.
Take-off climbs at ``TAKEOFF_CLIMB_MPS`` (the climb is not part of the measurement and a real
fleet would be airborne before the scenario starts). The airframe is tuned like fly._airframe_for,
with bank for the minimum turn radius at the schedule keeper's top speed (CATCH_UP_FACTOR x
cruise), so catching up does not widen turns.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from gcs_planner.coalition_hil.missions import VehicleSchedule
from gcs_planner.fly import CATCH_UP_FACTOR, G_MPS2, MAX_WALL_TELEMETRY_HZ, MOCK_TELEMETRY_HZ, _airframe_for
from gcs_planner.geo import Origin, enu_to_geodetic
from sitl_mock.flight import climb_run_m
from sitl_mock.process import MockFleetProcess

__all__ = ["mock_fleet"]

TAKEOFF_CLIMB_MPS = 40.0  # mock climb rate for the take-off only


def mock_fleet(schedules: list[VehicleSchedule], origin: Origin, speedup: float) -> MockFleetProcess:
    """The (not yet started) fleet process: one mock fixed wing per schedule, homed for its climb.
    Its own process, because sharing the GCS's core left an upload of 50 items taking 10 s of flight
    time at speed-up 20."""
    specs = []
    for s in schedules:
        vp = s.initial
        frame = _airframe_for(vp)
        run_m = climb_run_m(float(vp.speeds_mps[0]), TAKEOFF_CLIMB_MPS, float(vp.waypoints[0, 2]))
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
    return MockFleetProcess(vehicles=specs, speedup=speedup, home=origin, rate_hz=rate_hz)
