"""Client core (transfer.py) against server core (mission_server.py) on fake time, real MAVLink bytes.

A tiny discrete-event channel carries packed frames between the two cores with seeded loss,
duplication, reordering and delay, so every retry count and timeout is exact and the runs are fast.
"""

from __future__ import annotations

import heapq
import itertools
from dataclasses import dataclass, field, replace

import numpy as np
import pytest
from pymavlink.dialects.v20 import ardupilotmega as mavlink
from refusals import refused

from gcs_planner.mavlink import errors
from gcs_planner.mavlink.transfer import (
    COUNT_RETRIES,
    COUNT_RETRY_S,
    ClearTransfer,
    DownloadTransfer,
    SetCurrentTransfer,
    Timing,
    Transfer,
    UploadTransfer,
)
from gcs_planner.wire.enums import MissionResult
from gcs_planner.wire.types import MissionItem, MissionType
from gcs_planner.wire.wire import attach_extensions
from sitl_mock.mission_server import Failure, MissionServer
from sitl_mock.profiles import PROFILES

GCS = (255, 190)


@dataclass
class Channel:
    """Both directions of one link: one-way delay, loss, duplication, reordering (extra delay)."""

    loss: float = 0.0
    duplicate: float = 0.0
    reorder: float = 0.0
    delay_s: float = 0.002
    seed: int = 0
    rng: np.random.Generator = field(init=False)

    def __post_init__(self) -> None:
        self.rng = np.random.default_rng(self.seed)

    def arrivals(self, now_s: float) -> list[float]:
        if self.rng.random() < self.loss:
            return []
        copies = 2 if self.rng.random() < self.duplicate else 1
        out = []
        for _ in range(copies):
            extra = self.rng.uniform(0.0, 0.05) if self.rng.random() < self.reorder else 0.0
            out.append(now_s + self.delay_s + extra)
        return out


class Sim:
    """Runs one client transfer against a server (and optionally a second GCS) until both are quiet."""

    def __init__(self, server: MissionServer, channel: Channel | None = None) -> None:
        self.server = server
        self.channel = channel or Channel()
        self.now = 0.0
        self._queue: list[tuple[float, int, str, bytes]] = []
        self._tie = itertools.count()
        self._mav = {
            "gcs": mavlink.MAVLink(None, srcSystem=GCS[0], srcComponent=GCS[1]),
            "veh": mavlink.MAVLink(None, srcSystem=server.sysid, srcComponent=server.compid),
        }
        self._parser = {"gcs": mavlink.MAVLink(None), "veh": mavlink.MAVLink(None)}
        self.to_vehicle: list[mavlink.MAVLink_message] = []  # what the GCS sent (before loss)
        self.to_gcs: list[mavlink.MAVLink_message] = []

    def _send(self, side: str, msgs: list, now: float) -> None:
        dest = "veh" if side == "gcs" else "gcs"
        for m in msgs:
            (self.to_vehicle if side == "gcs" else self.to_gcs).append(m)
            raw = m.pack(self._mav[side])
            for t in self.channel.arrivals(now):
                heapq.heappush(self._queue, (t, next(self._tie), dest, bytes(raw)))

    def run(self, transfer: Transfer, until_s: float = 120.0) -> Transfer:
        self._send("gcs", transfer.start(self.now), self.now)
        while not transfer.done and self.now < until_s:
            candidates = [t for t in (transfer.deadline_s, self.server.next_deadline_s()) if t is not None]
            if self._queue:
                candidates.append(self._queue[0][0])
            if not candidates:
                break
            self.now = max(self.now, min(candidates))
            while self._queue and self._queue[0][0] <= self.now:
                _, _, dest, raw = heapq.heappop(self._queue)
                msg = self._parser[dest].parse_char(bytearray(raw))
                attach_extensions(msg, raw)
                if dest == "veh":
                    self._send("veh", self.server.handle(msg, self.now), self.now)
                else:
                    self._send("gcs", transfer.on_message(msg, self.now), self.now)
            self._send("gcs", transfer.on_timeout(self.now), self.now)
            self._send("veh", self.server.poll(self.now), self.now)
        return transfer

    def sent(self, name: str, seq: int | None = None) -> int:
        return sum(1 for m in self.to_vehicle if m.get_type() == name and (seq is None or m.seq == seq))


class DropOnce(Sim):
    """A Sim whose channel loses the first frame of one type and seq (request types by prefix)."""

    def __init__(self, server: MissionServer, channel: Channel, name: str, seq: int) -> None:
        super().__init__(server, channel)
        self.victim: tuple[str, int] | None = (name, seq)

    def _send(self, side: str, msgs: list, now: float) -> None:
        kept = []
        for m in msgs:
            if (
                self.victim
                and m.get_type().startswith(self.victim[0])
                and getattr(m, "seq", -1) == self.victim[1]
            ):
                self.victim = None
                (self.to_vehicle if side == "gcs" else self.to_gcs).append(m)
                continue
            kept.append(m)
        super()._send(side, kept, now)


