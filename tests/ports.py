"""Free loopback UDP ports for tests that start fleets on port ranges."""

from __future__ import annotations

import random
import socket


def free_port_run(count: int) -> int:
    """The first of ``count`` consecutive UDP ports on 127.0.0.1 that are free now."""
    for base in random.Random().sample(range(20000, 60000, 32), 50):
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
