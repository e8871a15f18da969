"""Mock fleets for a plan: one mock autopilot per VehiclePlan, homed and tuned for it.

These are gcs_planner's vehicle sources (gcs_planner.flight.vehicles.VehicleSource), registered as the
``gcs_planner.vehicle_sources`` entry points "mock" (MockVehicles, for ``fly``) and "mock-process"
(MockVehiclesProcess, the coalition HIL run's planes). Without a ``speedup`` a fleet runs in the
flight's own event loop in lockstep with it (gcs_planner.core.lockstep: one virtual clock, as fast as
the CPU allows, the same flight however busy the machine); with one it is paced by the wall clock
at that rate, in a thread (``fly``) or its own process (the coalition run, whose in-flight
planning would otherwise share a core with 32 simulated vehicles), for a GCS on its own clock.

Each airframe is tuned to its planned vehicle as one would set SITL parameters (``airframe_for``):
the plan's speed and turn radius need a lateral acceleration of v^2 / R and its steepest legs a
climb and sink rate of v x slope; a fixed wing gets at least that bank, both those vertical rates
and a top speed with headroom (CATCH_UP_FACTOR) for the schedule keeper to catch up. A multirotor
gets the acceleration of its turns flown at that catch-up speed, (CATCH_UP_FACTOR v)^2 / R (WP_ACC /
MPC_ACC_HOR set for the plan): that limit also sets its corner speed (sitl_mock.flight), and with
v^2 / R alone it could neither hold the planned speed through a Dubins arc's waypoint samples nor
catch up there (docs/timing-separation.md). A fixed wing's bank stays at the plan's: its L1 turns
are fitted to ArduPlane SITL's (sitl_mock.l1). A fixed wing's home is its take-off climb run south
of its first waypoint (the mock climbs heading north), so it reaches the waypoint at its altitude
and flies on.
"""

from __future__ import annotations

import contextlib
import time
from collections.abc import Sequence
from dataclasses import replace
from typing import Protocol

import numpy as np

from sitl_mock.faults import LinkFaults
from sitl_mock.fleet import MockFleet
from sitl_mock.flight import AIRFRAMES, G_MPS2, Airframe, climb_run_m
from sitl_mock.geodesy import Home, HomeLike, to_geodetic
from sitl_mock.l1 import L1Plane
from sitl_mock.process import MockFleetProcess

__all__ = ["CATCH_UP_FACTOR", "MockVehicles", "MockVehiclesProcess", "PlannedVehicle", "airframe_for"]

CATCH_UP_FACTOR = 1.3  # mock top speed / planned speed (headroom for schedule keeping)
PHYSICS_DT_S = 0.05  # the mock's physics step [s of flight time]
MOCK_TELEMETRY_HZ = 10.0  # wanted position-report rate [Hz of flight time]
MAX_WALL_TELEMETRY_HZ = 40.0  # cap per vehicle [Hz of wall time] so the mock keeps up
FLY_TAKEOFF_CLIMB_MPS = 2.0  # a fixed wing's take-off climb in `fly`: the rate its flight-time budget assumes
HIL_TAKEOFF_CLIMB_MPS = 40.0  # coalition HIL: the take-off is not part of the measurement
# fleet ids name a vehicle across MAVLink networks: fleet id = network x 256 + sysid (the interface
# between the GCS and its vehicle sources, documented in gcs_planner/core/fleet_ids.py and
# gcs_planner/mavlink/networks.py); on network 0 the fleet id is the system id
NETWORK_SPAN = 256


def network_of(fleet_id: int) -> int:
    """The MAVLink network of fleet id ``fleet_id``."""
    return fleet_id // NETWORK_SPAN


def wire_sysid(fleet_id: int) -> int:
    """The MAVLink system id of fleet id ``fleet_id`` on its own network."""
    return fleet_id % NETWORK_SPAN


class PlannedVehicle(Protocol):
    """What a fleet reads of a planned vehicle (a GCS's VehiclePlan has these): its fleet id, airframe
    type, route waypoints and path [m ENU about the fleet origin], planned speeds [m/s], turn radius [m]."""

    @property
    def sysid(self) -> int: ...
    @property
    def vehicle_type(self) -> str: ...  # a key of sitl_mock.flight.AIRFRAMES
    @property
    def waypoints(self) -> np.ndarray: ...  # (N, 3)
    @property
    def path(self) -> np.ndarray: ...  # (M, 3)
    @property
    def speeds_mps(self) -> np.ndarray: ...  # (N,)
    @property
    def turn_radius_m(self) -> float: ...