def mission(
    n: int, mission_type: int = MissionType.MISSION, base_lat: int = 473_977_000
) -> list[MissionItem]:
    """Items whose values survive ArduPilot's storage rounding (cm altitude, integer hold)."""
    return [
        MissionItem(
            seq=i,
            frame=3,
            command=16,
            current=int(i == 0),
            param1=float(i % 3),
            x=base_lat + 37 * i,
            y=85_455_000 - 11 * i,
            z=round(10.0 + 0.25 * i, 2),
            mission_type=mission_type,
        )
        for i in range(n)
    ]


def server(profile: str = "ardupilot", **kwargs) -> MissionServer:
    return MissionServer(1, 1, PROFILES[profile], **kwargs)


def upload(sim: Sim, items: list[MissionItem], **kwargs) -> UploadTransfer:
    return sim.run(UploadTransfer(1, items, mission_type=items[0].mission_type if items else 0, **kwargs))


def preload(srv: MissionServer, items: list[MissionItem]) -> None:
    assert upload(Sim(srv), items).outcome.error is None


PROFILE_NAMES = ["ardupilot", "px4"]


@pytest.mark.parametrize("profile", PROFILE_NAMES)
@pytest.mark.parametrize("mission_type", [MissionType.MISSION, MissionType.FENCE, MissionType.RALLY])
def test_clean_round_trip_sends_each_item_once(profile, mission_type):
    srv = server(profile)
    items = mission(8, mission_type)
    sim = Sim(srv)
    up = upload(sim, items)
    assert up.outcome.error is None
    assert up.outcome.opaque_id == srv.opaque_id(mission_type) != 0
    assert sim.sent("MISSION_COUNT") == 1 and sim.sent("MISSION_ITEM_INT") == len(items)
    down = Sim(srv).run(DownloadTransfer(1, mission_type=mission_type))
    assert down.outcome.error is None and down.outcome.opaque_id == up.outcome.opaque_id
    assert down.outcome.items == kept(srv, items)  # what the autopilot keeps (readback.py)


def test_ardupilot_truncates_stored_values_px4_does_not():
    """AP_Mission keeps the altitude as int32 cm (12.3456 m -> 1234 cm) and the hold in a uint16."""
    item = MissionItem(
        seq=0, frame=6, command=16, param1=2.7, param2=3.6, x=473_977_000, y=85_455_000, z=12.3456
    )
    for profile, frame, p1, z in (("ardupilot", 3, 2.0, 12.34), ("px4", 6, 2.7, 12.3456)):
        srv = server(profile)
        preload(srv, [item])
        got = Sim(srv).run(DownloadTransfer(1)).outcome.items[0]
        assert (
            got.frame == frame
            and got.param1 == pytest.approx(p1, abs=1e-6)
            and got.z == pytest.approx(z, 1e-6)
        )


def test_count_no_response_resends_count_then_times_out_and_keeps_previous():
    srv = server()
    old = mission(3)
    preload(srv, old)
    srv.failure = Failure.WRITE_COUNT_NO_RESPONSE
    sim = Sim(srv)
    up = upload(sim, mission(5, base_lat=400_000_000))
    assert isinstance(up.outcome.error, errors.MissionTimeoutError)
    assert sim.sent("MISSION_COUNT") == 1 + COUNT_RETRIES
    assert sim.now == pytest.approx((1 + COUNT_RETRIES) * COUNT_RETRY_S)
    assert srv.items() == _stored(srv, old)


def kept(srv: MissionServer, items: list[MissionItem]) -> list[MissionItem]:
    """What the server's autopilot stores of ``items`` (its readback model)."""
    return [srv.storage(i) for i in items]


def _stored(srv: MissionServer, items: list[MissionItem]) -> list[MissionItem]:
    """The items as the server stores them (ArduPilot normalises frames)."""
    return srv.items()[: len(items)] if len(srv.items()) == len(items) else []


def test_count_first_response_recovers_with_one_resend():
    srv = server("px4")
    srv.failure = Failure.WRITE_COUNT_FIRST_RESPONSE
    sim = Sim(srv)
    items = mission(4)
    assert upload(sim, items).outcome.error is None
    assert sim.sent("MISSION_COUNT") == 2 and srv.items() == kept(srv, items)


