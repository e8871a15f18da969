"""Replay a flight log: re-emit its raw MAVLink frames over UDP, or render it to Rerun.

MAVLink replay sends every recorded frame byte for byte, in receive order, with the recorded
inter-frame timing divided by ``speed`` (``speed <= 0`` or ``inf``: as fast as possible), so
another GCS (MAVProxy, QGroundControl) pointed at the address sees the flight again. Frames are
sent from one UDP socket, like a single router carrying all vehicles. The schedule is absolute
(time of frame k = start + (t_k - t_0) / speed), so sleep overshoot never accumulates.
"""

from __future__ import annotations

import contextlib
import math
import socket
import time
from collections.abc import Callable

from gcs_planner.errors import UserError
from gcs_planner.telemetry.reader import Flight

__all__ = ["parse_udp_url", "replay_to_mavlink"]


def parse_udp_url(url: str) -> tuple[str, int]:
    """``udpout:HOST:PORT`` (or ``udp:HOST:PORT``) -> (host, port)."""
    scheme, _, rest = url.partition(":")
    host, _, port = rest.rpartition(":")
    if scheme not in ("udpout", "udp") or not host or not port.isdigit() or not 0 < int(port) < 65536:
        raise UserError(f"--to must look like udpout:HOST:PORT, got {url!r}")
    return host, int(port)


def replay_to_mavlink(
    flight: Flight,
    url: str,
    speed: float = 1.0,
    progress: Callable[[int, int], None] | None = None,
    sleep: Callable[[float], None] = time.sleep,
    clock: Callable[[], float] = time.monotonic,
) -> int:
    """Send the flight's raw frames to ``url`` (udpout:HOST:PORT); returns frames sent.

    progress(sent, total) is called about every 100 frames.
    """
    host, port = parse_udp_url(url)
    frames = flight.frames
    if not frames:
        return 0
    realtime = speed > 0 and math.isfinite(speed)
    t0_ns = frames[0].t_ns
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        sock.connect((host, port))
        start = clock()
        for k, frame in enumerate(frames):
            if realtime:
                delay = start + (frame.t_ns - t0_ns) * 1e-9 / speed - clock()
                if delay > 0:
                    sleep(delay)
            with contextlib.suppress(ConnectionRefusedError):  # nobody listening yet: keep going
                sock.send(frame.data)
            if progress is not None and k % 100 == 0:
                progress(k + 1, len(frames))
    if progress is not None:
        progress(len(frames), len(frames))
    return len(frames)
