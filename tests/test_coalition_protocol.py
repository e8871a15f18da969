"""Contract-net timing: stay-in-range prediction, late bids, delta_max (seed 003 eqs. 20-23)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from gcs_planner.planning.coalition import simulate
from gcs_planner.planning.coalition.contract_net import Tender, bid_for, tender_times
from gcs_planner.planning.coalition.model import CoalitionParams, Target, UavSpec, World
from gcs_planner.planning.coalition.track import Leg, Loiter, Track


def _target(**kw) -> Target:
    d = dict(
        id="T",
        approx_xy=(0.0, 0.0),
        xy=(0.0, 0.0),
        appear_s=0.0,
        recon_s=5.0,
        recon_angle_rad=0.0,
        recon_uav="L",
        strike_angles_rad=(0.0, math.pi),
        strike_interval_s=0.0,
        assess_angles_rad=(),
        assess_delay_s=10.0,
        assess_duration_s=10.0,
        reward=10.0,
        decay_per_s=0.002,
    )
    d.update(kw)
    return Target(**d)


def _straight_track(x0: float, heading: float, t0: float, speed: float = 50.0) -> Track:
    """A UAV flying a straight leg (then loitering far away) from (x0, 0)."""
    t = np.linspace(t0, t0 + 20.0, 201)
    xy = np.column_stack([x0 + speed * (t - t0) * math.cos(heading), speed * (t - t0) * math.sin(heading)])
    end = Loiter.through(xy[-1, 0], xy[-1, 1], heading, t[-1], 300.0, speed)
    return Track([Leg(t, xy, np.full(len(t), heading), "transit")], end)


def test_delta_max_and_bid_deadline_follow_eq_20_21():
    p = CoalitionParams(delay_s=0.2, t_ta_s=0.5, margin_s=0.3)
    assert p.delta_max_s == pytest.approx(1.4)
    t_close, t_es = tender_times(10.0, p)
    assert t_es == pytest.approx(11.4)
    assert t_close == pytest.approx(10.0 + 2 * 0.2 + 0.3)  # bids close so compute + award fit before t_e^s


def test_bidder_predicted_to_leave_range_during_formation_is_excluded():
    p = CoalitionParams(link_range_m=1500.0, delay_s=0.2, t_ta_s=0.5, margin_s=0.3)
    leader = Loiter((0.0, 0.0), 1e-3, 1.0, 0.0, 0.0, 1e-6)  # effectively a fixed leader at the origin
    t0 = 5.0
    t_close, t_es = tender_times(t0, p)
    tender = Tender(1, 0, _target(), t0, t_close, t_es, leader, 20.0, 2, 0)
    # both start 1460 m away, inside range at t0; 1.4 s at 50 m/s is 70 m
    leaving = _straight_track(1460.0, 0.0, t0)  # flies away: 1530 m at t_e^s
    closing = _straight_track(1460.0, math.pi, t0)  # flies in: 1390 m at t_e^s
    assert np.hypot(*leaving.state_at(t0)[0, :2]) <= 1500.0
    bid, why = bid_for(1, leaving, 50.0, 150.0, 1, False, 20000.0, tender, t0 + 0.2, p)
    assert bid is None and "out of range" in why
    bid, why = bid_for(2, closing, 50.0, 150.0, 1, False, 20000.0, tender, t0 + 0.2, p)
    assert bid is not None, why
    # the bid carries the pose predicted at t_e^s and an ETA from there (eq. 23)
    assert bid.pose_at_tes[0] == pytest.approx(1460.0 - 50.0 * (t_es - t0), abs=0.5)
    assert bid.eta_s > t_es + (1460.0 - 70.0) / 50.0 - 1.0


def test_bidder_without_matching_capability_does_not_bid():
    p = CoalitionParams()
    leader = Loiter((0.0, 0.0), 1e-3, 1.0, 0.0, 0.0, 1e-6)
    t_close, t_es = tender_times(0.0, p)
    tender = Tender(1, 0, _target(), 0.0, t_close, t_es, leader, 20.0, 2, 0)  # strikes only
    near = _straight_track(500.0, math.pi, 0.0)
    bid, why = bid_for(1, near, 50.0, 150.0, 0, True, 20000.0, tender, 0.2, p)  # no munitions
    assert bid is None and why == "no matching capability"


def _small_world(extra_delay: dict[str, float]) -> World:
    """Leader L recons target T at the origin; four strikers loiter nearby; T needs 2 strikes."""
    uavs = [UavSpec(0, "L", 1, (-600.0, 0.0), 0.0, 300.0, 50.0, 150.0, 18000.0, 0, True, False, True)]
    for k, (x, y) in enumerate([(700.0, 300.0), (-500.0, 700.0), (300.0, -800.0), (900.0, -200.0)], start=1):
        uavs.append(
            UavSpec(k, f"S{k}", k + 1, (x, y), 1.0 * k, 300.0, 50.0, 150.0, 18000.0, 1, False, True, False)
        )
    params = CoalitionParams(t_end_s=200.0, station_radius_m=800.0)
    return World(uavs=uavs, targets=[_target()], threats=[], params=params, extra_delay_s=extra_delay)


def test_bid_arriving_after_the_deadline_is_ignored():
    on_time = simulate(_small_world({}), np.random.default_rng(0))
    bidders = {e["uav"] for e in on_time.events if e["event"] == "bid"}
    assert not [e for e in on_time.events if e["event"] == "late_bid_ignored"]
    slow = sorted(bidders)[0]
    late = simulate(_small_world({slow: 1.5}), np.random.default_rng(0))  # bid lands after t_e^s
    ignored = [e for e in late.events if e["event"] == "late_bid_ignored"]
    assert [e["uav"] for e in ignored] == [slow]
    tender = next(e for e in late.events if e["event"] == "tender")
    bid_rx_time = next(e for e in late.events if e["event"] == "bid" and e["uav"] == slow)["arrive_s"]
    assert bid_rx_time > tender["t_es_s"]
    awarded = {e["uav"] for e in late.events if e["event"] == "award"}
    assert slow not in awarded
    assert late.outcomes["T"].t_done_s is not None  # the others still formed the coalition


def test_determinism_for_a_seed():
    a = simulate(_small_world({}), np.random.default_rng(7))
    b = simulate(_small_world({}), np.random.default_rng(7))

    def strip(events):  # wall-clock compute times are the only non-deterministic fields
        return [{k: v for k, v in e.items() if k not in ("compute_s", "optimiser_s")} for e in events]

    assert strip(a.events) == strip(b.events)
    assert len(a.events) > 10


def test_conflicting_tenders_lower_reward_leader_postpones_and_retenders():
    """Leaders LA (target A, 2 strikes) and LB (target B, 2 strikes + 1 assessment) tender at the
    same time; LA receives the richer B tender while its own is open, postpones A, bids on B, and
    re-tenders A when it is released."""
    strikers = [
        (-900.0, 300.0),
        (-200.0, 900.0),
        (300.0, 900.0),
        (900.0, 400.0),
        (0.0, -1200.0),
        (-700.0, -900.0),
    ]
    uavs = [
        UavSpec(0, "LA", 1, (-400.0, -900.0), math.pi / 2, 300.0, 50.0, 150.0, 18000.0, 0, True, False, True),
        UavSpec(1, "LB", 2, (400.0, -900.0), math.pi / 2, 300.0, 50.0, 150.0, 18000.0, 0, True, False, False),
    ]
    for k, xy in enumerate(strikers, start=2):
        uavs.append(
            UavSpec(k, f"S{k}", k + 1, xy, 0.3 * k, 500.0, 60.0, 200.0, 26000.0, 2, False, True, False)
        )
    common = dict(recon_s=5.0, recon_angle_rad=-math.pi / 2, strike_angles_rad=(0.0, math.pi))
    a = _target(id="A", approx_xy=(-400.0, 0.0), xy=(-400.0, 0.0), recon_uav="LA", **common)
    b = _target(
        id="B", approx_xy=(400.0, 0.0), xy=(400.0, 0.0), recon_uav="LB", assess_angles_rad=(0.0,), **common
    )
    params = CoalitionParams(t_end_s=400.0, margin_s=2.0, station_radius_m=700.0)
    res = simulate(World(uavs=uavs, targets=[a, b], threats=[], params=params), np.random.default_rng(0))
    ev = res.events
    tenders = [e for e in ev if e["event"] == "tender"]
    assert tenders[0]["t_s"] == pytest.approx(tenders[1]["t_s"], abs=1e-6)  # simultaneous by symmetry
    postponed = [e for e in ev if e["event"] == "tender_postponed"]
    assert [(e["uav"], e["target"], e["for_target"]) for e in postponed] == [("LA", "A", "B")]
    # LA stays locked to B until B's formation fails (or its B task ends), then re-tenders A at once
    b_fail = next(e["t_s"] for e in ev if e["event"] == "formation_failed" and e["target"] == "B")
    retender_a = [e for e in tenders if e["target"] == "A" and e["t_s"] > tenders[0]["t_s"]]
    assert retender_a and retender_a[0]["t_s"] == pytest.approx(b_fail)
    assert not [e for e in ev if e["event"] == "formed" and e["target"] == "A" and e["t_s"] < b_fail]
    assert res.outcomes["A"].t_done_s is not None and res.outcomes["B"].t_done_s is not None


def test_bus_one_hop_adjacency_and_link_break_in_flight():
    from gcs_planner.planning.coalition.bus import MessageBus

    def positions(t):  # UAV 2 flies away from UAV 0 at 100 m/s starting 1450 m out
        return np.array([[0.0, 0.0], [1000.0, 0.0], [1450.0 + 100.0 * t, 0.0]])

    bus = MessageBus(positions, lambda i, t: positions(t)[i], 1500.0, 0.2, np.random.default_rng(0))
    adj = bus.adjacency(0.0)
    assert adj.tolist() == [[False, True, True], [True, False, True], [True, True, False]]
    assert bus.adjacency(1.0)[0, 2] == False  # noqa: E712 - time-varying: 1550 m at t = 1 s
    assert list(bus.neighbours(0, 0.0)) == [1, 2]
    assert bus.arrival_s(0, 1, 0.0) == pytest.approx(0.2)
    assert bus.arrival_s(0, 2, 0.0) == pytest.approx(0.2)  # 1470 m on arrival: delivered
    assert bus.arrival_s(0, 2, 0.4) is None  # in range when sent (1490 m), out on arrival (1510 m)
