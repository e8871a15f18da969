"""Mission upload latency: our MissionClient vs a plain pymavlink loop vs MAVSDK's MissionRaw client.

The mock fleet runs in a child process (its own interpreter and GIL), so every client sees the
same vehicle. Sections (all on 127.0.0.1):
  loopback  10/100/1000 items, each client, median wall time and client CPU time (all threads of the
            client process; MAVSDK's C++ threads included); ratio to MAVSDK. ``ours`` is the default
            client (Timing's items in flight), ``ours_w1`` the one-item-per-request client.
  delay     20 ms one-way (40 ms RTT) link: time / (items x RTT), target <= 1.2, both windows.
  loss      10 % loss each way (+ 20 ms delay): success over --loss-uploads uploads, slowdown vs no loss.
  fleet     100 vehicles at once (upload_fleet, workers=100 and the default 8) vs one vehicle.

    nice .venv/bin/python benchmarks/upload_latency.py [--profile px4|ardupilot] [--quick]
"""

from __future__ import annotations

import argparse
import asyncio
import functools
import math
import os
import statistics
import sys
import time
from pathlib import Path

os.environ.setdefault("MAVLINK20", "1")
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from pymavlink import mavutil  # noqa: E402

from gcs_planner.mavlink.fleet import upload_fleet  # noqa: E402
from gcs_planner.mavlink.link import MavlinkLink  # noqa: E402
from gcs_planner.mavlink.mission import MissionClient  # noqa: E402
from gcs_planner.mavlink.transfer import Timing  # noqa: E402
from gcs_planner.wire.types import MissionItem  # noqa: E402
from sitl_mock.faults import LinkFaults  # noqa: E402
from sitl_mock.process import MockFleetProcess  # noqa: E402

CAPACITY = 5000


def items(n: int, shift: int = 0) -> list[MissionItem]:
    return [
        MissionItem(
            seq=i,
            frame=3,
            command=16,
            current=int(i == 0),
            x=473_977_000 + 41 * i + shift,
            y=85_455_000 + 13 * i,
            z=round(20.0 + 0.5 * (i % 40), 2),
        )
        for i in range(n)
    ]


# ----------------------------------------------------------------------------- mock in a child process
def Mock(count: int = 1, profile: str = "px4", **faults: float) -> MockFleetProcess:  # noqa: N802
    """A MockFleet of ``count`` vehicles in a child process (its own GIL), so every client sees the
    same vehicle; use as a context manager, then ``.addresses``."""
    vehicles = [{"sysid": s, "capacity": CAPACITY} for s in range(1, count + 1)]
    return MockFleetProcess(vehicles=vehicles, profile=profile, faults=LinkFaults(**faults), rate_hz=2.0)


# ----------------------------------------------------------------------------- the three clients
async def _connect(addresses) -> MavlinkLink:
    link = await MavlinkLink.open(*(f"udpout:{h}:{p}" for h, p in addresses))
    want, seen = len(addresses), set()
    await link.wait_for(
        lambda m: m.get_type() == "HEARTBEAT" and (seen.add(m.get_srcSystem()) or len(seen) >= want), 30
    )
    return link


def ours(address, sizes: list[int], reps: int, window: int = Timing.window) -> dict[int, list[float]]:
    async def main():
        link = await _connect([address])
        client = MissionClient(link, 1, timing=Timing(window=window, verdict_s=0))  # the transfer only
        out = {}
        for n in sizes:
            times = []
            for r in range(reps):
                mission = items(n, r)
                t0, c0 = time.perf_counter(), time.process_time()
                await client.upload(mission)
                times.append((time.perf_counter() - t0, time.process_time() - c0))
            out[n] = times
        await link.close()
        return out

    return asyncio.run(main())


