"""Mission client over real UDP sockets (127.0.0.1, ephemeral ports) against the mock autopilot fleet.

Both profiles, link faults (loss, duplication, reordering), scripted failures, fleet upload with
retries, commands, and bad input (malformed items, values the vehicle rejects, duplicate sysids).
The deep retry/timeout matrix runs on fake time in test_mission_transfer.py; here every case must
hold on the wire.
"""

from __future__ import annotations

import asyncio
import math
from dataclasses import replace

import pytest
from refusals import refused

from gcs_planner.mavlink import errors
from gcs_planner.mavlink.command import CommandClient
from gcs_planner.mavlink.fleet import start_fleet, upload_fleet
from gcs_planner.mavlink.link import MavlinkLink
from gcs_planner.mavlink.mission import MissionClient
from gcs_planner.mavlink.transfer import Timing
from gcs_planner.wire.enums import MissionResult
from gcs_planner.wire.types import MissionItem, MissionType
from sitl_mock.faults import LinkFaults
from sitl_mock.fleet import MockFleet
from sitl_mock.mission_server import Failure

FAST = Timing(count_retry_s=0.3, inactivity_timeout_s=3.0)


UNGATED = {"arm_ready_s": 0.0}  # readiness is not what these tests are about


def mission(
    n: int, mission_type: int = MissionType.MISSION, base_lat: int = 473_977_000
) -> list[MissionItem]:
    """Values that survive ArduPilot's rounding; seq 0 stands for the home slot on ArduPilot."""
    return [
        MissionItem(
            seq=i,
            frame=3 if mission_type == MissionType.MISSION else 0,
            command=_cmd(mission_type),
            current=int(i == 0 and mission_type == MissionType.MISSION),
            x=base_lat + 53 * i,
            y=85_455_000 + 17 * i,
            z=round(15.0 + 0.5 * i, 2),
            mission_type=mission_type,
        )
        for i in range(n)
    ]


def _cmd(mission_type: int) -> int:
    return {MissionType.MISSION: 16, MissionType.FENCE: 5003, MissionType.RALLY: 5100}[mission_type]


def run(coro):
    return asyncio.run(asyncio.wait_for(coro, 60))


async def connected(fleet: MockFleet) -> MavlinkLink:
    link = await MavlinkLink.open(*(f"udpout:{h}:{p}" for h, p in fleet.addresses))
    wanted = {v.sysid for v in fleet.vehicles}
    seen: set[int] = set()
    await link.wait_for(
        lambda m: m.get_type() == "HEARTBEAT" and (seen.add(m.get_srcSystem()) or seen >= wanted), 5
    )
    return link


def same_positions(a: list[MissionItem], b: list[MissionItem], skip_home: bool) -> bool:
    start = 1 if skip_home else 0
    return [(i.x, i.y, i.z) for i in a[start:]] == [(i.x, i.y, i.z) for i in b[start:]]


@pytest.mark.parametrize("profile", ["ardupilot", "px4"])
def test_round_trip_all_three_lists(profile):
    async def main():
        async with MockFleet(count=1, profile=profile, flight=UNGATED) as fleet:
            link = await connected(fleet)
            client = MissionClient(link, 1)
            server = fleet.vehicle(1).mission_server
            for mission_type, n in (
                (MissionType.MISSION, 12),
                (MissionType.FENCE, 4),
                (MissionType.RALLY, 2),
            ):
                items = mission(n, mission_type)
                result = await client.upload(items, mission_type=mission_type, verify=True)
                assert result.verified and result.count == n
                assert result.opaque_id == server.opaque_id(mission_type) != 0
                back, opaque = await client.download_with_id(mission_type)
                assert opaque == result.opaque_id
                skip = profile == "ardupilot" and mission_type == MissionType.MISSION
                assert same_positions(back, items, skip_home=skip)
            sent = result.stats.sent
            assert sent["MISSION_COUNT"] == 1 and sent["MISSION_ITEM_INT"] == 2
            await link.close()

    run(main())