def airframe_for(vp: PlannedVehicle) -> Airframe:
    """The mock airframe tuned to the planned vehicle (module docstring)."""
    base = AIRFRAMES[vp.vehicle_type]
    speed = float(np.max(vp.speeds_mps))
    if speed <= 0:
        return base
    legs = np.diff(vp.path, axis=0)
    horizontal = np.hypot(legs[:, 0], legs[:, 1])
    slope = (legs[:, 2] / np.maximum(horizontal, 1e-9))[horizontal > 1.0]  # not take-off / landing
    frame = replace(
        base,
        cruise_speed_mps=speed,
        max_speed_mps=max(base.max_speed_mps, CATCH_UP_FACTOR * speed),
        climb_rate_mps=max(base.climb_rate_mps, CATCH_UP_FACTOR * speed * float(np.max(slope, initial=0.0))),
        sink_rate_mps=max(base.sink_rate_mps, -CATCH_UP_FACTOR * speed * float(np.min(slope, initial=0.0))),
    )
    if vp.turn_radius_m <= 0:
        return frame
    if vp.vehicle_type == "fixed_wing":
        lateral_mps2 = speed**2 / vp.turn_radius_m
        return replace(frame, max_bank_rad=max(base.max_bank_rad, float(np.arctan(lateral_mps2 / G_MPS2))))
    lateral_mps2 = (CATCH_UP_FACTOR * speed) ** 2 / vp.turn_radius_m  # the turns at catch-up speed
    return replace(frame, accel_mps2=max(base.accel_mps2, lateral_mps2))


def _home(vp: PlannedVehicle, origin: HomeLike, climb_run: float) -> Home:
    """On the ground under the first waypoint, ``climb_run`` metres south of it."""
    lat, lon, alt = to_geodetic(vp.waypoints[0, 0], vp.waypoints[0, 1] - climb_run, 0.0, origin)
    return Home(float(lat), float(lon), float(alt))


def _fleet_options(speedup: float | None) -> dict:
    """MockFleet's clock options. Lockstep (None): one physics step a tick, reports at
    MOCK_TELEMETRY_HZ of flight time; paced: reports within what one Python process streams."""
    if speedup is None:
        return dict(speedup=1.0, tick_s=PHYSICS_DT_S, physics_dt_s=PHYSICS_DT_S, rate_hz=MOCK_TELEMETRY_HZ)
    return dict(speedup=speedup, rate_hz=min(MOCK_TELEMETRY_HZ * speedup, MAX_WALL_TELEMETRY_HZ))


class _PlanFleet:
    """What both fleets share: the VehicleSource methods over started fleets, one per network
    (fleet ids, gcs_planner.mavlink.networks)."""

    simulated = True
    own_parameters = False  # tuned to the plan: the flight takes accel_mps2

    def __init__(self, fleets: list, airframes: dict[int, Airframe], speedup: float | None):
        self.fleets, self.airframes = fleets, airframes
        self.lockstep = speedup is None
        self.speedup = 1.0 if speedup is None else float(speedup)

    async def __aenter__(self) -> list[list[str]]:
        async with contextlib.AsyncExitStack() as stack:  # a fleet that fails to start stops those started
            for fleet in self.fleets:
                if self.lockstep:
                    await stack.enter_async_context(fleet)
                else:
                    stack.enter_context(fleet)
            self._running = stack.pop_all()
        return [[f"udpout:{h}:{p}" for h, p in fleet.addresses] for fleet in self.fleets]

    async def __aexit__(self, *exc: object) -> None:
        await self._running.__aexit__(*exc)

    def accel_mps2(self, sysid: int) -> float:
        return self.airframes[sysid].accel_mps2

    def homed_here(self, sysid: int) -> bool:
        return True  # every mock stands where _home put it for its plan

    def sim_time_s(self) -> float | None:
        """The fleet's simulated clock now (its vehicles' time_boot_ms), where this process runs it."""
        return getattr(self.fleets[0], "sim_time_s", None)

    def set_drift(self, sysid: int, east_mps: float, north_mps: float) -> None:
        self.fleets[network_of(sysid)].set_drift(wire_sysid(sysid), east_mps, north_mps)

    def cut_link(self, sysid: int) -> None:
        """The vehicle's link goes dead both ways: to the GCS it is lost (it stops reporting)."""
        self.fleets[network_of(sysid)].set_faults(wire_sysid(sysid), LinkFaults(loss=1.0))

    @property
    def lag_events(self) -> int:
        return sum(fleet.lag_events for fleet in self.fleets)


