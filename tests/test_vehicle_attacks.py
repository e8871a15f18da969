"""A misbehaving vehicle against the client, over real UDP: it cannot hold a command or a parameter
download for ever, write lines of its choosing into a backup, pass a gimbal's HEARTBEAT off as the
autopilot's, fill the memory with unfinished texts, or leave a file the tool cannot read back.

Each test is a defect a fake vehicle found in review (2026-12-06): before its fix the command and
the download ran until the outer timeout, the names went into the file, the gimbal passed.
"""

from __future__ import annotations

import asyncio
import math
from types import SimpleNamespace

import pytest
from pymavlink.dialects.v20 import ardupilotmega as mavlink
from test_link_attacks import Peer

from gcs_planner.autopilots import quirks_named
from gcs_planner.commands.params import _by_name
from gcs_planner.commands.signing_setup import _heartbeat_with
from gcs_planner.core.errors import UserError
from gcs_planner.flight.ops import _state_of
from gcs_planner.mavlink import params as params_module
from gcs_planner.mavlink.command import CommandClient
from gcs_planner.mavlink.errors import CommandTimeoutError
from gcs_planner.mavlink.link import MavlinkLink
from gcs_planner.mavlink.mission import MissionClient, _describe
from gcs_planner.mavlink.params import Param, download_params
from gcs_planner.mavlink.statustext import MAX_OPEN, TextAssembler
from gcs_planner.missions.files import save_mission_file
from gcs_planner.missions.mission_file import MissionFile, MissionFileError
from gcs_planner.wire.types import MissionItem

OUTER_S = 20.0  # a hang shows as this outer timeout


async def _open(vehicle: Peer) -> tuple[MavlinkLink, tuple[str, int]]:
    link = await MavlinkLink.open(f"udpout:{vehicle.address[0]}:{vehicle.address[1]}", heartbeat_period_s=0)
    return link, ("127.0.0.1", link.local_address[1])


async def _repeat(peer: Peer, to: tuple[str, int], make, period_s: float = 0.02) -> None:
    """Send ``make(i)`` every ``period_s`` until cancelled."""
    i = 0
    while True:
        peer.send(peer.frame(make(i)), to)
        i += 1
        await asyncio.sleep(period_s)


def test_a_command_the_vehicle_keeps_in_progress_ends_at_its_cap():
    async def main():
        vehicle = Peer(1, 1)
        link, gcs = await _open(vehicle)
        in_progress = mavlink.MAVLink_command_ack_message(mavlink.MAV_CMD_MISSION_START, 5, 0, 0, 255, 190)
        task = asyncio.create_task(_repeat(vehicle, gcs, lambda i: in_progress))
        try:
            client = CommandClient(link, 1, retry_s=0.1, in_progress_max_s=0.5)
            with pytest.raises(CommandTimeoutError, match="MISSION_START still IN_PROGRESS after 0.5 s"):
                await client.mission_start()
        finally:
            task.cancel()
            await link.close()
            vehicle.sock.close()

    asyncio.run(asyncio.wait_for(main(), OUTER_S))


def test_a_vehicle_that_dribbles_parameters_ends_the_download_at_its_bound(monkeypatch):
    """One new value every 0.1 s of 1000: no 10 s silence ever ended it (100 s here, hours for a
    list of 65534). It now ends at 20 s + 1 s a parameter, shrunk here to 0.5 s + 1 ms."""
    monkeypatch.setattr(params_module, "DEADLINE_BASE_S", 0.5)
    monkeypatch.setattr(params_module, "DEADLINE_PER_ITEM_S", 0.001)

    async def main():
        vehicle = Peer(1, 1)
        link, gcs = await _open(vehicle)
        value = lambda i: mavlink.MAVLink_param_value_message(f"P{i}".encode(), 1.0, 9, 1000, i)  # noqa: E731
        task = asyncio.create_task(_repeat(vehicle, gcs, value, period_s=0.1))
        try:
            with pytest.raises(UserError, match=r"of 1000 parameters missing after 1\.5 s"):
                await download_params(link, 1, timeout_s=10.0)
        finally:
            task.cancel()
            await link.close()
            vehicle.sock.close()

    asyncio.run(asyncio.wait_for(main(), OUTER_S))


@pytest.mark.parametrize("name", ["#\nTHR_MIN,0 #", "A\tB", "", "#HASH", "TOO_LONG_A_NAME_17", "caf\ufffd"])
def test_a_parameter_name_no_file_line_can_hold_is_refused(name):
    """'#\\nTHR_MIN,0 #' put a line THR_MIN,0 into the backup: a parameter the vehicle never had."""
    with pytest.raises(UserError, match=r"parameter 1 is named .*not 1-16 letters, digits or _; nothing"):
        _by_name([Param("RTL_ALT", 15.0, 9, 0), Param(name, 1.5, 9, 1)], 1)