@pytest.mark.parametrize(("profile", "n"), [("ardupilot", 6), ("px4", 12)])
def test_lossy_link_equal_mission_or_failure_with_previous_intact(profile, n):
    async def main():
        async with MockFleet(count=1, profile=profile, flight=UNGATED) as fleet:
            link = await connected(fleet)
            client = MissionClient(link, 1)
            old = mission(3)
            await client.upload(old)
            server = fleet.vehicle(1).mission_server
            before = server.items()
            fleet.set_faults(1, LinkFaults(loss=0.2, duplicate=0.1, reorder=0.2, seed=7))
            new = mission(n, base_lat=400_000_000)
            outcomes = []
            for _ in range(2):
                try:
                    await client.upload(new)
                    outcomes.append(True)
                    assert same_positions(server.items(), new, skip_home=False)
                except errors.MissionError:
                    outcomes.append(False)
                    # reported failure: previous mission intact, or (lost final ACK) the new one complete
                    assert server.items() == before or same_positions(server.items(), new, False)
            fleet.set_faults(1, LinkFaults())
            if outcomes[-1]:
                back = await client.download()
                assert same_positions(back, new, skip_home=profile == "ardupilot")
            assert any(outcomes)
            await link.close()

    run(main())


def test_scripted_failures_over_udp():
    async def main():
        async with MockFleet(count=1, profile="ardupilot", flight=UNGATED) as fleet:
            link = await connected(fleet)
            client = MissionClient(link, 1, timing=FAST)
            server = fleet.vehicle(1).mission_server
            items = mission(5)

            fleet.set_mission_failure(1, Failure.WRITE_COUNT_FIRST_RESPONSE)
            first = await client.upload(items)
            assert first.stats.sent["MISSION_COUNT"] == 2

            fleet.set_mission_failure(1, Failure.WRITE_REQUEST1_INCORRECT_SEQUENCE)
            spec = MissionClient(link, 1, timing=replace(FAST, window=1))  # pipelining hides the failure
            assert (await spec.upload(mission(5, base_lat=470_000_000))).stats.invalid_sequence_acks >= 1

            fleet.set_mission_failure(1, Failure.WRITE_FINAL_ACK_NO_RESPONSE)  # ArduPilot: ACK lost for good
            lost = await client.upload(items)
            assert lost.ack_lost and lost.verified and lost.opaque_id == server.opaque_id()

            # a final ERROR after the last item reads like ArduPilot's answer to a resent last item:
            # the read-back decides, and ArduPilot stored the items as they arrived
            fleet.set_mission_failure(1, Failure.WRITE_FINAL_ACK_ERROR_ACK)
            final_error = await client.upload(mission(7, base_lat=460_000_000))
            assert final_error.ack_lost and final_error.verified
            before = server.items()

            fleet.set_mission_failure(1, Failure.READ_REQUEST1_ERROR_ACK)
            with pytest.raises(errors.MissionError, match="download: ERROR"):
                await client.download()

            fleet.set_mission_failure(1, Failure.WRITE_COUNT_NO_RESPONSE)
            with pytest.raises(errors.MissionTimeoutError):
                await client.upload(mission(2))
            assert server.items() == before
            await link.close()

    run(main())


def test_missing_request_is_pushed_ahead_long_before_the_vehicle_would_cancel():
    """The vehicle never asks for item 1 (it would cancel at 8 s): the client's push-ahead timer must
    fire mid-transfer, although the waiting loop was armed at the 1.5 s MISSION_COUNT deadline (one
    item in flight: with two, item 1 is on its way before the vehicle fails to ask for it)."""

    async def main():
        async with MockFleet(count=1, profile="ardupilot", flight=UNGATED) as fleet:
            link = await connected(fleet)
            fleet.set_mission_failure(1, Failure.WRITE_REQUEST1_NO_RESPONSE)
            items = mission(6)
            result = await MissionClient(link, 1, timing=Timing(window=1)).upload(items)
            # before the 1.5 s MISSION_COUNT deadline the waiting loop was armed at (push timeouts
            # are 0.5 s at most): a busy machine's scheduling delays fit in the difference
            assert result.elapsed_s < 1.5 and result.stats.sent["MISSION_ITEM_INT"] == 7
            server = fleet.vehicle(1).mission_server
            assert server.items()[1:] == [server.storage(i) for i in items[1:]]
            await link.close()

    run(main())


