"""Every planner's compiled kernels loaded once, on tiny problems, before the work that is timed.

numba compiles a kernel at its first call after an install (~30 s for all of them) and loads it
from its on-disk cache in every later process (~10 ms a kernel, ~0.2 s of LLVM start-up). A sweep's
worker calls this before its first run, so that no run carries that; a user may run it after an
install (docs/planners.md, "Compiled kernels").

    python -m gcs_planner.planning.warm
"""

from __future__ import annotations

import numpy as np

from gcs_planner.geometry.dubins import shortest_path
from gcs_planner.planning import parse_scenario, plan_scenario

__all__ = ["load_kernels"]

_ORIGIN = {"lat_deg": 47.4, "lon_deg": 8.5, "alt_m": 488.0}

# two vehicles crossing, one with a tower in its way (RRT* grows a tree), each landing at its goal
_SWARM = {
    "name": "kernels-swarm",
    "origin": _ORIGIN,
    "planner": {"name": "priority_swarm", "waypoints": 2, "particles": 4, "iterations": 2, "rounds": 1,
                "rrt_iterations": 20},
    "vehicles": [
        {"id": "a", "sysid": 1, "start": [0.0, -200.0, 30.0], "goal": [0.0, 200.0, 30.0], "landing_mps": 1.0},
        {"id": "b", "sysid": 2, "start": [-200.0, 0.0, 30.0], "goal": [200.0, 0.0, 30.0], "landing_mps": 1.0},
    ],
    "obstacles": {"cylinders": [{"x": 0.0, "y": 100.0, "radius_m": 10.0, "z_max_m": 100.0}]},
}  # fmt: skip

# two vehicles crossing under a schedule error, a manned aircraft passing (pair and zone checks)
_DECONFLICT = {
    "name": "kernels-4d",
    "origin": _ORIGIN,
    "planner": {"name": "deconflict_4d", "iterations": 2, "particles": 4, "timing_error_s": 0.5},
    "vehicles": [
        {"id": "a", "sysid": 1, "start": [8.0, 0.0, 10.0], "goal": [-8.0, 0.0, 10.0], "speed_mps": 4.0},
        {"id": "b", "sysid": 2, "start": [0.0, 8.0, 10.0], "goal": [0.0, -8.0, 10.0], "speed_mps": 4.0},
    ],
    "manned": [
        {"id": "ga", "dt_s": 1.0, "position_m": [-60.0, 6.0, 12.0], "velocity_mps": [10.0, 0.0, 0.0],
         "observed_s": 10.0,
         "modes": [{"name": "cruise", "velocity_mps": [10.0, 0.0, 0.0], "sigma_mps": [0.3, 0.3, 0.1]}]},
    ],
}  # fmt: skip


def load_kernels() -> None:
    """Plan the two tiny scenarios above (each planner's kernels, and those they share) and sample
    a Dubins path (the coalition planner's and the flights' kernels)."""
    for raw in (_SWARM, _DECONFLICT):
        plan_scenario(parse_scenario(raw, raw["name"]))
    shortest_path((0.0, 0.0, 0.0), (100.0, 50.0, 1.0), 20.0).sample(np.linspace(0.0, 50.0, 3))


if __name__ == "__main__":
    load_kernels()