def _networks(specs: list[dict]) -> list[list[dict]]:
    """The vehicle specs of each network 0..max, with their system ids on it."""
    count = 1 + max(network_of(spec["sysid"]) for spec in specs)
    out: list[list[dict]] = [[] for _ in range(count)]
    for spec in specs:
        out[network_of(spec["sysid"])].append({**spec, "sysid": wire_sysid(spec["sysid"])})
    return out


class MockVehicles(_PlanFleet):
    """``fly``'s mock fleet on one simulated clock: in lockstep in the flight's loop (one fleet per
    network), or paced at ``speedup`` in a thread of this process, or, for a plan over several
    networks (fleets past 254), one process per network sharing the clock."""

    def __init__(
        self,
        plans: Sequence[PlannedVehicle],
        origin: HomeLike,
        speedup: float | None = None,
        autopilot: str = "ardupilot",
        scurve_legs: bool = False,
        params: dict[str, float] | None = None,
    ) -> None:
        """``scurve_legs``: multirotors fly ArduCopter's S-curve legs (FlightRules.scurve_legs);
        ``params``: values every vehicle serves instead of its own, as SITL's --defaults file."""
        airframes, specs = {}, []
        for vp in plans:
            frame, run_m = airframe_for(vp), 0.0
            if vp.vehicle_type == "fixed_wing":
                frame = replace(frame, climb_rate_mps=FLY_TAKEOFF_CLIMB_MPS)
                run_m = climb_run_m(frame.cruise_speed_mps, FLY_TAKEOFF_CLIMB_MPS, float(vp.waypoints[0, 2]))
            airframes[vp.sysid] = frame
            specs.append(
                dict(sysid=vp.sysid, home=_home(vp, origin, run_m), vehicle_type=vp.vehicle_type,
                     profile=autopilot, airframe=frame, params=params)
            )  # fmt: skip
        networks = _networks(specs)
        options = dict(
            home=origin, flight={"scurve_legs": True} if scurve_legs else None, **_fleet_options(speedup)
        )
        if speedup is None:
            fleets = [MockFleet(vehicles=n, **options) for n in networks]
        elif len(networks) == 1:
            fleets = [MockFleet(vehicles=specs, **options)]
        else:
            zero = time.monotonic()
            fleets = [MockFleetProcess(vehicles=n, clock_zero_s=zero, **options) for n in networks]
        super().__init__(fleets, airframes, speedup)
        self.own_parameters = scurve_legs


class MockVehiclesProcess(_PlanFleet):
    """The coalition HIL run's fleet: mock fixed wings in their own process (module docstring),
    each with the bank for its minimum turn radius at the keeper's top speed (CATCH_UP_FACTOR x
    cruise), so catching up does not widen turns. With an ``l1`` response they fly ArduPlane's
    L1 guidance (sitl_mock.flight; ``sitl_mock.l1.SITL_PLANE`` is the SITL plane's): a stand-in
    for ArduPlane SITL's wide turns."""

    def __init__(
        self,
        plans: Sequence[PlannedVehicle],
        origin: HomeLike,
        speedup: float | None = None,
        l1: L1Plane | None = None,
    ) -> None:
        airframes, specs = {}, []
        for vp in plans:
            cruise = float(vp.speeds_mps[0])
            run_m = climb_run_m(cruise, HIL_TAKEOFF_CLIMB_MPS, float(vp.waypoints[0, 2]))
            frame = airframe_for(vp)
            gain = l1.turn_gain if l1 else 1.0  # an airframe turning at less than its bank's rate banks more
            bank = float(np.arctan((CATCH_UP_FACTOR * cruise) ** 2 / vp.turn_radius_m / G_MPS2 / gain))
            bank = max(frame.max_bank_rad, bank)
            frame = replace(frame, max_bank_rad=bank, climb_rate_mps=HIL_TAKEOFF_CLIMB_MPS, l1=l1)
            airframes[vp.sysid] = frame
            specs.append(
                dict(sysid=vp.sysid, home=_home(vp, origin, run_m), vehicle_type="fixed_wing",
                     profile="ardupilot", airframe=frame)
            )  # fmt: skip
        if len(_networks(specs)) > 1:
            raise ValueError("the coalition run flies one network: its vehicles need sysids 1..254")
        options = dict(vehicles=specs, home=origin, **_fleet_options(speedup))
        fleet = MockFleet(**options) if speedup is None else MockFleetProcess(**options)
        super().__init__([fleet], airframes, speedup)
