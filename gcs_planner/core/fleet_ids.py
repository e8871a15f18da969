"""Fleet ids: a vehicle named across MAVLink networks, ``network x 256 + sysid`` (mavlink/networks.py).

On network 0 the fleet id is the MAVLink system id itself. No imports: scenario and plan code
use these without loading the MAVLink stack.
"""

from __future__ import annotations

__all__ = ["MAX_NETWORK", "NETWORK_SPAN", "fleet_id", "id_runs", "network_of", "wire_sysid"]

NETWORK_SPAN = 256  # fleet id = network x NETWORK_SPAN + sysid
MAX_NETWORK = 63  # networks 0..63: 16,000 vehicles


def fleet_id(network: int, sysid: int) -> int:
    return network * NETWORK_SPAN + sysid


def network_of(vehicle: int) -> int:
    return vehicle // NETWORK_SPAN


def wire_sysid(vehicle: int) -> int:
    """The MAVLink system id of fleet id ``vehicle`` on its own network."""
    return vehicle % NETWORK_SPAN


def id_runs(ids) -> str:
    """Ids as sorted runs, for a line about many vehicles: [1, 2, 3, 7] -> "1-3, 7"."""
    runs: list[list[int]] = []
    for i in sorted(ids):
        if runs and i == runs[-1][1] + 1:
            runs[-1][1] = i
        else:
            runs.append([i, i])
    return ", ".join(str(a) if a == b else f"{a}-{b}" for a, b in runs)
