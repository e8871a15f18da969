"""Interop with MAVSDK (C++ library, python `mavsdk` 4.x ctypes API) over real UDP on 127.0.0.1.

- MAVSDK's own importers read our .plan and WPL files into exactly our items.
- MAVSDK's MissionRaw client uploads to and downloads from our mock vehicle (both profiles).
- Our MissionClient uploads to MAVSDK's MissionRawServer (the autopilot side of MAVSDK), which
  receives exactly our items.
"""

from __future__ import annotations

import asyncio
import threading
from dataclasses import replace

import pytest
from ports import free_udp_port

mavsdk = pytest.importorskip("mavsdk")
from mavsdk import ComponentType, Configuration, Mavsdk, log_subscribe  # noqa: E402
from mavsdk.plugins.mission_raw import MissionItem as RawItem  # noqa: E402
from mavsdk.plugins.mission_raw import MissionRaw  # noqa: E402
from mavsdk.plugins.mission_raw_server import MissionRawServer  # noqa: E402

from gcs_planner.core.geo import Origin  # noqa: E402
from gcs_planner.missions.files import in_file_frames, plan_mission_file  # noqa: E402
from gcs_planner.missions.items import plan_to_items  # noqa: E402
from gcs_planner.missions.planfile import dumps_plan  # noqa: E402
from gcs_planner.missions.wpl import dumps_wpl  # noqa: E402
from gcs_planner.model.plan import VehiclePlan  # noqa: E402
from gcs_planner.wire.types import MissionItem  # noqa: E402

ORIGIN = Origin(47.397742, 8.545594, 488.0)

log_subscribe(lambda *args: True)  # keep MAVSDK's console logging out of test output


def vehicle_plan(n: int = 8, **kw) -> VehiclePlan:
    import numpy as np

    wps = np.c_[
        np.linspace(0, 70 * (n - 1), n), np.linspace(0, 30 * (n - 1), n), np.r_[0.0, np.full(n - 1, 25.0)]
    ]
    speeds = np.r_[0.0, np.where(np.arange(1, n) % 3, 8.0, 11.0)]
    seg = np.linalg.norm(np.diff(wps, axis=0), axis=1)
    times = np.r_[0.0, np.cumsum(seg / speeds[1:])]
    return VehiclePlan("v", 1, wps, times, speeds, wps, times, **kw)


def to_ours(raw) -> MissionItem:
    return MissionItem(
        raw.seq,
        raw.frame,
        raw.command,
        raw.current,
        raw.autocontinue,
        raw.param1,
        raw.param2,
        raw.param3,
        raw.param4,
        raw.x,
        raw.y,
        raw.z,
        raw.mission_type,
    )


def to_raw(it: MissionItem) -> RawItem:
    return RawItem(*it.fields())


class MavsdkServer:
    """MAVSDK acting as an autopilot (sysid 1, compid 1) with MissionRawServer on udpin 127.0.0.1:port."""

    def __init__(self):
        self.port = free_udp_port()
        self.mavsdk = Mavsdk(Configuration.create_with_component_type(ComponentType.AUTOPILOT))
        self.mavsdk.add_any_connection(f"udpin://127.0.0.1:{self.port}")
        self.server = MissionRawServer(self.mavsdk.server_component())
        self.received: list[list[MissionItem]] = []
        self.event = threading.Event()

        def incoming(result, plan, _user_data):
            self.received.append([to_ours(it) for it in plan.mission_items])
            self.event.set()

        self.server.subscribe_incoming_mission(incoming)

    def close(self):
        self.mavsdk.destroy()


def mavsdk_client(url: str) -> tuple[Mavsdk, MissionRaw]:
    """MAVSDK as a ground station (sysid 255, compid 190) connected to ``url``; its MissionRaw plugin."""
    client = Mavsdk(Configuration.create_manual(255, 190, True))
    client.add_any_connection(url)
    system = client.first_autopilot(10.0)
    if system is None:
        client.destroy()
        pytest.fail(f"MAVSDK found no autopilot on {url} within 10 s")
    return client, MissionRaw(system)


@pytest.fixture(scope="module")
def mavsdk_pair():
    server = MavsdkServer()
    client, raw = mavsdk_client(f"udpout://127.0.0.1:{server.port}")
    yield server, raw
    client.destroy()
    server.close()


