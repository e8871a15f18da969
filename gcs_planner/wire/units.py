"""MAVLink number conventions without numpy: degE7 rounding, DO_CHANGE_SPEED speed types, no fix.

Kept apart from items.py (numpy, pyproj) so that a short command reading a mission file starts fast.
"""

from __future__ import annotations

import math

__all__ = [
    "NO_FIX_DEG", "SPEED_AIRSPEED", "SPEED_GROUNDSPEED", "e7", "half_away", "impossible_position", "no_fix",
    "off_the_globe", "reports_no_fix",
]  # fmt: skip

SPEED_AIRSPEED, SPEED_GROUNDSPEED = 0.0, 1.0  # MAV_CMD_DO_CHANGE_SPEED param1
NO_FIX_DEG = 0.01  # a reported position this near (0, 0) is no position (no_fix)


def e7(deg: float) -> int:
    """One value in degrees -> degE7 int, rounded half away from zero (as items.deg_to_e7)."""
    return half_away(float(deg) * 1e7)


def half_away(value: float) -> int:
    """One value rounded to the nearest int, halves away from zero."""
    return int(math.copysign(math.floor(abs(value) + 0.5), value))


def no_fix(lat_deg, lon_deg):
    """Where a reported position (floats or numpy arrays) is within NO_FIX_DEG of (0, 0): ArduPilot's
    GLOBAL_POSITION_INT before it has a position, (0, 0) and then its dead reckoning from there
    (docs/real-autopilots.md)."""
    return (abs(lat_deg) < NO_FIX_DEG) & (abs(lon_deg) < NO_FIX_DEG)


def reports_no_fix(msg) -> bool:
    """A GLOBAL_POSITION_INT that carries no position: none yet (``no_fix`` of its degE7 lat, lon)
    or an impossible one (``impossible_position``)."""
    return bool(no_fix(msg.lat * 1e-7, msg.lon * 1e-7)) or impossible_position(msg)


def impossible_position(msg) -> bool:
    """A GLOBAL_POSITION_INT past a pole or the antimeridian (a valid int32 all the same)."""
    return bool(off_the_globe(msg.lat, msg.lon))


def off_the_globe(lat_e7, lon_e7):
    """Where degE7 latitudes and longitudes (ints or numpy arrays) are past a pole or the antimeridian."""
    return (abs(lat_e7) > 900_000_000) | (abs(lon_e7) > 1_800_000_000)