def test_partial_write_verified_by_download_over_udp():
    async def main():
        async with MockFleet(count=1, profile="ardupilot", flight=UNGATED) as fleet:
            link = await connected(fleet)
            client = MissionClient(link, 1)
            old = mission(8)
            await client.upload(old)
            ahead = mission(8, base_lat=470_000_000)[5:]  # re-plan the legs ahead only
            result = await client.upload(ahead, partial=True, verify=True)
            assert result.verified and result.count == 3
            held = fleet.vehicle(1).mission_server.items()
            kept = fleet.vehicle(1).mission_server.storage
            assert held[5:] == [kept(i) for i in ahead] and held[1:5] == [kept(i) for i in old[1:5]]
            await link.close()

    run(main())


def test_subscriptions_by_sysid_see_only_their_vehicle():
    async def main():
        async with MockFleet(count=2, profile="px4") as fleet:
            link = await connected(fleet)
            seen: dict[str, set[int]] = {"one": set(), "all": set()}
            stop_one = link.subscribe(lambda m, raw, t: seen["one"].add(m.get_srcSystem()), sysid=1)
            link.subscribe(lambda m, raw, t: seen["all"].add(m.get_srcSystem()))
            await asyncio.sleep(0.5)
            assert seen == {"one": {1}, "all": {1, 2}}
            stop_one()
            seen["one"].clear()
            await asyncio.sleep(0.3)
            assert not seen["one"] and not link._by_sysid
            await link.close()

    run(main())


def test_vehicle_reboot_forgets_mission_and_client_sees_it():
    async def main():
        async with MockFleet(count=1, profile="px4") as fleet:
            link = await connected(fleet)
            client = MissionClient(link, 1)
            await client.upload(mission(4))
            fleet.reboot(1)
            await asyncio.sleep(0.05)
            assert await client.download() == []
            await link.close()

    run(main())


def test_bad_input_is_refused_and_vehicle_unchanged():
    """PX4 keeps its list when an item is refused (ArduPilot truncates at MISSION_COUNT)."""

    async def main():
        async with MockFleet(count=1, profile="px4", flight=UNGATED) as fleet:
            link = await connected(fleet)
            client = MissionClient(link, 1, timing=FAST)
            server = fleet.vehicle(1).mission_server
            await client.upload(mission(3))
            before = server.items()
            sent_before = link.frames_sent
            with pytest.raises(errors.MissionInputError, match="65535"):
                await client.upload([MissionItem(seq=i, frame=3, command=16) for i in range(70_000)])
            with pytest.raises(errors.MissionInputError, match="item 1: seq"):
                await client.upload([mission(3)[0], mission(3)[2]])
            assert link.frames_sent - sent_before <= 1  # at most a heartbeat went out
            bad = [
                (dict(x=910_000_000, y=1, z=10.0), MissionResult.INVALID_PARAM5_X),
                (dict(command=31_999, x=1, y=1, z=10.0), MissionResult.UNSUPPORTED),
                (dict(x=1, y=1, z=math.nan), MissionResult.INVALID_PARAM7),
            ]
            for fields, result in bad:
                item = MissionItem(**{"seq": 0, "frame": 3, "command": 16, **fields})
                with pytest.raises(errors.MissionError, match="vehicle 1 refused the mission up") as caught:
                    await client.upload([item])
                assert refused(caught.value, result)
                assert server.items() == before
            await link.close()

    run(main())


def test_duplicate_sysid_is_reported_not_merged():
    async def main():
        async with MockFleet(vehicles=[{"sysid": 1}, {"sysid": 1}, {"sysid": 2}], profile="px4") as fleet:
            link = await connected(fleet)
            for _ in range(50):
                if link.duplicates():
                    break
                await asyncio.sleep(0.05)
            assert list(link.duplicates()) == [1] and len(link.duplicates()[1]) == 2
            with pytest.raises(errors.DuplicateSysidError, match="system id 1 is used by 2 vehicles"):
                await MissionClient(link, 1).upload(mission(3))
            results = await upload_fleet(link, {1: mission(3), 2: mission(3)})
            assert isinstance(results[1].error, errors.DuplicateSysidError) and results[1].attempts == 1
            assert results[2].ok
            assert all(v.mission_server.count() == 0 for v in fleet.vehicles if v.sysid == 1)
            await link.close()

    run(main())