@pytest.mark.parametrize(("profile", "cancel_at_s"), [("ardupilot", 8.0), ("px4", 5.0)])
def test_request1_no_response_vehicle_cancels_previous_intact(profile, cancel_at_s):
    """The spec-literal client (no push-ahead, one item in flight) waits for a request that never comes."""
    srv = server(profile)
    old = mission(3)
    preload(srv, old)
    before = srv.items()
    srv.failure = Failure.WRITE_REQUEST1_NO_RESPONSE
    sim = Sim(srv)
    new = mission(6, base_lat=400_000_000)
    up = upload(sim, new, timing=Timing(push_ahead=False, window=1))
    assert refused(up.outcome.error, MissionResult.OPERATION_CANCELLED)
    assert sim.now == pytest.approx(cancel_at_s, abs=0.1)
    assert not srv.busy()
    if profile == "px4":
        assert srv.items() == before  # PX4 switches lists on completion only
    else:  # ArduPilot stored item 0 in place: a mix (mission.py reads it back and says so)
        assert srv.items() == [srv.storage(new[0]), *before[1:]]


@pytest.mark.parametrize("profile", PROFILE_NAMES)
@pytest.mark.parametrize("window", [1, 2])
def test_request1_no_response_recovered_by_push_ahead(profile, window):
    """One item in flight: the client pushes item 1 when its request is overdue and the vehicle takes
    it. Two in flight: item 1 left with item 0, so nothing is missing."""
    srv = server(profile)
    srv.failure = Failure.WRITE_REQUEST1_NO_RESPONSE
    sim = Sim(srv)
    items = mission(6, base_lat=400_000_000)
    up = upload(sim, items, timing=Timing(window=window))
    assert up.outcome.error is None and srv.items() == kept(srv, items)
    assert sim.now < 0.2  # the vehicle itself would have waited 5-8 s
    assert sim.sent("MISSION_ITEM_INT", 0) == 3 - window and sim.sent("MISSION_ITEM_INT", 1) == 1


@pytest.mark.parametrize("profile", PROFILE_NAMES)
@pytest.mark.parametrize("window", [2, 4])
def test_items_in_flight_divide_a_slow_links_upload_time_and_go_once_in_order(profile, window):
    items = mission(40)
    spec = Sim(server(profile), Channel(delay_s=0.05))
    upload(spec, items, timing=Timing(window=1))
    srv = server(profile)
    sim = Sim(srv, Channel(delay_s=0.05))
    up = upload(sim, items, timing=Timing(window=window))
    assert up.outcome.error is None and srv.items() == kept(srv, items)
    assert [sim.sent("MISSION_ITEM_INT", k) for k in range(40)] == [1] * 40
    assert up.stats.invalid_sequence_acks == 0  # never ahead of what the vehicle waits for
    assert sim.now < 1.1 * spec.now / window  # ``window`` items per round trip instead of one


@pytest.mark.parametrize(("autopilot", "pipelined"), [(3, True), (12, True), (0, False), (None, False)])
def test_items_go_unasked_only_to_autopilots_that_drop_unexpected_ones(autopilot, pipelined):
    """ArduPilot (3) and PX4 (12) drop an item whose seq they do not wait for; MAVSDK's server
    (generic, 0) stores it, and before a HEARTBEAT the autopilot is unknown."""
    from gcs_planner.mavlink.link import MavlinkLink, VehicleInfo
    from gcs_planner.mavlink.mission import MissionClient

    link = MavlinkLink()
    if autopilot is not None:
        link.vehicles[1] = VehicleInfo(1, ("127.0.0.1", 14550), autopilot=autopilot)
    timing = MissionClient(link, 1)._transfer(UploadTransfer, items=mission(3)).timing
    assert (timing.window, timing.push_ahead) == ((Timing.window, True) if pipelined else (1, False))


def test_a_window_of_no_items_is_refused():
    with pytest.raises(ValueError, match="Timing.window is 0"):
        Timing(window=0)


@pytest.mark.parametrize("profile", PROFILE_NAMES)
@pytest.mark.parametrize("victim", [("MISSION_ITEM_INT", 3), ("MISSION_REQUEST", 4), ("MISSION_ITEM_INT", 9)])
@pytest.mark.parametrize("window", [2, 4])
def test_a_lost_frame_with_items_in_flight_costs_a_push_not_the_vehicle_retry(profile, victim, window):
    """The vehicle drops what follows a lost item, so the push resends the window (go-back-N)."""
    srv = server(profile)
    sim = DropOnce(srv, Channel(delay_s=0.02), *victim)
    items = mission(10)
    clean = Sim(server(profile), Channel(delay_s=0.02))
    upload(clean, items, timing=Timing(window=window))
    up = upload(sim, items, timing=Timing(window=window))
    assert up.outcome.error is None and srv.items() == kept(srv, items)
    # the vehicle's own re-request: 0.25 s (PX4), 1 s (ArduPilot); the last item has the 0.3 s ACK timer
    assert sim.now - clean.now < (0.35 if victim[1] == 9 else 0.1)
    assert sum(sim.sent("MISSION_ITEM_INT", k) for k in range(10)) <= 10 + 2 * window


