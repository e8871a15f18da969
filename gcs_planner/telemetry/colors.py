"""One colour per vehicle, the same in Foxglove (GeoJSON/LocationFix) and Rerun views.

Tableau-10 by system id, so vehicle 1 is blue, 2 orange, 3 green ... in every view of every log.
"""

from __future__ import annotations

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


def vehicle_color(sysid: int) -> tuple[int, int, int, int]:
    """RGBA [0-255] of vehicle ``sysid``."""
    r, g, b = _PALETTE[(sysid - 1) % len(_PALETTE)]
    return r, g, b, 255
