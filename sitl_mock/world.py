"""Shared simulated world of one fleet: frame origin, simulated clock, kinematics, timers, batteries.

Everything indexed by vehicle lives in arrays here so a fleet tick touches all vehicles with a
few numpy operations; vehicles keep only their own index.

Battery model (open choice): a linear drain of ``DRAIN_PCT_PER_S`` while airborne, a tenth of it
while armed on the ground, nothing disarmed; the current [A] follows the same three levels.
"""

from __future__ import annotations

import numpy as np

from sitl_mock.flight import Airframe, Kinematics
from sitl_mock.geodesy import HomeLike

__all__ = ["World"]

DRAIN_PCT_PER_S = 100.0 / (20 * 60)  # a full battery lasts 20 min of flight
CURRENT_A = {"airborne": 15.0, "armed": 1.5, "idle": 0.3}


class World:
    """Simulated time [s], kinematics and per-vehicle arrays for ``len(airframes)`` vehicles."""

    def __init__(self, frame: HomeLike, airframes: list[Airframe], ground_enu_m: np.ndarray) -> None:
        n = len(airframes)
        self.frame = frame
        self.kin = Kinematics(airframes, ground_enu_m)
        self.sim_time_s = 0.0
        self.timers = np.full(n, np.inf)  # sim time a vehicle asked to be woken at [s]
        self.armed = np.zeros(n, dtype=bool)
        self.battery_pct = np.full(n, 100.0)
        self.consumed_mah = np.zeros(n)

    def current_a(self) -> np.ndarray:
        air = self.kin.airborne()
        return np.where(
            air, CURRENT_A["airborne"], np.where(self.armed, CURRENT_A["armed"], CURRENT_A["idle"])
        )

    def step(self, dt_s: float) -> None:
        """Advance kinematics, clock and batteries by ``dt_s`` [s]."""
        self.kin.step(dt_s)
        self.sim_time_s += dt_s
        air = self.kin.airborne()
        drain = np.where(air, DRAIN_PCT_PER_S, np.where(self.armed, 0.1 * DRAIN_PCT_PER_S, 0.0))
        self.battery_pct = np.maximum(self.battery_pct - drain * dt_s, 0.0)
        self.consumed_mah += self.current_a() * dt_s / 3.6