@pytest.mark.parametrize("profile", PROFILE_NAMES)
@pytest.mark.parametrize("direction", ["item", "request"])
def test_one_lost_frame_costs_a_push_not_the_vehicle_retry(profile, direction):
    """Item 3 or the request for item 4 lost on a 20 ms link, one item in flight: recovered in
    ~2.5 RTT + 1 RTT."""
    srv = server(profile)
    victim = ("MISSION_ITEM_INT", 3) if direction == "item" else ("MISSION_REQUEST", 4)
    sim = DropOnce(srv, Channel(delay_s=0.02), *victim)
    items = mission(10)
    clean = Sim(server(profile), Channel(delay_s=0.02))
    upload(clean, items, timing=Timing(window=1))
    up = upload(sim, items, timing=Timing(window=1))
    assert up.outcome.error is None and srv.items() == kept(srv, items)
    assert sim.now - clean.now < 0.2  # the vehicle's own re-request: 0.25 s (PX4), 1 s (ArduPilot)
    assert sim.sent("MISSION_ITEM_INT", 3) == 2  # the push resent 3 ...
    assert sim.sent("MISSION_ITEM_INT", 4) == 1  # ... and sent 4 once, unasked


@pytest.mark.parametrize("profile", PROFILE_NAMES)
@pytest.mark.parametrize(
    "failure", [Failure.WRITE_REQUEST0_INCORRECT_SEQUENCE, Failure.WRITE_REQUEST1_INCORRECT_SEQUENCE]
)
@pytest.mark.parametrize("window", [1, 2])
def test_incorrect_sequence_requests_are_recovered(profile, failure, window):
    srv = server(profile)
    srv.failure = failure
    sim = Sim(srv)
    items = mission(5)
    up = upload(sim, items, timing=Timing(window=window))
    assert up.outcome.error is None
    assert srv.items() == kept(srv, items)
    if profile == "ardupilot" and window == 1 and failure == Failure.WRITE_REQUEST1_INCORRECT_SEQUENCE:
        # ArduPilot answers the skipped item with INVALID_SEQUENCE (a first request for item 1 is
        # ignored: a session starts at item 0, so it answers someone else's MISSION_COUNT)
        assert up.stats.invalid_sequence_acks >= 1


@pytest.mark.parametrize(
    ("failure", "result"),
    [
        (Failure.WRITE_REQUEST0_ERROR_ACK, MissionResult.ERROR),
        (Failure.WRITE_REQUEST1_ERROR_ACK, MissionResult.UNSUPPORTED_FRAME),
        (Failure.WRITE_FINAL_ACK_ERROR_ACK, MissionResult.INVALID_PARAM5_X),
    ],
)
def test_error_acks_become_typed_errors_and_keep_previous(failure, result):
    srv = server("px4")  # PX4 keeps the previous list; ArduPilot stores in place (test below)
    preload(srv, mission(3))
    before, before_id = srv.items(), srv.opaque_id()
    srv.failure, srv.failure_result = failure, result
    up = upload(Sim(srv), mission(4, base_lat=400_000_000))
    assert refused(up.outcome.error, result)
    assert srv.items() == before and srv.opaque_id() == before_id


def test_non_atomic_final_error_leaves_a_mix_but_is_reported():
    srv = server(non_atomic=True)
    preload(srv, mission(6))
    srv.failure = Failure.WRITE_FINAL_ACK_ERROR_ACK
    new = mission(4, base_lat=400_000_000)
    up = upload(Sim(srv), new)
    assert refused(up.outcome.error, MissionResult.ERROR)
    assert [i.x for i in srv.items()] == [i.x for i in new]  # ArduPilot wrote the items anyway
    assert srv.opaque_id() == 0  # ... and the list is no known plan


@pytest.mark.parametrize(("profile", "acked"), [("ardupilot", False), ("px4", False)])
def test_final_ack_no_response_resends_only_last_item(profile, acked):
    srv = server(profile)
    srv.failure = Failure.WRITE_FINAL_ACK_NO_RESPONSE
    sim = Sim(srv)
    items = mission(5)
    up = upload(sim, items)
    assert up.outcome.ack_lost
    timing = Timing()
    if profile == "ardupilot":  # the resent last item is answered MISSION_ACK(ERROR): no upload runs
        assert refused(up.outcome.error, MissionResult.ERROR)
        assert sim.sent("MISSION_ITEM_INT", 4) == 2
    else:
        assert isinstance(up.outcome.error, errors.MissionTimeoutError)
        assert sim.sent("MISSION_ITEM_INT", 4) == 1 + timing.final_item_retries
    assert all(sim.sent("MISSION_ITEM_INT", s) == 1 for s in range(4))
    assert len(srv.items()) == 5  # the vehicle took it: mission.py verifies by download in this case


