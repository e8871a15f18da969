"""Where a flight's vehicles come from: a VehicleSource starts them (or not) and says how to reach them.

``fly`` and the coalition HIL run take a source instead of starting mock autopilots themselves, so
the flight code never imports the mock: real vehicles or SITL are ``ConnectedVehicles(urls)``, the
mock fleet (sitl_mock) is found through the ``gcs_planner.vehicle_sources`` entry point
(pyproject.toml) by ``mock_vehicles``. Layers import one way: sitl_mock uses gcs_planner's MAVLink
core and plan types; nothing in gcs_planner imports sitl_mock.
"""

from __future__ import annotations

from collections.abc import Sequence
from importlib.metadata import entry_points
from typing import Protocol

from gcs_planner.core.errors import UserError
from gcs_planner.model.plan import VehiclePlan

__all__ = ["ROUTE_ACCEL_MPS2", "ConnectedVehicles", "MixedVehicles", "VehicleSource", "mock_vehicles"]

ROUTE_ACCEL_MPS2 = 2.5  # real vehicles' assumed acceleration from the hover (ArduCopter WPNAV_ACCEL)
ENTRY_POINT_GROUP = "gcs_planner.vehicle_sources"


class VehicleSource(Protocol):
    """Vehicles for one flight. ``simulated``: they share one simulated clock (time_boot_ms) that
    runs ``speedup`` times faster than the flight's loop clock; real vehicles run at 1 on their
    own clocks. ``lockstep``: they run in the flight's own event loop, which must then be a
    gcs_planner.core.lockstep.LockstepLoop (``lockstep.run``), so that one clock serves both sides.
    ``own_parameters``: they fly their legs as their autopilot does, by the parameters they serve
    (real vehicles, SITL, mocks with ArduCopter's S-curve legs): the flight reads those parameters
    and leads each route's start by the autopilot's measured latency; otherwise (mocks tuned to the
    plan) it takes ``accel_mps2``."""

    simulated: bool
    lockstep: bool
    speedup: float
    own_parameters: bool

    async def __aenter__(self) -> list[list[str]]:
        """Start the vehicles (if this source runs them); the link URLs that reach each network
        (one list for a fleet of at most 254; fleet ids, mavlink/networks.py)."""

    async def __aexit__(self, *exc: object) -> None:
        """Stop what ``__aenter__`` started."""

    def sim_time_s(self) -> float | None:
        """The vehicles' simulated clock now, where this process runs it (None: it does not)."""

    def accel_mps2(self, sysid: int) -> float:
        """The vehicle's acceleration from the hover [m/s^2] (route starts lead by v / 2a)."""

    def homed_here(self, sysid: int) -> bool:
        """Whether this source stood the vehicle at its start itself (a mock homed for its plan):
        the pre-flight gate checks only the others."""

    def set_drift(self, sysid: int, east_mps: float, north_mps: float) -> None:
        """Fault injection: a wind-like drift on one vehicle (mock vehicles only)."""

    @property
    def lag_events(self) -> int:
        """How often a simulator fell behind its speed-up (0 for real vehicles)."""


class ConnectedVehicles:
    """Vehicles this tool does not start: real autopilots or SITL reached at ``urls``, or with
    ``per_network``, each URL a network of its own (network k: the k-th URL). ``speedup``: the
    rate their clocks run at (1 for real vehicles; SITL's --speedup). ``lockstep``: they run in
    the flight's own loop (a mock fleet a test treats as connected vehicles)."""

    simulated = False
    own_parameters = True
    lag_events = 0

    def __init__(
        self, urls: Sequence[str], per_network: bool = False, speedup: float = 1.0, lockstep: bool = False
    ) -> None:
        self.networks = [[u] for u in urls] if per_network else [list(urls)]
        self.speedup = float(speedup)
        self.lockstep = lockstep

    async def __aenter__(self) -> list[list[str]]:
        return self.networks

    async def __aexit__(self, *exc: object) -> None:
        pass

    def sim_time_s(self) -> float | None:
        return None

    def accel_mps2(self, sysid: int) -> float:
        return ROUTE_ACCEL_MPS2

    def homed_here(self, sysid: int) -> bool:
        return False

    def set_drift(self, sysid: int, east_mps: float, north_mps: float) -> None:
        raise UserError("--drift injects a fault into mock vehicles; it cannot act on connected vehicles")


class MixedVehicles:
    """Some vehicles connected (``connected``: real or SITL), the rest mock vehicles (``mock``),
    on one network and one link. Their clocks differ, so the flight times frames on receipt
    (``simulated`` is False); the mock runs at the connected vehicles' rate, in lockstep with the
    flight where they are."""

    simulated = False
    own_parameters = True

    def __init__(self, mock: VehicleSource, connected: ConnectedVehicles, mock_sysids: set[int]) -> None:
        self.mock, self.connected, self.mock_sysids = mock, connected, mock_sysids
        self.speedup = connected.speedup
        self.lockstep = connected.lockstep

    async def __aenter__(self) -> list[list[str]]:
        (mock_urls,) = await self.mock.__aenter__()
        return [mock_urls + self.connected.networks[0]]

    async def __aexit__(self, *exc: object) -> None:
        await self.mock.__aexit__(*exc)

    def sim_time_s(self) -> float | None:
        return None

    def _source(self, sysid: int) -> VehicleSource:
        return self.mock if sysid in self.mock_sysids else self.connected

    def accel_mps2(self, sysid: int) -> float:
        return self._source(sysid).accel_mps2(sysid)

    def homed_here(self, sysid: int) -> bool:
        return self._source(sysid).homed_here(sysid)

    def set_drift(self, sysid: int, east_mps: float, north_mps: float) -> None:
        self._source(sysid).set_drift(sysid, east_mps, north_mps)

    def cut_link(self, sysid: int) -> None:
        """A mock vehicle's link goes dead (fault injection); a connected vehicle's cannot be cut."""
        if sysid not in self.mock_sysids:
            raise UserError(f"sysid {sysid} is connected: only a mock vehicle's link can be cut")
        self.mock.cut_link(sysid)

    @property
    def lag_events(self) -> int:
        return self.mock.lag_events


def mock_vehicles(kind: str, plans: Sequence[VehiclePlan], **options) -> VehicleSource:
    """The mock fleet ``kind`` ("mock": in this process, "mock-process": its own process) for
    ``plans``, one mock autopilot per VehiclePlan, from the installed entry point."""
    found = {ep.name: ep for ep in entry_points(group=ENTRY_POINT_GROUP)}
    if kind not in found:
        raise UserError(
            f"no vehicle source {kind!r} is installed (known: {sorted(found)}); install gcs-planner with"
            " its sitl_mock package (pip install -e .)"
        )
    return found[kind].load()(plans, **options)
