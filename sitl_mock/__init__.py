"""Pure-Python mock autopilot fleet: MAVLink over UDP, mission protocol, kinematic flight, faults.

Public API: `MockFleet` (many vehicles, one loop), `MockVehicle` (one autopilot), `LinkFaults`
(per-link loss, delay, jitter, duplication, reordering). See docs/sitl-mock.md.
"""

from sitl_mock.faults import LinkFaults
from sitl_mock.fleet import MockFleet, VehicleSnapshot
from sitl_mock.flight import AIRFRAMES, Airframe
from sitl_mock.mission_server import Failure
from sitl_mock.vehicle import DEFAULT_HOME, MockVehicle, VehicleState

__all__ = [
    "AIRFRAMES",
    "Airframe",
    "DEFAULT_HOME",
    "Failure",
    "LinkFaults",
    "MockFleet",
    "MockVehicle",
    "VehicleSnapshot",
    "VehicleState",
]
