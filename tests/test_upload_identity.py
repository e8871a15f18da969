"""Issue 14: an upload session belongs to one GCS, a busy vehicle cannot keep an upload running for
ever, and giving up tells the vehicle. Fake time, real MAVLink bytes between the client core and the
mock's server core; two GCSs share the vehicle's channel (the vehicle's frames reach both)."""

from __future__ import annotations

import heapq
import itertools

import pytest
from pymavlink.dialects.v20 import ardupilotmega as mavlink
from refusals import refused

from gcs_planner.mavlink import errors
from gcs_planner.mavlink.transfer import DownloadTransfer, Timing, UploadTransfer
from gcs_planner.wire.enums import MissionResult
from gcs_planner.wire.wire import attach_extensions
from sitl_mock.mission_server import Failure
from tests.test_mission_transfer import Sim, kept, mission, preload, server


class TwoGcs:
    """One vehicle, two GCSs on one broadcast channel (10 ms each way); each GCS has its own ids."""

    def __init__(self, srv, delay_s: float = 0.01) -> None:
        self.srv, self.delay_s, self.now = srv, delay_s, 0.0
        self._queue: list = []
        self._tie = itertools.count()
        self._veh = mavlink.MAVLink(None, srcSystem=srv.sysid, srcComponent=srv.compid)
        self._parsers: dict[str, mavlink.MAVLink] = {"veh": mavlink.MAVLink(None)}
        self.gcs: dict[str, tuple[mavlink.MAVLink, UploadTransfer, float]] = {}

    def add(self, name: str, transfer: UploadTransfer, start_s: float) -> None:
        self.gcs[name] = (mavlink.MAVLink(None, srcSystem=transfer.gcs[0], srcComponent=transfer.gcs[1]),
                          transfer, start_s)  # fmt: skip
        self._parsers[name] = mavlink.MAVLink(None)

    def _send(self, src: str, msgs: list) -> None:
        mav = self._veh if src == "veh" else self.gcs[src][0]
        for m in msgs:
            raw = bytes(m.pack(mav))
            for dest in [n for n in self.gcs] if src == "veh" else ["veh"]:
                heapq.heappush(self._queue, (self.now + self.delay_s, next(self._tie), dest, raw))

    def run(self, until_s: float = 60.0) -> None:
        started: set[str] = set()
        while self.now < until_s:
            times = [t for _, tr, t in self.gcs.values()]
            times = [t for n, (_, _, t) in self.gcs.items() if n not in started]
            times += [
                tr.deadline_s for _, tr, _ in self.gcs.values() if tr.deadline_s is not None and not tr.done
            ]
            if self.srv.next_deadline_s() is not None:
                times.append(self.srv.next_deadline_s())
            if self._queue:
                times.append(self._queue[0][0])
            if not times:
                return
            self.now = max(self.now, min(times))
            for name, (_, tr, t) in self.gcs.items():
                if name not in started and t <= self.now:
                    started.add(name)
                    self._send(name, tr.start(self.now))
            while self._queue and self._queue[0][0] <= self.now:
                _, _, dest, raw = heapq.heappop(self._queue)
                msg = self._parsers[dest].parse_char(bytearray(raw))
                attach_extensions(msg, raw)
                if dest == "veh":
                    self._send("veh", self.srv.handle(msg, self.now))
                elif dest in started:  # a GCS not started yet has no socket open
                    self._send(dest, self.gcs[dest][1].on_message(msg, self.now))
            for name, (_, tr, _) in self.gcs.items():
                if name in started:
                    self._send(name, tr.on_timeout(self.now))
            self._send("veh", self.srv.poll(self.now))
            if all(tr.done for _, tr, _ in self.gcs.values()) and not self.srv.busy():
                return


def two_uploads(profile: str, ids_b: tuple[int, int], start_b_s: float):
    srv = server(profile)
    old = mission(5, base_lat=300_000_000)
    preload(srv, old)
    before = srv.items()
    # A still runs when B starts (0.1 s, 0.3 s): a window of items per 20 ms round trip here
    n = 20 * Timing().window
    a_items, b_items = mission(n, base_lat=400_000_000), mission(n, base_lat=410_000_000)
    sim = TwoGcs(srv)
    a = UploadTransfer(1, a_items, gcs_sysid=255, gcs_compid=190)
    b = UploadTransfer(1, b_items, gcs_sysid=ids_b[0], gcs_compid=ids_b[1])
    sim.add("a", a, 0.0)
    sim.add("b", b, start_b_s)
    sim.run()
    assert a.done and b.done
    return srv, before, (a, a_items), (b, b_items)