@pytest.mark.parametrize("autopilot", ["ardupilot", "px4"])
def test_mavsdk_imports_our_plan_and_wpl_files(mavsdk_pair, autopilot):
    _, raw = mavsdk_pair
    vp = vehicle_plan(takeoff_delay_s=5.0, final_action="rtl")
    as_in_files = in_file_frames(plan_to_items(vp, ORIGIN, autopilot))  # MAVSDK keeps the files' frames
    wpl = [
        to_ours(it)
        for it in raw.import_mission_planner_mission_from_string(dumps_wpl(as_in_files)).mission_items
    ]
    assert wpl == as_in_files
    imported = raw.import_qgroundcontrol_mission_from_string(
        dumps_plan(plan_mission_file(vp, ORIGIN, autopilot))
    )
    plan_items = [to_ours(it) for it in imported.mission_items]
    body = as_in_files[1:] if autopilot == "ardupilot" else as_in_files  # .plan files carry no home item
    assert plan_items == [replace(it, seq=i, current=int(i == 0)) for i, it in enumerate(body)]


@pytest.fixture(scope="module")
def mock_fleet():
    sitl_mock = pytest.importorskip("sitl_mock")
    with sitl_mock.MockFleet(vehicles=[{"profile": "ardupilot"}, {"profile": "px4"}], home=ORIGIN) as fleet:
        yield fleet


def stored(fleet, sysid: int, mission_type: int = 0) -> list[MissionItem]:
    return fleet.call(lambda: fleet.vehicle(sysid).mission_server.items(mission_type))


@pytest.mark.parametrize(("sysid", "autopilot"), [(1, "ardupilot"), (2, "px4")])
def test_mavsdk_mission_raw_client_uploads_to_and_downloads_from_mock(mock_fleet, sysid, autopilot):
    host, port = mock_fleet.vehicle(sysid).address
    client, raw = mavsdk_client(f"udpout://{host}:{port}")
    try:
        items = plan_to_items(vehicle_plan(n=12, takeoff_delay_s=2.0), ORIGIN, autopilot)
        raw.upload_mission([to_raw(it) for it in items])
        held = stored(mock_fleet, sysid)
        kept = mock_fleet.vehicle(sysid).mission_server.storage  # what the autopilot keeps (readback.py)
        assert held == [kept(it) for it in items]
        downloaded = [to_ours(it) for it in raw.download_mission()]
        # `current` in a download marks the vehicle's current item, not the uploaded flag
        assert [replace(it, current=0) for it in downloaded] == [replace(it, current=0) for it in held]
        if autopilot == "px4":
            rally = [
                MissionItem(i, 6, 5100, 0, 1, x=473977420 + 1000 * i, y=85455940, z=30.0, mission_type=2)
                for i in range(3)
            ]
            raw.upload_rally_points([to_raw(it) for it in rally])
            assert stored(mock_fleet, sysid, 2) == [kept(it) for it in rally]
            assert [to_ours(it) for it in raw.download_rallypoints()] == [kept(it) for it in rally]
    finally:
        client.destroy()


@pytest.mark.parametrize("mission_type", [0, 2])
def test_our_client_uploads_to_mavsdk_mission_raw_server(mavsdk_pair, mission_type):
    """MAVSDK's autopilot side receives exactly our items (mission, rally points) and returns them."""
    from gcs_planner.autopilots import quirks_for
    from gcs_planner.mavlink.link import MavlinkLink
    from gcs_planner.mavlink.mission import MissionClient
    from gcs_planner.missions.items import rally_items

    server, _ = mavsdk_pair
    if mission_type == 0:
        items = plan_to_items(vehicle_plan(n=15, takeoff_delay_s=4.0, final_action="rtl"), ORIGIN, "px4")
    else:
        items = rally_items([(0.0, 0.0, 30.0), (120.0, -40.0, 35.0), (-60.0, 80.0, 40.0)], ORIGIN)
    server.received.clear()
    server.event.clear()

    async def upload():
        link = await MavlinkLink.open(f"udpout:127.0.0.1:{server.port}")
        try:
            await link.wait_for(
                lambda m: m.get_type() == "HEARTBEAT" and m.get_srcSystem() == 1, timeout_s=5.0
            )
            # MAVSDK's server stores any item it gets, so the client must not send any unasked
            assert not quirks_for(link.vehicles[1].autopilot).pipelined
            client = MissionClient(link, 1)
            return await client.upload(items, mission_type=mission_type), await client.download(mission_type)
        finally:
            await link.close()

    result, downloaded = asyncio.run(upload())
    assert result.count == len(items)
    assert downloaded == items  # MAVSDK's server also answers our download with the same items
    assert server.event.wait(5.0), "MissionRawServer reported no incoming mission"
    assert server.received[-1] == items
