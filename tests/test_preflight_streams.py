"""A stream the vehicle refuses to set but sends anyway (PX4 and MISSION_CURRENT on real SITL) is
not reported missing; one that never comes is."""

from __future__ import annotations

import asyncio
import logging

import pytest
from pymavlink.dialects.v20 import ardupilotmega as mavlink

from gcs_planner.mavlink.command import CommandClient
from gcs_planner.mavlink.errors import CommandError, CommandTimeoutError
from gcs_planner.mavlink.link import MavlinkLink
from gcs_planner.mavlink.preflight import request_streams

sitl_mock = pytest.importorskip("sitl_mock")

REFUSED = (mavlink.MAVLINK_MSG_ID_MISSION_CURRENT, mavlink.MAVLINK_MSG_ID_WIND_COV)


def test_only_a_refused_stream_that_never_flows_is_missing(monkeypatch, caplog):
    async def refuse(self, message_id: int, rate_hz: float) -> None:
        if message_id in REFUSED:
            raise CommandError("DENIED", sysid=self.sysid, command=511, result=2)

    monkeypatch.setattr(CommandClient, "set_message_interval", refuse)

    async def run():
        with sitl_mock.MockFleet(count=1, profile="px4", speedup=5) as fleet:  # PX4 streams unasked
            host, port = fleet.vehicle(1).address
            async with await MavlinkLink.open(f"udpout:{host}:{port}") as link:
                rates = {m: 1.0 for m in REFUSED}
                return await request_streams(link, [1], rates)

    with caplog.at_level(logging.WARNING):
        missing = asyncio.run(run())
    assert missing == {1: ["WIND_COV"]}
    assert "no WIND_COV stream" in caplog.text and "MISSION_CURRENT" not in caplog.text


def test_a_vehicle_deaf_to_commands_is_asked_once_not_once_a_stream(monkeypatch):
    """No COMMAND_ACK to the first request (the retries spent): the rest are not asked for, each
    would wait as long; what flows anyway still counts."""
    asked: list[int] = []

    async def deaf(self, message_id: int, rate_hz: float) -> None:
        asked.append(message_id)
        raise CommandTimeoutError("no COMMAND_ACK")

    monkeypatch.setattr(CommandClient, "set_message_interval", deaf)

    async def run():
        with sitl_mock.MockFleet(count=1, profile="px4", speedup=5) as fleet:  # PX4 streams unasked
            host, port = fleet.vehicle(1).address
            async with await MavlinkLink.open(f"udpout:{host}:{port}") as link:
                rates = {mavlink.MAVLINK_MSG_ID_HEARTBEAT: 1.0, mavlink.MAVLINK_MSG_ID_WIND_COV: 1.0}
                return await request_streams(link, [1], rates)

    assert asyncio.run(run()) == {1: ["WIND_COV"]}
    assert asked == [mavlink.MAVLINK_MSG_ID_HEARTBEAT]