def test_fleet_upload_pool_retries_and_reports_per_vehicle():
    async def main():
        vehicles = [{"sysid": s} for s in range(1, 7)] + [{"sysid": 7, "capacity": 2}]
        async with MockFleet(vehicles=vehicles, profile="px4") as fleet:
            fleet.set_mission_failure(3, Failure.WRITE_FINAL_ACK_ERROR_ACK)  # fails every time: retried
            fleet.set_mission_failure(4, Failure.WRITE_COUNT_FIRST_RESPONSE)  # recovers inside one attempt
            link = await connected(fleet)
            calls = []
            missions = {s: mission(5, base_lat=470_000_000 + s) for s in range(1, 8)}
            results = await upload_fleet(
                link,
                missions,
                workers=3,
                retries=2,
                timing=FAST,
                progress=lambda done, total, r: calls.append((done, total, r.sysid)),
            )
            assert [c[0] for c in calls] == list(range(1, 8)) and {c[2] for c in calls} == set(range(1, 8))
            for s in (1, 2, 4, 5, 6):
                assert results[s].ok and results[s].attempts == 1
                assert results[s].opaque_id == fleet.vehicle(s).mission_server.opaque_id()
            assert not results[3].ok and results[3].attempts == 3
            assert refused(results[7].error, MissionResult.NO_SPACE) and results[7].attempts == 1
            started = await start_fleet(link, [1, 2])
            assert all(r.ok for r in started.values())
            await link.close()

    run(main())


def test_a_fleet_upload_raises_an_error_that_is_not_a_vehicles(monkeypatch):
    """A bug in the upload path (here a RuntimeError) ends the fleet upload with that error, once
    every worker has hit it; it is not reported as a KeyError of a missing result, nor waited out."""

    async def broken(self, items, **kwargs):
        raise RuntimeError("a bug")

    async def main():
        async with MockFleet(count=3, profile="px4") as fleet:
            link = await connected(fleet)
            monkeypatch.setattr(MissionClient, "upload", broken)
            with pytest.raises(RuntimeError, match="a bug"):
                await asyncio.wait_for(upload_fleet(link, {s: mission(3) for s in (1, 2, 3)}, workers=2), 10)
            await link.close()

    run(main())


@pytest.mark.parametrize("profile", ["ardupilot", "px4"])
def test_commands_and_set_current(profile):
    async def main():
        async with MockFleet(count=1, profile=profile, speedup=5, flight=UNGATED) as fleet:
            link = await connected(fleet)
            vehicle = fleet.vehicle(1)
            client, command = MissionClient(link, 1), CommandClient(link, 1)
            await client.upload(mission(6))
            await command.set_mode("GUIDED")
            assert vehicle.state.mode == "GUIDED"
            await command.arm()
            await command.mission_start()
            assert vehicle.state.armed and vehicle.state.mode == "AUTO"
            await client.set_current(4)
            assert vehicle.mission_server.current_seq == 4
            with pytest.raises(errors.CommandError, match="DO_SET_MISSION_CURRENT with FAILED"):
                await command.set_mission_current(40)
            with pytest.raises(errors.UserError, match="mode 'FLY' does not exist"):
                await command.set_mode("FLY")
            await command.rtl()
            assert vehicle.state.mode == "RTL"
            await link.close()

    run(main())


def test_clear_in_auto_falls_back_to_empty_upload_on_ardupilot():
    """ArduPilot refuses MISSION_CLEAR_ALL in AUTO: reported, list kept; force= uploads an empty list."""

    async def main():
        async with MockFleet(count=1, profile="ardupilot", flight=UNGATED) as fleet:
            link = await connected(fleet)
            client, command = MissionClient(link, 1), CommandClient(link, 1)
            await client.upload(mission(4))
            await command.set_mode("GUIDED")
            await command.arm()
            await command.mission_start()
            assert fleet.vehicle(1).mission_server.mission_running
            with pytest.raises(errors.MissionError, match="the list is unchanged .* --force"):
                await client.clear()
            assert fleet.vehicle(1).mission_server.count() == 4
            notes = await client.clear(force=True)
            assert notes == [
                "mission: MISSION_CLEAR_ALL refused (ERROR); cleared by uploading an empty list (--force)"
            ]
            assert fleet.vehicle(1).mission_server.count() == 0
            assert len(await client.download()) == 1  # ArduPilot always reports home at seq 0
            await link.close()

    run(main())


