"""Free loopback UDP ports for tests that start fleets on port ranges."""

from __future__ import annotations

import random
import socket
import time


def free_port_run(count: int) -> int:
    """The first of ``count`` consecutive UDP ports on 127.0.0.1 that are free now.

    Drawn below Linux's ephemeral range (32768 up), where the kernel hands out ports to sockets
    bound to port 0 (a mock fleet's, or another pytest worker's), so only another draw can race it.
    """
    for base in random.Random().sample(range(20000, 32768 - 32, 32), 50):
        socks = []
        try:
            for port in range(base, base + count):
                socks.append(socket.socket(socket.AF_INET, socket.SOCK_DGRAM))
                socks[-1].bind(("127.0.0.1", port))
            return base
        except OSError:
            continue
        finally:
            for s in socks:
                s.close()
    raise RuntimeError("no free port run")


def free_udp_port() -> int:
    """A UDP port on 127.0.0.1 the kernel has just given out and taken back (free now)."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def frames_from_a_gcs(vehicle: socket.socket, wait_s: float = 0.2) -> list[str]:
    """The MAVLink messages from a ground station (sysid 255) that reach ``vehicle`` within ``wait_s``.

    Other datagrams are ignored: a module's mock fleet keeps streaming to the GCS ports of tests that
    have ended, and the kernel may give the same port number to ``vehicle`` (a flake of CI, 2026-12-05).
    """
    from pymavlink.dialects.v20 import ardupilotmega as mavlink

    parser = mavlink.MAVLink(None)
    parser.robust_parsing = True
    found: list[str] = []
    deadline = time.monotonic() + wait_s
    while (left := deadline - time.monotonic()) > 0:
        vehicle.settimeout(left)
        try:
            data = vehicle.recv(65535)
        except TimeoutError:
            break
        messages = parser.parse_buffer(data) or []
        found += [m.get_type() for m in messages if m.get_srcSystem() == 255]
    return found