def test_a_name_the_vehicle_gives_twice_is_refused():
    with pytest.raises(UserError, match="parameters 0 and 2 are both named RTL_ALT"):
        _by_name([Param("RTL_ALT", 15.0, 9, 0), Param("WP_SPD", 5.0, 9, 1), Param("RTL_ALT", 1.0, 9, 2)], 1)
    assert list(_by_name([Param("RTL_ALT", 15.0, 9, 0), Param("WP_SPD", 5.0, 9, 1)], 1)) == [
        "RTL_ALT",
        "WP_SPD",
    ]


def test_signing_is_judged_by_the_autopilots_heartbeat_not_a_gimbals():
    """An autopilot that ignored SETUP_SIGNING and still signs, beside a gimbal (compid 154) that
    never signed: the gimbal's unsigned HEARTBEAT made `--disable` report 'signing off'."""

    async def main():
        autopilot, gimbal = Peer(1, 1, key=b"k" * 32), Peer(1, 154)
        link, gcs = await _open(autopilot)
        beat = lambda i: mavlink.MAVLink_heartbeat_message(2, 3, 0, 0, 4, 3)  # noqa: E731
        tasks = [asyncio.create_task(_repeat(p, gcs, beat, 0.05)) for p in (autopilot, gimbal)]
        try:
            assert not await _heartbeat_with(link, 1, 1, signed=False)  # only the gimbal's are unsigned
            assert await _heartbeat_with(link, 1, 154, signed=False)
        finally:
            for task in tasks:
                task.cancel()
            await link.close()
            autopilot.sock.close()
            gimbal.sock.close()

    asyncio.run(asyncio.wait_for(main(), OUTER_S))


class _Chunk:
    def __init__(self, compid: int, text_id: int, seq: int, text: str) -> None:
        self.id, self.chunk_seq, self.text, self._compid = text_id, seq, text, compid

    def get_srcSystem(self) -> int:  # noqa: N802 (pymavlink's name)
        return 1

    def get_srcComponent(self) -> int:  # noqa: N802
        return self._compid


def test_first_chunks_that_never_finish_cannot_fill_the_memory():
    """262,140 unfinished texts held 105 MB; at most MAX_OPEN now wait, the longest-waiting dropped."""
    texts = TextAssembler()
    assert texts.feed(_Chunk(1, 7, 0, "x" * 50)) is None  # a real text, waiting for its second chunk
    for n in range(20_000):
        texts.feed(_Chunk(n % 256, 1 + n % 65535, 0, "y" * 50))
    assert len(texts._open) == MAX_OPEN
    assert texts.feed(_Chunk(1, 7, 1, "end")) is None  # dropped: waited longest
    texts.feed(_Chunk(1, 9, 0, "a" * 50))
    assert texts.feed(_Chunk(1, 9, 1, "b")) == "a" * 50 + "b"  # a text that keeps coming completes


def _home_item(**fields) -> MissionItem:
    return MissionItem(0, 0, mavlink.MAV_CMD_NAV_WAYPOINT, x=473977420, y=85455940, **{"z": 488.0, **fields})


def _waypoint(seq: int, **fields) -> MissionItem:
    return MissionItem(
        seq, 3, mavlink.MAV_CMD_NAV_WAYPOINT, x=473977420 + seq, y=85455940, **{"z": 20.0, **fields}
    )


@pytest.mark.parametrize("suffix", [".plan", ".waypoints"])
@pytest.mark.parametrize(
    "held",
    [
        [_home_item(z=math.nan), _waypoint(1)],  # a NaN home altitude: a traceback in .plan
        [_home_item(param1=math.inf), _waypoint(1)],  # inf in row 0: a WPL the tool then refused
    ],
)
def test_a_downloaded_list_no_file_can_hold_writes_nothing(tmp_path, held, suffix):
    out = tmp_path / f"vehicle{suffix}"
    with pytest.raises(MissionFileError, match="cannot be stored in a mission file.*nothing written"):
        save_mission_file(out, MissionFile.from_items(held))
    assert not out.exists()