def test_px4_reacks_repeated_final_item_when_ack_lost():
    srv = server("px4")
    items = mission(3)

    class DropFirstFinalAck(Channel):
        dropped = False

    sim = Sim(srv)
    orig = srv.handle

    def handle(msg, now):
        out = orig(msg, now)
        if out and out[0].get_type() == "MISSION_ACK" and not DropFirstFinalAck.dropped:
            DropFirstFinalAck.dropped = True
            return []
        return out

    srv.handle = handle
    up = upload(sim, items)
    assert up.outcome.error is None and up.outcome.opaque_id == srv.opaque_id()
    assert sim.sent("MISSION_ITEM_INT", 2) == 2


def test_duplicated_link_does_not_flood():
    srv = server("px4")
    sim = Sim(srv, Channel(duplicate=1.0))
    items = mission(20)
    up = upload(sim, items)
    assert up.outcome.error is None and srv.items() == kept(srv, items)
    assert sim.sent("MISSION_ITEM_INT") == len(items) and up.stats.duplicates_ignored >= len(items) - 1


def test_stale_accepted_before_last_item_is_ignored():
    up = UploadTransfer(1, mission(3))
    up.start(0.0)
    stale = mavlink.MAVLink_mission_ack_message(255, 190, MissionResult.ACCEPTED, 0)
    stale._header = mavlink.MAVLink_header(stale.id, srcSystem=1, srcComponent=1)
    assert up.on_message(stale, 0.1) == [] and not up.done


def test_accepted_counts_once_every_item_went_out_though_the_last_request_was_lost():
    """Three items leave with the first request; the vehicle stores them and ACKs, but its request
    for the last item is lost: the ACK is the upload's (not stale, not a lost ACK to read back)."""
    up = UploadTransfer(1, mission(3))
    up.start(0.0)
    assert up.on_request(0, (1, 1), (255, 190), 0, 0.01) == [0, 1, 2]
    up.on_request(1, (1, 1), (255, 190), 0, 0.02)  # the request for 2 is lost
    ack = _from_vehicle(mavlink.MAVLink_mission_ack_message(255, 190, MissionResult.ACCEPTED, 0))
    up.on_message(ack, 0.03)
    assert up.done and up.outcome.error is None and not up.outcome.ack_lost


@pytest.mark.parametrize("profile", PROFILE_NAMES)
@pytest.mark.parametrize("seed", range(6))
def test_lossy_link_gives_equal_mission_or_reported_failure(profile, seed):
    srv = server(profile)
    old = mission(4)
    preload(srv, old)
    before = srv.items()
    new = mission(25, base_lat=400_000_000)
    sim = Sim(srv, Channel(loss=0.2, duplicate=0.1, reorder=0.2, delay_s=0.01, seed=seed))
    up = upload(sim, new)
    if up.outcome.error is None:
        got = Sim(srv, Channel(loss=0.2, duplicate=0.1, reorder=0.2, seed=seed + 100)).run(
            DownloadTransfer(1)
        )
        assert got.outcome.error is None
        assert [(i.x, i.y, i.z) for i in got.outcome.items] == [(i.x, i.y, i.z) for i in new]
    elif up.outcome.ack_lost:
        assert srv.items() in (before, srv.items()) and len(srv.items()) in (len(old), len(new))
    else:
        assert srv.items() == before


@pytest.mark.parametrize("window", [2, 8, 16])
def test_lossy_link_mostly_succeeds(window):
    """ack_lost only where the vehicle holds the mission: with a wide window a push sends the last
    item while the vehicle still waits for an earlier one, and the final-item timer resends from
    there instead of running out (it reported a lost ACK of a vehicle mid-upload: window 8, seed 7)."""
    ok = 0
    for seed in range(10):
        srv = server("ardupilot")
        sim = Sim(srv, Channel(loss=0.2, seed=seed))
        items = mission(30)
        outcome = upload(sim, items, timing=Timing(window=window)).outcome
        if outcome.ack_lost:  # ArduPilot never repeats a lost final ACK: the vehicle holds the mission
            assert [i.x for i in srv.items()] == [i.x for i in items]
        ok += outcome.error is None or outcome.ack_lost
    assert ok >= 9


