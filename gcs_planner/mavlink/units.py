"""MAVLink number conventions without numpy: degE7 rounding and DO_CHANGE_SPEED speed types.

Kept apart from items.py (numpy, pyproj) so that a short command reading a mission file starts fast.
"""

from __future__ import annotations

import math

__all__ = ["SPEED_AIRSPEED", "SPEED_GROUNDSPEED", "e7", "half_away"]

SPEED_AIRSPEED, SPEED_GROUNDSPEED = 0.0, 1.0  # MAV_CMD_DO_CHANGE_SPEED param1


def e7(deg: float) -> int:
    """One value in degrees -> degE7 int, rounded half away from zero (as items.deg_to_e7)."""
    return half_away(float(deg) * 1e7)


def half_away(value: float) -> int:
    """One value rounded to the nearest int, halves away from zero."""
    return int(math.copysign(math.floor(abs(value) + 0.5), value))
