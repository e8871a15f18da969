"""A minimal synchronous GCS on pymavlink's ``mavutil`` for tests, benchmarks and manual poking.

Deliberately plain (no retries beyond answering requests): the real client is
gcs_planner.mavlink.mission; this one lets the mock be tested without depending on it.
"""

from __future__ import annotations

import os
import time

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavutil  # noqa: E402

from gcs_planner.wire.types import MissionItem  # noqa: E402

__all__ = ["Probe"]

GCS_SYSID, GCS_COMPID = 255, 190


class Probe:
    """A GCS connection to one vehicle address (``udpout``); sends a heartbeat on connect."""

    def __init__(self, address: tuple[str, int]) -> None:
        host, port = address
        self.conn = mavutil.mavlink_connection(
            f"udpout:{host}:{port}", source_system=GCS_SYSID, source_component=GCS_COMPID
        )
        self.mav = self.conn.mav
        self.heartbeat()

    def close(self) -> None:
        self.conn.close()

    def heartbeat(self) -> None:
        self.mav.heartbeat_send(mavutil.mavlink.MAV_TYPE_GCS, mavutil.mavlink.MAV_AUTOPILOT_INVALID, 0, 0, 0)

    def recv(self, types: str | list[str] | None = None, timeout_s: float = 2.0, condition=None):
        """Next message of ``types`` (optionally satisfying ``condition(msg)``), None on timeout."""
        deadline = time.monotonic() + timeout_s
        while (left := deadline - time.monotonic()) > 0:
            msg = self.conn.recv_match(type=types, blocking=True, timeout=min(left, 0.2))
            if msg is not None and (condition is None or condition(msg)):
                return msg
        return None

    def collect(self, duration_s: float) -> list:
        """Every message received during ``duration_s`` seconds."""
        out = []
        deadline = time.monotonic() + duration_s
        while (left := deadline - time.monotonic()) > 0:
            msg = self.conn.recv_match(blocking=True, timeout=min(left, 0.1))
            if msg is not None:
                out.append(msg)
        return out

    def command(self, sysid: int, command: int, *params: float, timeout_s: float = 2.0) -> int | None:
        """COMMAND_LONG to (sysid, 1); returns the COMMAND_ACK result (None: no ACK)."""
        p = [*params, *([0.0] * (7 - len(params)))]
        self.mav.command_long_send(sysid, 1, command, 0, *p)
        ack = self.recv("COMMAND_ACK", timeout_s, lambda m: m.command == command)
        return None if ack is None else ack.result

    def upload(self, sysid: int, items: list[MissionItem], timeout_s: float = 5.0) -> int | None:
        """Upload a mission (answers each request with MISSION_ITEM_INT); MISSION_ACK type or None."""
        mission_type = items[0].mission_type if items else 0
        self.mav.mission_count_send(sysid, 1, len(items), mission_type)
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            msg = self.recv(
                ["MISSION_REQUEST", "MISSION_REQUEST_INT", "MISSION_ACK"], deadline - time.monotonic()
            )
            if msg is None:
                break
            if msg.get_type() == "MISSION_ACK":
                return msg.type
            it = items[msg.seq]
            self.mav.mission_item_int_send(
                sysid, 1, msg.seq, it.frame, it.command, it.current, it.autocontinue,
                it.param1, it.param2, it.param3, it.param4, it.x, it.y, it.z, mission_type,
            )  # fmt: skip
        return None

    def download_count(self, sysid: int, mission_type: int = 0) -> int | None:
        """MISSION_REQUEST_LIST -> the vehicle's MISSION_COUNT (the transfer is then cancelled)."""
        self.mav.mission_request_list_send(sysid, 1, mission_type)
        msg = self.recv("MISSION_COUNT", 2.0)
        if msg is None:
            return None
        self.mav.mission_ack_send(sysid, 1, mavutil.mavlink.MAV_MISSION_OPERATION_CANCELLED, mission_type)
        return msg.count