def pymavlink_loop(address, sizes: list[int], reps: int) -> dict[int, list[float]]:
    """The loop most scripts write: COUNT, answer each request, stop at MISSION_ACK (no retries)."""
    conn = mavutil.mavlink_connection(
        f"udpout:{address[0]}:{address[1]}", source_system=254, source_component=190
    )
    conn.mav.heartbeat_send(6, 8, 0, 0, 4)
    conn.wait_heartbeat(timeout=10)
    out = {}
    for n in sizes:
        times = []
        for r in range(reps):
            mission = items(n, r)
            t0, c0 = time.perf_counter(), time.process_time()
            conn.mav.mission_count_send(1, 1, n, 0)
            while True:
                m = conn.recv_match(
                    type=["MISSION_REQUEST", "MISSION_REQUEST_INT", "MISSION_ACK"], blocking=True, timeout=10
                )
                if m is None or m.get_type() == "MISSION_ACK":
                    break
                it = mission[m.seq]
                conn.mav.mission_item_int_send(1, 1, *it.fields())
            if m is None or m.type != 0:
                raise RuntimeError(f"pymavlink loop upload of {n} items failed: {m}")
            times.append((time.perf_counter() - t0, time.process_time() - c0))
        out[n] = times
    conn.close()
    return out


def mavsdk_client(address, sizes: list[int], reps: int) -> dict[int, list[float]] | None:
    try:
        from mavsdk import Configuration, Mavsdk, log_subscribe
        from mavsdk.plugins.mission_raw import MissionItem as RawItem
        from mavsdk.plugins.mission_raw import MissionRaw
    except ImportError:
        return None
    log_subscribe(lambda *args: True)
    sdk = Mavsdk(Configuration.create_manual(253, 190, True))
    sdk.add_any_connection(f"udpout://{address[0]}:{address[1]}")
    raw = MissionRaw(sdk.first_autopilot(10.0))
    out = {}
    for n in sizes:
        times = []
        for r in range(reps):
            mission = [
                RawItem(
                    i.seq,
                    i.frame,
                    i.command,
                    i.current,
                    i.autocontinue,
                    i.param1,
                    i.param2,
                    i.param3,
                    i.param4,
                    i.x,
                    i.y,
                    i.z,
                    0,
                )
                for i in items(n, r)
            ]
            t0, c0 = time.perf_counter(), time.process_time()
            raw.upload_mission(mission)
            times.append((time.perf_counter() - t0, time.process_time() - c0))
        out[n] = times
    sdk.destroy()
    return out


# ----------------------------------------------------------------------------- sections
def med(values: list[float]) -> float:
    return statistics.median(values)


def loopback(profile: str, sizes: list[int], reps: int, rounds: int = 3) -> None:
    """Each client gets a fresh mock (one peer, nothing stale) per round; client order rotates per round,
    so drifting machine load hits all three alike. Medians over rounds x reps uploads."""
    print(f"\n## loopback, profile {profile}: median upload time [ms] over {rounds} x {reps} uploads")
    clients = {
        "ours": ours,
        "ours_w1": functools.partial(ours, window=1),
        "pymavlink": pymavlink_loop,
        "mavsdk": mavsdk_client,
    }
    samples: dict[str, dict[int, list[tuple[float, float]]]] = {
        name: {n: [] for n in sizes} for name in clients
    }
    for r in range(rounds):
        names = list(clients)[r % len(clients) :] + list(clients)[: r % len(clients)]
        for name in names:
            with Mock(1, profile) as mock:
                got = clients[name](mock.addresses[0], sizes, reps)
            if got is None:
                samples.pop(name, None)
                continue
            for n in sizes:
                samples[name][n] += got[n]
    print(f"{'items':>6} {'client':>10} {'wall_ms':>9} {'client_cpu_ms':>14} {'wall/mavsdk':>12}")
    for n in sizes:
        sdk_wall = med([w for w, _ in samples["mavsdk"][n]]) if "mavsdk" in samples else math.nan
        for name, runs in samples.items():
            wall, cpu = med([w for w, _ in runs[n]]), med([c for _, c in runs[n]])
            print(f"{n:>6} {name:>10} {1e3 * wall:>9.1f} {1e3 * cpu:>14.1f} {wall / sdk_wall:>12.2f}")


def delayed(profile: str, n: int, reps: int) -> None:
    rtt = 0.04
    print(f"\n## 20 ms one-way delay, profile {profile}, {n} items: time / (items x RTT), target <= 1.2")
    print(f"{'items':>6} {'window':>7} {'time_s':>8} {'ratio':>6}")
    for window in (Timing.window, 1):
        with Mock(1, profile, delay_s=0.02) as mock:
            t = med([w for w, _ in ours(mock.addresses[0], [n], reps, window)[n]])
        print(f"{n:>6} {window:>7} {t:>8.3f} {t / (n * rtt):>6.2f}")


