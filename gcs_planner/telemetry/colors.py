"""One colour per vehicle, the same in Foxglove (GeoJSON/LocationFix) and Rerun views.

Tableau-10 for system ids 1-10, so vehicle 1 is blue, 2 orange, 3 green ... in every view of
every log; past 10 (a swarm) hues a golden angle apart, so no two vehicles of a fleet share one.
"""

from __future__ import annotations

import colorsys

__all__ = ["vehicle_color"]

_PALETTE = (
    (31, 119, 180),
    (255, 127, 14),
    (44, 160, 44),
    (214, 39, 40),
    (148, 103, 189),
    (140, 86, 75),
    (227, 119, 194),
    (127, 127, 127),
    (188, 189, 34),
    (23, 190, 207),
)


GOLDEN_FRACTION = 0.6180339887498949  # hue step past the palette: spreads any count of hues evenly


def vehicle_color(sysid: int) -> tuple[int, int, int, int]:
    """RGBA [0-255] of vehicle ``sysid``."""
    if 1 <= sysid <= len(_PALETTE):
        return (*_PALETTE[sysid - 1], 255)
    hue = (sysid * GOLDEN_FRACTION) % 1.0
    value = 0.95 - 0.25 * (sysid % 3) / 2  # alternate brightness: neighbours in hue still differ
    r, g, b = colorsys.hsv_to_rgb(hue, 0.75, value)
    return round(255 * r), round(255 * g), round(255 * b), 255