def test_udpin_link_serves_a_vehicle_that_connects_to_the_gcs():
    """SITL-style: the vehicle sends first to our listening port; replies are routed back to it by sysid."""
    from pymavlink.dialects.v20 import ardupilotmega as mavlink

    from sitl_mock.mission_server import MissionServer
    from sitl_mock.profiles import PROFILES

    async def main():
        link = await MavlinkLink.open("udpin:127.0.0.1:0")
        loop = asyncio.get_running_loop()
        server = MissionServer(7, 1, PROFILES["px4"])
        mav, parser = mavlink.MAVLink(None, srcSystem=7, srcComponent=1), mavlink.MAVLink(None)

        class Vehicle(asyncio.DatagramProtocol):
            def connection_made(self, transport):
                self.transport = transport

            def datagram_received(self, data, addr):
                for msg in parser.parse_buffer(data) or []:
                    for out in server.handle(msg, loop.time()):
                        self.transport.sendto(out.pack(mav))

        transport, _ = await loop.create_datagram_endpoint(Vehicle, remote_addr=link.local_address)
        transport.sendto(mavlink.MAVLink_heartbeat_message(2, 12, 0, 0, 4, 3).pack(mav))
        await link.wait_for(lambda m: m.get_srcSystem() == 7, 2)
        assert link.vehicles[7].autopilot == 12 and not link.vehicles[7].duplicate
        items = mission(9)
        result = await MissionClient(link, 7).upload(items)
        assert server.items() == [server.storage(i) for i in items] and result.opaque_id == server.opaque_id()
        transport.close()
        await link.close()

    run(main())


def test_vehicle_that_skips_items_then_accepts_is_a_protocol_error_over_udp():
    """Over a real socket: requests 0-2, then only the last item, then ACCEPTED is no success."""
    from pymavlink.dialects.v20 import ardupilotmega as mavlink

    async def main():
        link = await MavlinkLink.open("udpin:127.0.0.1:0")
        loop = asyncio.get_running_loop()
        mav, parser = mavlink.MAVLink(None, srcSystem=7, srcComponent=1), mavlink.MAVLink(None)
        seen: set[int] = set()

        class Skipper(asyncio.DatagramProtocol):
            def connection_made(self, transport):
                self.transport = transport

            def send(self, msg):
                self.transport.sendto(msg.pack(mav))

            def datagram_received(self, data, addr):
                for msg in parser.parse_buffer(data) or []:
                    kind = msg.get_type()
                    if kind == "MISSION_COUNT" and not seen:
                        self.send(mavlink.MAVLink_mission_request_int_message(255, 190, 0, 0))
                    elif kind == "MISSION_ITEM_INT" and msg.seq not in seen:
                        seen.add(msg.seq)
                        if msg.seq < 2:
                            self.send(mavlink.MAVLink_mission_request_int_message(255, 190, msg.seq + 1, 0))
                        elif msg.seq == 2:
                            self.send(mavlink.MAVLink_mission_request_int_message(255, 190, 28, 0))
                        elif msg.seq == 28:
                            self.send(mavlink.MAVLink_mission_ack_message(255, 190, 0, 0))

        transport, _ = await loop.create_datagram_endpoint(Skipper, remote_addr=link.local_address)
        transport.sendto(mavlink.MAVLink_heartbeat_message(2, 12, 0, 0, 4, 3).pack(mav))
        await link.wait_for(lambda m: m.get_srcSystem() == 7, 2)
        with pytest.raises(errors.MissionProtocolError, match=r"without items \d+-27 .*mix"):
            await MissionClient(link, 7, timing=FAST).upload(mission(29))
        transport.close()
        await link.close()

    run(main())