def test_second_uploader_and_foreign_items_are_denied():
    srv = server()
    first = UploadTransfer(1, mission(3))
    mav = mavlink.MAVLink(None, srcSystem=255, srcComponent=190)
    other = mavlink.MAVLink(None, srcSystem=254, srcComponent=190)
    parser = mavlink.MAVLink(None)

    def deliver(msg, mav_):
        raw = msg.pack(mav_)
        return srv.handle(parser.parse_char(bytearray(raw)), 0.0)

    request = deliver(first.start(0.0)[0], mav)
    assert request[0].get_type() == "MISSION_REQUEST"
    second = deliver(mavlink.MAVLink_mission_count_message(1, 1, 2, 0), other)
    assert second[0].get_type() == "MISSION_ACK" and second[0].type == MissionResult.DENIED
    foreign = deliver(UploadTransfer(1, mission(3))._item(0), other)
    assert foreign[0].type == MissionResult.DENIED
    download = deliver(mavlink.MAVLink_mission_request_list_message(1, 1, 0), other)
    assert download[0].type == MissionResult.DENIED


def test_over_capacity_is_no_space_with_statustext():
    srv = server(capacity=10)
    sim = Sim(srv)
    up = upload(sim, mission(11))
    assert refused(up.outcome.error, MissionResult.NO_SPACE)
    assert any(m.get_type() == "STATUSTEXT" and b"10" in m.text.encode() for m in sim.to_gcs)


def test_clear_refused_in_auto_on_ardupilot_but_empty_upload_works():
    srv = server()
    preload(srv, mission(3))
    srv.mission_running = True
    clear = Sim(srv).run(ClearTransfer(1))
    assert refused(clear.outcome.error, MissionResult.ERROR) and srv.count() == 3
    assert upload(Sim(srv), []).outcome.error is None and srv.count() == 0
    srv2 = server("px4")
    preload(srv2, mission(3))
    srv2.mission_running = True
    assert Sim(srv2).run(ClearTransfer(1, mission_type=MissionType.ALL)).outcome.error is None
    assert srv2.count() == 0


def test_set_current_legacy_confirmed_by_mission_current():
    srv = server()
    preload(srv, mission(5))
    assert Sim(srv).run(SetCurrentTransfer(1, 3)).outcome.error is None and srv.current_seq == 3
    bad = Sim(srv).run(SetCurrentTransfer(1, 9))
    assert isinstance(bad.outcome.error, errors.MissionTimeoutError) and srv.current_seq == 3


@pytest.mark.parametrize(
    ("failure", "ok", "error"),
    [
        (Failure.READ_REQUEST_LIST_NO_RESPONSE, False, errors.MissionTimeoutError),
        (Failure.READ_REQUEST_LIST_FIRST_RESPONSE, True, None),
        (Failure.READ_REQUEST0_NO_RESPONSE, False, errors.MissionTimeoutError),
        (Failure.READ_REQUEST1_NO_RESPONSE, False, errors.MissionTimeoutError),
        (Failure.READ_REQUEST0_FIRST_RESPONSE, True, None),
        (Failure.READ_REQUEST1_FIRST_RESPONSE, True, None),
        (Failure.READ_REQUEST0_INCORRECT_SEQUENCE, False, errors.MissionTimeoutError),
        (Failure.READ_REQUEST1_INCORRECT_SEQUENCE, False, errors.MissionTimeoutError),
        (Failure.READ_REQUEST0_ERROR_ACK, False, MissionResult.ERROR),
        (Failure.READ_REQUEST1_ERROR_ACK, False, MissionResult.ERROR),
    ],
)
def test_download_failure_matrix(failure, ok, error):
    srv = server("px4")
    items = mission(4)
    preload(srv, items)
    srv.failure = failure
    sim = Sim(srv)
    down = sim.run(DownloadTransfer(1))
    if ok:
        assert down.outcome.error is None and down.outcome.items == kept(srv, items)
    else:
        refusal = isinstance(error, MissionResult)
        assert refused(down.outcome.error, error) if refusal else type(down.outcome.error) is error
        assert down.outcome.items is None
    if failure == Failure.READ_REQUEST1_NO_RESPONSE:
        assert sim.sent("MISSION_REQUEST_INT", 1) == 1 + Timing().download_retries
    if failure == Failure.READ_REQUEST_LIST_NO_RESPONSE:
        assert sim.sent("MISSION_REQUEST_LIST") == 1 + COUNT_RETRIES


def test_cancel_mid_upload_releases_px4_session():
    srv = server("px4")
    up = UploadTransfer(1, mission(5))
    sim = Sim(srv)
    sim._send("gcs", up.start(0.0), 0.0)
    sim.run(up, until_s=0.003)  # COUNT delivered, first request on its way
    assert srv.busy()
    sim._send("gcs", up.cancel(sim.now), sim.now)
    sim.run(DownloadTransfer(1))  # delivers the cancel first, then downloads
    assert refused(up.outcome.error, MissionResult.OPERATION_CANCELLED) and not srv.busy()


