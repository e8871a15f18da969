"""Keep freed heap memory for the next numpy temporaries instead of handing it back at once.

glibc gives the top of its heap back to the kernel as soon as more than its trim threshold is
free there. A planner that allocates and frees arrays of a few MB thousands of times (the 4-D
planner's pair checks) then has every new array's pages faulted in afresh: 740 k page faults and
1.7 s of system time in a 7 s plan of 100 UAVs (docs/results/deconflict_100uav.md). A top pad
keeps that much slack above the heap's top, so the same pages are reused.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import functools
import sys

__all__ = ["keep_heap_slack"]

M_TOP_PAD = -2  # glibc mallopt parameter
TOP_PAD_BYTES = 64 << 20


@functools.cache
def keep_heap_slack() -> bool:
    """Ask glibc to keep TOP_PAD_BYTES above the heap top (once per process); False elsewhere."""
    if not sys.platform.startswith("linux"):
        return False
    name = ctypes.util.find_library("c")
    try:
        return bool(ctypes.CDLL(name).mallopt(M_TOP_PAD, TOP_PAD_BYTES)) if name else False
    except (OSError, AttributeError):  # a libc without mallopt (musl)
        return False
