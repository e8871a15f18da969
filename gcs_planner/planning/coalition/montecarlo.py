"""Seed 003's Monte Carlo world (sections 5.2-5.3): a random fleet against the scenario's targets.

``run`` is a sweep task (``task = "gcs_planner.planning.coalition.montecarlo:run"`` in a study): it
draws ``uavs`` UAVs in the paper's Table 1 type mix (11:11:10) at random positions and headings in
the 8 x 7 km area, keeps the scenario's targets and needs without threats or preset recon
vehicles, applies the other parameters to the [planner] table and runs the event simulation.
benchmarks/coalition_montecarlo.py runs the same function.
"""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path
from typing import Any

import msgspec
import numpy as np

from gcs_planner.planning import load_scenario
from gcs_planner.planning.coalition import simulate
from gcs_planner.planning.coalition.model import UavSpec, World, load_world

__all__ = ["random_world", "run"]

# the paper's Table 1 types: recon-strike-assess (munitions set per UAV), strike, recon-assess
_RECON_STRIKE = dict(altitude_m=300.0, speed_mps=50.0, r_min_m=150.0, range_max_m=18000.0,
                     recon=True, strike=True, assess=True)  # fmt: skip
_STRIKE = dict(altitude_m=500.0, speed_mps=60.0, r_min_m=200.0, range_max_m=26000.0, munitions=4,
               recon=False, strike=True, assess=False)  # fmt: skip
_RECON = dict(altitude_m=400.0, speed_mps=50.0, r_min_m=150.0, range_max_m=20000.0, munitions=0,
              recon=True, strike=False, assess=True)  # fmt: skip


def random_world(base: World, n: int, seed: int, **params: Any) -> World:
    """n UAVs in the Table 1 mix at random positions / headings; base's targets, no threats."""
    rng = np.random.default_rng(seed)
    n_rse, n_s = round(n * 11 / 32), round(n * 11 / 32)
    xy = rng.uniform([500.0, 500.0], [7500.0, 6500.0], (n, 2))
    heading = rng.uniform(-math.pi, math.pi, n)
    uavs = []
    for i in range(n):
        if i < n_rse:
            kind = {**_RECON_STRIKE, "munitions": 2 if i < n_rse // 2 else 1}
        else:
            kind = _STRIKE if i < n_rse + n_s else _RECON
        uavs.append(
            UavSpec(i, f"U{i + 1}", i + 1, (float(xy[i, 0]), float(xy[i, 1])), float(heading[i]), **kind)
        )
    targets = [replace(t, recon_uav=None) for t in base.targets]
    return World(uavs, targets, threats=[], params=msgspec.structs.replace(base.params, **params))


def run(scenario: Path, params: dict[str, Any], seed: int) -> dict[str, Any]:
    """One Monte Carlo run: ``params`` holds ``uavs`` and any [planner] value (``jitter_fraction``
    sets delay_jitter_s to that share of delay_s, as the communication study pairs them); the same
    seed draws the world and drives the simulation. Metrics: J, completion_s, served, optimiser_s."""
    params = dict(params)
    n = int(params.pop("uavs"))
    if "jitter_fraction" in params:
        params["delay_jitter_s"] = params.pop("jitter_fraction") * params["delay_s"]
    world = random_world(load_world(load_scenario(scenario)), n, seed, **params)
    res = simulate(world, np.random.default_rng(seed))
    formed = [e for e in res.events if e["event"] == "formed"]
    return {
        "J": res.effectiveness,
        "completion_s": res.completion_s,
        "served": sum(o.t_done_s is not None for o in res.outcomes.values()) / len(res.outcomes),
        "optimiser_s": float(np.mean([e["optimiser_s"] for e in formed])) if formed else math.nan,
    }