def test_bad_items_rejected_before_anything_is_sent():
    items = mission(3)
    with pytest.raises(errors.MissionInputError, match="item 1: seq is 2"):
        UploadTransfer(1, [items[0], items[2]])
    with pytest.raises(errors.MissionInputError, match="mission_type"):
        UploadTransfer(1, items, mission_type=MissionType.FENCE)


def test_server_rejects_unknown_command_and_bad_latitude():
    for item, error in (
        (MissionItem(seq=0, frame=3, command=60000, x=1, y=1), MissionResult.UNSUPPORTED),
        (MissionItem(seq=0, frame=3, command=16, x=910_000_000, y=1), MissionResult.INVALID_PARAM5_X),
    ):
        srv = server()
        up = upload(Sim(srv), [item])
        assert refused(up.outcome.error, error) and srv.count() == 0


def test_partial_write_replaces_only_its_range_on_ardupilot_and_px4_refuses_it():
    srv = server("ardupilot")
    old = mission(6)
    preload(srv, old)
    new = [replace(it, x=it.x + 999) for it in old[2:5]]
    sim = Sim(srv)
    up = sim.run(UploadTransfer(1, new, partial=True))
    assert up.outcome.error is None
    assert srv.items()[2:5] == kept(srv, new) and srv.items()[:2] == kept(srv, old[:2])
    assert srv.items()[5] == srv.storage(old[5])
    assert sim.sent("MISSION_WRITE_PARTIAL_LIST") == 1 and sim.sent("MISSION_COUNT") == 0
    assert [m.seq for m in sim.to_vehicle if m.get_type() == "MISSION_ITEM_INT"] == [2, 3, 4]

    px4 = server("px4")
    preload(px4, old)
    up = Sim(px4).run(UploadTransfer(1, new, partial=True))
    assert refused(up.outcome.error, MissionResult.UNSUPPORTED)
    assert "partial upload: UNSUPPORTED" in str(up.outcome.error) and px4.items() == kept(px4, old)


@pytest.mark.parametrize("seed", range(4))
def test_partial_write_over_a_lossy_link(seed):
    srv = server("ardupilot")
    old = mission(10)
    preload(srv, old)
    new = [replace(it, z=it.z + 5.0) for it in old[4:9]]
    up = Sim(srv, Channel(loss=0.2, duplicate=0.1, reorder=0.2, seed=seed)).run(
        UploadTransfer(1, new, partial=True)
    )
    if up.outcome.error is None or up.outcome.ack_lost:
        assert srv.items()[4:9] == new
    else:
        assert srv.items() == old
    assert srv.items()[:4] == old[:4] and srv.items()[9:] == old[9:]


def test_partial_write_input_is_checked():
    with pytest.raises(errors.MissionInputError, match="at least one item"):
        UploadTransfer(1, [], partial=True)
    with pytest.raises(errors.MissionInputError, match="item 1: seq is 7, expected 4"):
        UploadTransfer(1, [mission(5)[3], mission(8)[7]], partial=True)


def _from_vehicle(msg: mavlink.MAVLink_message) -> mavlink.MAVLink_message:
    msg._header = mavlink.MAVLink_header(msg.id, srcSystem=1, srcComponent=1)
    return msg


def _request(seq: int) -> mavlink.MAVLink_message:
    return _from_vehicle(mavlink.MAVLink_mission_request_int_message(255, 190, seq, 0))


@pytest.mark.parametrize("window", [1, 2, 4])
@pytest.mark.parametrize("asked", [[0, 1, 2, 28], [0, 1, 2, 27, 28], [0, 5, 28], [0, 28]])
def test_accepted_after_skipped_items_is_a_protocol_error_naming_them(window, asked):
    """A vehicle that jumps over items it was never sent cannot hold them: ACCEPTED is no success."""
    up = UploadTransfer(1, mission(29), timing=Timing(window=window, push_ahead=False))
    up.start(0.0)
    t = 0.0
    for seq in asked:
        t += 0.5
        up.on_message(_request(seq), t)
    ack = _from_vehicle(mavlink.MAVLink_mission_ack_message(255, 190, MissionResult.ACCEPTED, 0))
    up.on_message(ack, t + 0.5)
    assert up.done and isinstance(up.outcome.error, errors.MissionProtocolError)
    text = str(up.outcome.error)
    assert "mix" in text and "\n" not in text
    sent = {k for s in asked for k in range(s, min(s + window, 29))}
    missing = sorted(set(range(29)) - sent)
    assert f"without items {missing[0]}" in text and f"{missing[-1]} (never" in text