def lossy(profile: str, n: int, uploads: int) -> None:
    print(f"\n## 10 % loss each way + 20 ms delay, profile {profile}, {n} items, {uploads} uploads")

    async def run(addresses, count):
        link = await _connect(addresses)
        client = MissionClient(link, 1)
        ok, times, lost_ack = 0, [], 0
        for r in range(count):
            t0 = time.perf_counter()
            try:
                res = await client.upload(items(n, r))
            except Exception as exc:  # noqa: BLE001 - counted as a failure and shown
                print(f"  upload {r} failed: {exc}")
                continue
            ok += 1
            lost_ack += res.ack_lost
            times.append(time.perf_counter() - t0)
        await link.close()
        return ok, times, lost_ack

    with Mock(1, profile, delay_s=0.02) as mock:
        _, base, _ = asyncio.run(run(mock.addresses, 5))
    with Mock(1, profile, delay_s=0.02, loss=0.1, seed=3) as mock:
        ok, times, lost_ack = asyncio.run(run(mock.addresses, uploads))
    print(
        f"{'success':>8} {'rate_%':>7} {'base_s':>7} {'lossy_median_s':>15} {'slowdown':>9} {'ack_lost':>9}"
    )
    print(
        f"{ok:>4}/{uploads:<3} {100 * ok / uploads:>7.1f} {med(base):>7.3f} {med(times):>15.3f} "
        f"{med(times) / med(base):>9.2f} {lost_ack:>9}"
    )


def fleet(profile: str, count: int, n: int, delay_s: float) -> None:
    print(f"\n## {count} vehicles vs one, profile {profile}, {n} items, delay {delay_s * 1e3:.0f} ms")

    async def run(addresses, workers):
        link = await _connect(addresses)
        missions = {s: items(n, s) for s in range(1, len(addresses) + 1)}
        t0, c0 = time.perf_counter(), time.process_time()
        results = await upload_fleet(link, missions, workers=workers)
        elapsed, cpu = time.perf_counter() - t0, time.process_time() - c0
        await link.close()
        return elapsed, cpu, sum(r.ok for r in results.values())

    with Mock(count, profile, delay_s=delay_s) as mock:
        one, _, _ = asyncio.run(run(mock.addresses[:1], 1))
        rows = [(w, *asyncio.run(run(mock.addresses, w))) for w in (count, 8)]
    print(f"{'workers':>8} {'ok':>5} {'time_s':>8} {'client_cpu_s':>13} {'one_vehicle_s':>14} {'ratio':>6}")
    for workers, elapsed, cpu, ok in rows:
        print(f"{workers:>8} {ok:>5} {elapsed:>8.3f} {cpu:>13.3f} {one:>14.3f} {elapsed / one:>6.2f}")


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--profile", choices=("px4", "ardupilot"), default="px4")
    p.add_argument("--reps", type=int, default=5)
    p.add_argument("--loss-uploads", type=int, default=50)
    p.add_argument("--sections", default="loopback,delay,loss,fleet")
    p.add_argument("--quick", action="store_true", help="small sizes (smoke run)")
    args = p.parse_args()
    sections = args.sections.split(",")
    sizes = [10, 100] if args.quick else [10, 100, 1000]
    print(
        f"# upload_latency: {os.cpu_count()} CPUs, load average {os.getloadavg()[0]:.1f},"
        f" python {sys.version.split()[0]}"
    )
    if "loopback" in sections:
        loopback(args.profile, sizes, args.reps)
    if "delay" in sections:
        delayed(args.profile, 20 if args.quick else 100, 3)
    if "loss" in sections:
        lossy(args.profile, 20, 5 if args.quick else args.loss_uploads)
    if "fleet" in sections:
        for delay_s in (0.0, 0.02):
            fleet(args.profile, 10 if args.quick else 100, 20, delay_s)


if __name__ == "__main__":
    main()