@pytest.mark.parametrize("profile", ["ardupilot", "px4"])
@pytest.mark.parametrize("ids_b", [(254, 190), (255, 191)])
def test_a_second_gcs_with_other_ids_is_refused_and_nothing_is_merged(profile, ids_b):
    """ArduPilot DENIES a MISSION_COUNT from other ids mid-upload, PX4 answers it ERROR; the first
    upload ignores the vehicle's frames to the other GCS (same sysid, other compid) and completes."""
    srv, _, (a, a_items), (b, _) = two_uploads(profile, ids_b, start_b_s=0.1)
    assert a.outcome.error is None
    expected = MissionResult.DENIED if profile == "ardupilot" else MissionResult.ERROR
    assert refused(b.outcome.error, expected)
    assert srv.items() == kept(srv, a_items)


def test_the_same_ids_restarting_an_ardupilot_upload_is_detected_and_not_fed():
    """ArduPilot lets a MISSION_COUNT of the uploader's own ids restart the upload; the first GCS
    sees the vehicle go back to item 0, stops (its items would mix into the new session) and says
    why; the vehicle ends with the second GCS's mission, whole."""
    srv, _, (a, _), (b, b_items) = two_uploads("ardupilot", (255, 190), start_b_s=0.3)
    assert isinstance(a.outcome.error, errors.MissionProtocolError)
    assert "another GCS with our ids (255/190)" in str(a.outcome.error)
    assert b.outcome.error is None and srv.items() == kept(srv, b_items)


def test_the_same_ids_on_px4_fail_both_uploads_and_keep_the_previous_mission():
    """PX4 answers a second MISSION_COUNT of the partner's ids with ERROR once items flow (to both
    GCSs: they share the ids); the first then cancels, and PX4 keeps the list it had."""
    srv, before, (a, _), (b, _) = two_uploads("px4", (255, 190), start_b_s=0.3)
    assert refused(a.outcome.error, MissionResult.ERROR)
    assert refused(b.outcome.error, MissionResult.ERROR)
    assert srv.items() == before and not srv.busy()


@pytest.mark.parametrize("profile", ["ardupilot", "px4"])
def test_a_vehicle_asking_for_item_0_for_ever_meets_the_deadline_and_is_cancelled(profile):
    srv = server(profile)
    srv.failure = Failure.WRITE_REQUEST0_REPEAT
    sim = Sim(srv)
    items = mission(6)
    timing = Timing(deadline_base_s=5.0, deadline_per_item_s=0.5)
    up = sim.run(UploadTransfer(1, items, timing=timing), until_s=60.0)
    assert up.done and isinstance(up.outcome.error, errors.MissionTimeoutError)
    assert "not done within 8 s, the bound for 6 items" in str(up.outcome.error)
    assert sim.now == pytest.approx(8.0, abs=0.05)
    last = sim.to_vehicle[-1]
    assert last.get_type() == "MISSION_ACK" and last.type == MissionResult.OPERATION_CANCELLED
    if profile == "px4":  # PX4 ends the session on the cancel; ArduPilot ignores it (8 s timeout)
        sim.run(DownloadTransfer(1), until_s=sim.now + 0.05)  # delivers the cancel
        assert not srv.busy()


def test_the_default_deadline_grows_with_the_item_count():
    assert UploadTransfer(1, mission(3)).give_up_after_s == 23.0
    assert UploadTransfer(1, mission(300)).give_up_after_s == 320.0


def test_giving_up_after_the_last_item_cancels_the_session():
    """No final ACK (lost for good): the client's last word is MISSION_ACK(OPERATION_CANCELLED)."""
    srv = server("px4")
    srv.failure = Failure.WRITE_FINAL_ACK_NO_RESPONSE
    sim = Sim(srv)
    up = sim.run(UploadTransfer(1, mission(4)))
    assert up.outcome.ack_lost
    last = sim.to_vehicle[-1]
    assert last.get_type() == "MISSION_ACK" and last.type == MissionResult.OPERATION_CANCELLED