@pytest.mark.parametrize(("window", "batch", "top_up"), [(16, 8, 8), (8, 8, 4), (2, 8, 1), (3, 8, 1)])
def test_a_window_is_topped_up_a_batch_at_a_time(window, batch, top_up):
    """PX4 sends each request alone: the window is refilled only when a whole top-up (a batch, at
    most half the window) is due, so most requests send nothing and the items leave together; the
    tail of the list goes when the window reaches it; every item goes once."""
    n = 41
    up = UploadTransfer(1, mission(n), timing=Timing(window=window, batch=batch))
    up.start(0.0)
    sends = [up.on_request(seq, (1, 1), (255, 190), 0, 0.001 * (seq + 1)) for seq in range(n)]
    assert sends[0] == list(range(window))
    sent = [k for due in sends for k in due]
    assert sent == list(range(n))  # once each, in order
    refills = [due for due in sends[1:] if due]
    assert all(len(due) == top_up for due in refills[:-1]) and 0 < len(refills[-1]) <= top_up
    assert sum(1 for due in sends if due) == 1 + len(refills)  # the other requests sent nothing


def test_lost_request_for_an_item_in_flight_still_succeeds():
    """With two items in flight a lost request skips an item that was sent: that upload is complete."""
    up = UploadTransfer(1, mission(4), timing=Timing(window=2, push_ahead=False))
    up.start(0.0)
    for t, seq in [(0.1, 0), (0.2, 2), (0.3, 3)]:  # the request for 1 was lost, item 1 went with 0
        up.on_message(_request(seq), t)
    ack = _from_vehicle(mavlink.MAVLink_mission_ack_message(255, 190, MissionResult.ACCEPTED, 0))
    up.on_message(ack, 0.4)
    assert up.done and up.outcome.error is None


def _count(n: int) -> mavlink.MAVLink_message:
    return _from_vehicle(mavlink.MAVLink_mission_count_message(255, 190, n, 0))


def _item_int(seq: int) -> mavlink.MAVLink_message:
    return _from_vehicle(
        mavlink.MAVLink_mission_item_int_message(
            255, 190, seq, 6, 16, 0, 1, 0, 0, 0, 0, 473977420, 85455940, 20, 0
        )
    )


def test_a_vehicle_that_answers_each_request_on_its_last_retry_cannot_hold_a_download_for_hours():
    """Each item came just before its retries ran out, so no per-item limit ever fired: 65535 items
    took ~36 h. The download now ends at the upload's overall bound, 20 s + 1 s an item."""
    n = 40  # ~3 s an item here: ~120 s unbounded
    down = DownloadTransfer(1)
    down.start(0.0)
    t = 0.1
    down.on_message(_count(n), t)
    while not down.done and t < 3600:
        for _ in range(Timing().download_retries):  # every re-request goes unanswered ...
            t = down.deadline_s
            down.on_timeout(t)
            if down.done:
                break
        if not down.done:  # ... and the last one is answered
            down.on_message(_item_int(len(down._items)), t + 0.01)
    assert down.done and isinstance(down.outcome.error, errors.MissionTimeoutError)
    assert t <= 20 + n + 0.1
    assert f"of {n} items in {20 + n} s" in str(down.outcome.error)


@pytest.mark.parametrize("x", [float("nan"), float("inf"), 1e30])
def test_a_legacy_float_item_that_no_int32_holds_ends_the_download_naming_it(x):
    """A float MISSION_ITEM with a NaN latitude raised inside the link's subscriber (logged, then
    re-requested until 'item 0 not received'): now the download ends once, naming the item."""
    down = DownloadTransfer(1)
    down.start(0.0)
    down.on_message(_count(2), 0.1)
    legacy = _from_vehicle(
        mavlink.MAVLink_mission_item_message(255, 190, 0, 6, 16, 0, 1, 0, 0, 0, 0, x, 8.5, 20, 0)
    )
    out = down.on_message(legacy, 0.2)
    assert down.done and isinstance(down.outcome.error, errors.MissionProtocolError)
    assert "item 0: x = " in str(down.outcome.error) and "MISSION_ITEM" in str(down.outcome.error)
    assert [m.get_type() for m in out] == ["MISSION_ACK"]


def test_a_vehicle_that_asks_only_for_items_outside_the_upload_is_not_called_silent():
    """It asked for item 45 of 40 every time: the timeout said 'no answer to MISSION_COUNT'."""
    up = UploadTransfer(1, mission(40))
    up.start(0.0)
    t = 0.0
    while not up.done:
        up.on_message(_request(45), t + 0.01)
        t = up.deadline_s
        up.on_timeout(t)
    text = str(up.outcome.error)
    assert isinstance(up.outcome.error, errors.MissionTimeoutError) and "no answer" not in text
    assert "asked only for items outside this upload's 0-39, e.g. 45" in text