def test_a_fence_return_point_without_an_altitude_writes_nothing(tmp_path):
    back = MissionItem(0, 0, mavlink.MAV_CMD_NAV_FENCE_RETURN_POINT, x=473977420, y=85455940, z=math.nan,
                       mission_type=1)  # fmt: skip
    out = tmp_path / "fence.plan"
    with pytest.raises(MissionFileError, match=r"fence item 0: z = nan"):
        save_mission_file(out, MissionFile.from_items([_home_item(), _waypoint(1)], fence=[back]))
    assert not out.exists()


def test_a_nan_param_written_to_wpl_is_said_and_a_nan_altitude_refused(tmp_path):
    """WPL writes NaN as 0 (Mission Planner cannot read nan): said for a param; for an altitude that
    is a waypoint on the ground, and a .plan's null altitude is refused when read back, so neither
    format takes it."""
    held = MissionFile.from_items([_home_item(), _waypoint(1), _waypoint(2, param1=math.nan)])
    losses = save_mission_file(tmp_path / "m.waypoints", held)
    assert any(loss.fields == ("param1",) and loss.indexes == (1,) for loss in losses)
    for suffix in (".plan", ".waypoints"):
        out = tmp_path / f"nan_z{suffix}"
        with pytest.raises(MissionFileError, match=r"mission item 1: z = nan"):
            save_mission_file(
                out, MissionFile.from_items([_home_item(), _waypoint(1), _waypoint(2, z=math.nan)])
            )
        assert not out.exists()


def test_a_vehicle_that_acks_early_holds_a_truncated_list_and_is_said_so():
    """It ACKed after two of the rows: 'a mixed list of 2 items: seq 1-1 as sent, 0 not from this
    upload' described a list that holds nothing foreign, only too little."""
    sent = [_home_item(), *(_waypoint(k) for k in range(1, 5))]
    held = sent[:2]
    text = _describe(sent, held, quirks_named("ardupilot"), None)
    assert text.startswith("the vehicle now holds only the first 1 of this upload's 4 items")
    assert "mixed" in _describe(sent, [sent[0], _waypoint(1, z=99.0)], quirks_named("ardupilot"), None)


def test_a_vehicle_that_gives_up_its_climb_is_named_with_its_own_words():
    """PX4 SIH (2026-12-06) detected a landing 0.8 m up and disarmed; the error only said the
    vehicle 'did not reach take-off altitude in time'."""
    link = SimpleNamespace(vehicles={3: SimpleNamespace(armed=False), 4: SimpleNamespace(armed=True)})
    status = SimpleNamespace(reason=lambda s: {3: "Disarmed by landing"}.get(s, ""))
    assert _state_of(link, status, 3) == "; sysid 3 disarmed: Disarmed by landing"
    assert _state_of(link, status, 4) == ""


def test_a_download_across_a_tcp_reconnect_is_made_again_from_the_start():
    """A SITL that restarts mid-download with another list: the link reconnected silently and the
    file held item 0 of the old list and items 1-2 of the new one (exit 0)."""
    lists = [[10, 11, 12], [20, 21, 22]]  # the x of each item: the old list, then the new one

    async def main():
        connections = 0

        async def vehicle(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
            nonlocal connections
            mine, connections = connections, connections + 1
            held = lists[min(mine, 1)]
            mav, parser = mavlink.MAVLink(None, 1, 1), mavlink.MAVLink(None)
            parser.robust_parsing = True
            writer.write(mavlink.MAVLink_heartbeat_message(2, 3, 0, 0, 4, 3).pack(mav))
            while data := await reader.read(4096):
                for m in parser.parse_buffer(data) or []:
                    if m.get_type() == "MISSION_REQUEST_LIST":
                        writer.write(mavlink.MAVLink_mission_count_message(255, 190, len(held), 0).pack(mav))
                    elif m.get_type() == "MISSION_REQUEST_INT":
                        item = mavlink.MAVLink_mission_item_int_message(
                            255, 190, m.seq, 3, 16, 0, 1, 0, 0, 0, 0, held[m.seq], 85455940, 20.0, 0
                        )
                        writer.write(item.pack(mav))
                        if mine == 0 and m.seq == 0:  # restarts after its first item
                            await writer.drain()
                            writer.close()
                            return
                await writer.drain()

        server = await asyncio.start_server(vehicle, "127.0.0.1", 0)
        port = server.sockets[0].getsockname()[1]
        link = await MavlinkLink.open(f"tcp:127.0.0.1:{port}", heartbeat_period_s=0)
        try:
            items = await MissionClient(link, 1).download()
        finally:
            await link.close()
            server.close()
        assert [it.x for it in items] == lists[1] and link.reconnects == 1

    asyncio.run(asyncio.wait_for(main(), OUTER_S))
