"""End to end: a mock fleet over real UDP, H1's MavlinkLink.subscribe feeding the FlightLogger and
the live Rerun views at once; the log read back has every vehicle's positions."""

from __future__ import annotations

import asyncio
import time

import numpy as np
import pytest

from gcs_planner.core.geo import geodetic_to_enu
from gcs_planner.telemetry import FlightLogger, read_flight

UNGATED = {"arm_ready_s": 0.0, "streams_by_request": False}  # rules these tests are not about

fleet_module = pytest.importorskip("sitl_mock.fleet")  # submodule: works with a stale editable install too
link_module = pytest.importorskip("gcs_planner.mavlink.link")

SYSIDS = [1, 2, 3]


MIN_POSITIONS = 5  # per vehicle, recorded before the link is closed


async def _record(addresses, logger, live, timeout_s: float = 60.0) -> int:
    """Feed the logger and the live views until every vehicle has sent MIN_POSITIONS position
    reports (not for a fixed time: on a loaded machine start-up can take the whole of it)."""
    urls = [f"udpout:{host}:{port}" for host, port in addresses]
    link = await link_module.MavlinkLink.open(*urls, heartbeat_period_s=0.2)
    seen = 0
    positions = dict.fromkeys(SYSIDS, 0)

    def on_frame(msg, raw, t_s) -> None:
        nonlocal seen
        seen += 1
        logger.on_frame(msg, raw, t_s)
        live.on_frame(msg, raw, t_s)
        if msg is not None and msg.get_type() == "GLOBAL_POSITION_INT" and msg.get_srcSystem() in positions:
            positions[msg.get_srcSystem()] += 1

    unsubscribe = link.subscribe(on_frame)
    deadline = time.monotonic() + timeout_s
    while min(positions.values()) < MIN_POSITIONS and time.monotonic() < deadline:
        await asyncio.sleep(0.05)
    unsubscribe()
    await link.close()
    assert min(positions.values()) >= MIN_POSITIONS, f"positions per vehicle after {timeout_s} s: {positions}"
    return seen


def test_mock_fleet_over_udp_is_logged_and_shown_live(tmp_path):
    import rerun as rr

    from gcs_planner.telemetry.rerun_views import APPLICATION_ID, LiveRerunLogger

    path, rrd = tmp_path / "live.mcap", tmp_path / "live.rrd"
    with fleet_module.MockFleet(flight=UNGATED, count=len(SYSIDS), speedup=5.0) as fleet:
        origin = fleet.home
        rec = rr.RecordingStream(APPLICATION_ID, recording_id="live-test")
        rec.save(str(rrd))
        live = LiveRerunLogger(rec, origin, t0_s=time.time())
        live.start()
        with FlightLogger(path, origin, flush_interval_s=0.2) as logger:
            seen = asyncio.run(_record(fleet.addresses, logger, live))
        rec.flush()
        rec.disconnect()
    flight = read_flight(path)
    assert not flight.truncated
    assert seen > 0 and len(flight.frames) == seen  # nothing dropped between link and log
    assert flight.sysids == SYSIDS
    for s in SYSIDS:
        track = flight.positions[s]
        assert len(track) >= MIN_POSITIONS  # recorded until each vehicle had sent that many
        east, north, _ = geodetic_to_enu(track.lat_deg, track.lon_deg, track.alt_m, origin)
        assert np.all(np.hypot(east, north) < 1000.0)  # on the ground near home
    assert "HEARTBEAT" in flight.message_types()
    from rerun.chunk import RrdReader

    entities = {c.entity_path for c in RrdReader(rrd).stream()}
    assert {f"/map/vehicle/{s}" for s in SYSIDS} <= entities
    assert {f"/series/altitude_m/{s}" for s in SYSIDS} <= entities
