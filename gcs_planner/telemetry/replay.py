"""Replay a flight log: re-emit its raw MAVLink frames over UDP, or render it to Rerun.

MAVLink replay sends every recorded frame byte for byte, in receive order, with the recorded
inter-frame timing divided by ``speed`` (``speed <= 0`` or ``inf``: as fast as the rate cap
allows), so another GCS (MAVProxy, QGroundControl) pointed at the address sees the flight again.
Frames are sent from one UDP socket, like a single router carrying all vehicles; a ground
station's own frames are not replayed. The schedule is absolute (frame k at start +
max((t_k - t_0) / speed, k / max_rate)), so sleep overshoot never accumulates, and never faster
than ``max_rate`` frames per second (default MAX_RATE_HZ): unpaced, 23,894 frames went out in
0.1 s and a loopback receiver got 15,401 of them. A silence longer than ``max_gap_s`` of replay
time (default MAX_GAP_S: a link lost and found again, two flights in one log) is cut to it: a log
with one frame three hours late would otherwise hold the replay three hours.
"""

from __future__ import annotations

import contextlib
import math
import os
import socket
import time
from collections.abc import Callable, Iterator

import numpy as np

from gcs_planner.core.errors import UserError
from gcs_planner.core.geo import Origin
from gcs_planner.telemetry.reader import Flight, RawFrame

os.environ.setdefault("MAVLINK20", "1")
from pymavlink.dialects.v20 import ardupilotmega as mavlink  # noqa: E402

__all__ = [
    "MAX_GAP_S", "MAX_RATE_HZ", "long_gaps", "parse_udp_url", "paced", "replay_to_mavlink",
    "replay_to_rerun_live",
]  # fmt: skip

MAX_RATE_HZ = 2000.0  # frames/s; a GCS's socket buffer (~200 KB) then absorbs a 0.1 s stall
MAX_GAP_S = 10.0  # [s of replay] longer silences are cut to this (a GCS shows a link loss well before)


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
    max_rate: float = MAX_RATE_HZ,
    max_gap_s: float = MAX_GAP_S,
) -> int:
    """Send the vehicles' raw frames to ``url`` (udpout:HOST:PORT); returns frames sent.

    progress(sent, total) is called about every 100 frames.
    """
    host, port = parse_udp_url(url)
    frames = flight.vehicle_frames
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        sock.connect((host, port))
        for k, frame in enumerate(paced(flight, speed, sleep, clock, max_rate, max_gap_s)):
            with contextlib.suppress(ConnectionRefusedError):  # nobody listening yet: keep going
                sock.send(frame.data)
            if progress is not None and k % 100 == 0:
                progress(k + 1, len(frames))
    if progress is not None:
        progress(len(frames), len(frames))
    return len(frames)


def paced(
    flight: Flight,
    speed: float,
    sleep: Callable[[float], None] = time.sleep,
    clock: Callable[[], float] = time.monotonic,
    max_rate: float = math.inf,
    max_gap_s: float = MAX_GAP_S,
) -> Iterator[RawFrame]:
    """The vehicles' frames (a ground station's are not replayed), frame k yielded at
    start + max(s_k, k / max_rate), s_k its time in ``_schedule_s``: ``speed`` 1 replays at the pace the
    vehicles flew (a log of a 10x SITL as slowly as it was flown, in flight time); speed 0 or
    inf: no recorded timing."""
    frames = flight.vehicle_frames
    if not frames:
        return
    schedule = _schedule_s(flight, speed, max_gap_s)
    start = clock()
    for k, frame in enumerate(frames):
        due = max(schedule[k], k / max_rate)
        delay = start + due - clock()
        if delay > 0:
            sleep(delay)
        yield frame


def _schedule_s(flight: Flight, speed: float, max_gap_s: float) -> np.ndarray:
    """Replay time of each vehicle frame from the first: (t_k - t_0) x clock_rate / speed, each
    silence longer than ``max_gap_s`` cut to it; zeros when ``speed`` is 0 or inf."""
    t_ns = np.fromiter((f.t_ns for f in flight.vehicle_frames), dtype=np.int64)
    if not (speed > 0 and math.isfinite(speed)):
        return np.zeros(len(t_ns))
    gaps = np.diff(t_ns) * (flight.clock_rate * 1e-9 / speed)
    return np.concatenate([[0.0], np.cumsum(np.minimum(gaps, max_gap_s))])


def long_gaps(flight: Flight, speed: float, max_gap_s: float = MAX_GAP_S) -> list[float]:
    """The silences [s of replay] a replay at ``speed`` cuts to ``max_gap_s``, longest first."""
    t = _schedule_s(flight, speed, math.inf)
    gaps = np.diff(t)
    return sorted(gaps[gaps > max_gap_s].tolist(), reverse=True)


def replay_to_rerun_live(flight: Flight, rec, speed: float = 1.0, max_gap_s: float = MAX_GAP_S) -> int:
    """Re-play a log into a live Rerun recording (e.g. a spawned viewer) with timing scaled by speed.

    Frames go through LiveRerunLogger exactly as they did while flying, on the timeline of the
    log's .rrd (seconds of flight: receive time x ``flight.clock_rate``); the pacing stays the
    recorded receive timing divided by ``speed``, as for MAVLink replay. Returns frames shown.
    """
    from gcs_planner.telemetry.rerun_views import LiveRerunLogger, scenario_from_text

    parser = mavlink.MAVLink(None)
    parser.robust_parsing = True
    origin = flight.origin or Origin(0.0, 0.0, 0.0)
    live = LiveRerunLogger(rec, origin, flight.start_time_s, flight.clock_rate)
    live.start(flight.plan, scenario_from_text(flight.scenario_text))
    shown = 0
    for frame in paced(flight, speed, max_gap_s=max_gap_s):
        try:
            msg = parser.decode(bytearray(frame.data))
        except mavlink.MAVError:
            continue
        live.on_frame(msg, frame.data, frame.t_ns * 1e-9)
        shown += 1
    return shown
