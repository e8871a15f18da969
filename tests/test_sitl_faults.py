"""Link fault injection: the channel's statistics, then measured over real UDP against the mock."""

import asyncio
import time

import numpy as np
import pytest

from sitl_mock import LinkFaults, MockFleet
from sitl_mock.faults import REORDER_HOLD_S, FaultyChannel
from sitl_mock.probe import Probe

UNGATED = {"arm_ready_s": 0.0, "streams_by_request": False}  # rules these tests are not about


def _run_channel(
    faults: LinkFaults, n: int, spacing_s: float = 0.0
) -> tuple[list[tuple[int, float]], list[float]]:
    """Push datagrams 0..n-1 through a channel; (index, arrival time [s]) in arrival order, send times."""
    out: list[tuple[int, float]] = []
    sent: list[float] = []

    async def main() -> None:
        loop = asyncio.get_running_loop()
        t0 = loop.time()
        ch = FaultyChannel(lambda data, addr: out.append((int(data), loop.time() - t0)), faults, (7, 0))
        for k in range(n):
            sent.append(loop.time() - t0)
            ch.send(str(k).encode(), ("127.0.0.1", 1))
            if spacing_s:
                await asyncio.sleep(spacing_s)
        await asyncio.sleep(faults.delay_s + faults.jitter_s + REORDER_HOLD_S + 0.05)

    asyncio.run(main())
    return out, sent


def test_loss_rate_matches_and_is_seeded():
    out, _ = _run_channel(LinkFaults(loss=0.3, seed=4), 4000)
    assert 0.27 < 1 - len(out) / 4000 < 0.33
    assert [k for k, _ in out] == sorted(k for k, _ in out)  # loss alone never reorders
    again, _ = _run_channel(LinkFaults(loss=0.3, seed=4), 4000)
    other, _ = _run_channel(LinkFaults(loss=0.3, seed=5), 4000)
    assert [k for k, _ in again] == [k for k, _ in out]
    assert [k for k, _ in other] != [k for k, _ in out]


def test_duplication_and_reordering():
    out, _ = _run_channel(LinkFaults(duplicate=0.2, seed=1), 2000)
    keys = [k for k, _ in out]
    assert 0.17 < len(keys) / 2000 - 1 < 0.23 and set(keys) == set(range(2000))
    out, _ = _run_channel(LinkFaults(reorder=0.2, seed=1), 2000)
    keys = [k for k, _ in out]
    assert sorted(keys) == list(range(2000))  # nothing lost
    swaps = sum(1 for a, b in zip(keys, keys[1:], strict=False) if b < a)
    assert 0.15 * 2000 < swaps < 0.25 * 2000


def test_delay_and_jitter_bounds():
    out, sent = _run_channel(LinkFaults(delay_s=0.05, jitter_s=0.02, seed=3), 50, spacing_s=0.002)
    assert len(out) == 50
    lateness = np.array([t - sent[k] for k, t in out])
    assert lateness.min() >= 0.05 - 0.002  # never early (loop clock resolution)
    assert np.median(lateness) <= 0.05 + 0.02 + 0.01  # within delay + jitter, loop slack aside
    assert lateness.max() - lateness.min() > 0.005  # jitter spreads them


def test_bad_fault_values_name_the_field():
    with pytest.raises(ValueError, match="loss"):
        LinkFaults(loss=1.5)
    with pytest.raises(ValueError, match="delay_s"):
        LinkFaults(delay_s=float("nan"))


def _seqs(probe: Probe, seconds: float) -> list[int]:
    """MAVLink sequence numbers of what arrives in ``seconds`` (after dropping anything buffered)."""
    probe.collect(0.05)
    time.sleep(seconds)
    return [m.get_seq() for m in probe.collect(0.1)]


def _both(a: Probe, b: Probe, seconds: float) -> tuple[int, int]:
    """Messages received by two probes over the same ``seconds`` window."""
    a.collect(0.05)
    b.collect(0.05)
    time.sleep(seconds)
    return len(a.collect(0.1)), len(b.collect(0.1))


def test_faults_measured_over_udp():
    """Same fleet, vehicle 1 clean, vehicle 2 lossy then duplicating then reordering (set at run time),
    each frame a datagram of its own so that every fault acts on single frames."""
    with MockFleet(flight=UNGATED, count=2, rate_hz=50.0, batch_frames=False) as fleet:
        clean, faulty = Probe(fleet.addresses[0]), Probe(fleet.addresses[1])
        time.sleep(0.1)
        fleet.set_faults(2, LinkFaults(loss=0.5, seed=2))
        n_clean, n_lossy = _both(clean, faulty, 1.0)
        assert n_clean > 40 and 0.3 * n_clean < n_lossy < 0.7 * n_clean

        fleet.set_faults(2, LinkFaults(duplicate=1.0))
        seqs = _seqs(faulty, 0.6)
        while len(seqs) > 1 and seqs[0] != seqs[1]:
            seqs.pop(0)  # frames sent before the switch (still in the socket) come once
        assert len(seqs) > 20 and all(a == b for a, b in zip(seqs[::2], seqs[1::2], strict=False))

        fleet.set_faults(2, LinkFaults(reorder=0.3, seed=9))
        seqs = _seqs(faulty, 1.0)
        backwards = sum(1 for a, b in zip(seqs, seqs[1:], strict=False) if (b - a) % 256 > 128)
        assert backwards >= 5
        clean_seqs = _seqs(clean, 0.3)
        assert all((b - a) % 256 == 1 for a, b in zip(clean_seqs, clean_seqs[1:], strict=False))
        clean.close()
        faulty.close()


def test_scripted_drift_moves_the_reported_track():
    with MockFleet(flight=UNGATED, count=2, speedup=20.0) as fleet:
        fleet.at(1.0, lambda f: f.set_drift(2, 1.0, 0.0))
        for sysid in (1, 2):
            v = fleet.vehicle(sysid)
            fleet.call(lambda v=v: (v._cmd_arm(1.0, 0.0), v._cmd_takeoff(0, 0, 0, 0, 0, 0, 20.0)))
        assert fleet.wait_until(lambda f: f.sim_time_s > 20.0, timeout_s=10.0)
        pos = fleet.positions_enu()
        fleet.set_speedup(1.0)
        t0, w0 = fleet.sim_time_s, time.monotonic()
        time.sleep(0.5)
        rate = (fleet.sim_time_s - t0) / (time.monotonic() - w0)
    assert 0.5 < rate < 1.5  # was 20 s of simulated time per second
    assert np.hypot(*pos[0, :2]) < 0.01  # vehicle 1 hovers where it took off
    assert pos[1, 0] > 10.0  # vehicle 2's report walked east at ~1 m/s once airborne
