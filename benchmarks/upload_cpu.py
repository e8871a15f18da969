"""Upload CPU per item and transfer time: our MissionClient vs MAVSDK's MissionRaw, in one run.

One mock vehicle (sitl_mock, in a child process with its own GIL) listens on 127.0.0.1; each client
uploads missions of every size to it over UDP loopback. Per upload it records:
  wall      from the upload call to its return (MISSION_COUNT .. MISSION_ACK);
  cpu       CPU time (user + system, every thread) of the client: this process, where MAVSDK's C++
            library runs its own threads, plus any child process that is not the mock (none today:
            MAVSDK 4 is a library, not a mavsdk_server process);
  vehicle   CPU time of the mock's (or the SITL's) process, the other half of every round trip.
Against the mock the table adds ``vehicle / MAVSDK wall``: the mock's CPU over MAVSDK's transfer
time. The mock serves in one thread, so a transfer lasts at least the mock's CPU (and, where the
two take turns on one core, the client's as well): where that column is over 0.5 at the lowest of
the two clients, no client, however lean, is 0.5x MAVSDK's time against this vehicle.
Placement (``--placement``): ``shared`` leaves the mock and the client where the scheduler puts
them; on this 2-core VM its wake-affine placement runs a ping-pong of two processes on one core, so
the two take turns and the transfer lasts about both CPU times added. ``apart`` pins the mock's
process to the last CPU and the client to the others, as a vehicle is a computer of its own: then
each side can work while the other does, and every round trip crosses cores, as on any real link.
Both are measured in the same run, for both clients.
Ours runs with ``Timing(verdict_s=0)``: the transfer only, without the second a PX4 vehicle is
listened to after its ACK for a refusal (verdict.py), which MAVSDK does not do and which costs no
CPU; ``--window`` and ``--batch`` set its Timing.window and .batch (default: the client's). Each
round gives each client a fresh mock and rotates the client order, so drifting machine load hits
both alike; medians over rounds x reps uploads. The markdown goes to stdout (and --out).
``--sitl PORT PID``: a real autopilot (SITL) instead of the mock, started by hand to send to
127.0.0.1:PORT; each client in turn listens there, and "vehicle CPU" is that process's.

    .venv/bin/python benchmarks/upload_cpu.py [--sizes 100 500] [--rounds 3] [--reps 5] [--window N]
        [--batch N] [--placement shared apart] [--sitl PORT PID] [--out FILE]
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import datetime
import functools
import os
import platform
import statistics
import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from upload_latency import Mock, items  # noqa: E402

from gcs_planner.mavlink.link import MavlinkLink  # noqa: E402
from gcs_planner.mavlink.mission import MissionClient  # noqa: E402
from gcs_planner.mavlink.transfer import Timing  # noqa: E402

TIMING = Timing(verdict_s=0)  # ours: the transfer only (docstring)
Sample = tuple[float, float, float]  # wall, client cpu, mock cpu [s]


def cpu_s(pid: int) -> float:
    """On-CPU seconds of every thread of process ``pid`` (/proc schedstat: nanoseconds, not ticks)."""
    total = 0
    for task in Path(f"/proc/{pid}/task").iterdir():
        with contextlib.suppress(FileNotFoundError):
            total += int((task / "schedstat").read_text().split()[0])
    return total * 1e-9


def children(pid: int) -> list[int]:
    """Process ids of ``pid``'s children and their descendants."""
    out = []
    for task in Path(f"/proc/{pid}/task").iterdir():
        with contextlib.suppress(FileNotFoundError):
            out += [int(c) for c in (task / "children").read_text().split()]
    return [d for c in out for d in (c, *children(c))]


class CpuMeter:
    """CPU seconds used so far by the client (this process and any child but the mock: a
    mavsdk_server would be one) and by the mock's process."""

    def __init__(self, mock_pid: int) -> None:
        self.mock_pid = mock_pid

    def read(self) -> tuple[float, float]:
        client = cpu_s(os.getpid())
        for pid in children(os.getpid()):
            if pid != self.mock_pid:
                with contextlib.suppress(FileNotFoundError):
                    client += cpu_s(pid)
        return client, cpu_s(self.mock_pid)


def measured(meter: CpuMeter, upload: Callable[[], object]) -> Sample:
    c0, m0 = meter.read()
    t0 = time.perf_counter()
    upload()
    wall = time.perf_counter() - t0
    c1, m1 = meter.read()
    return wall, c1 - c0, m1 - m0


async def measured_async(meter: CpuMeter, upload) -> Sample:
    c0, m0 = meter.read()
    t0 = time.perf_counter()
    await upload
    wall = time.perf_counter() - t0
    c1, m1 = meter.read()
    return wall, c1 - c0, m1 - m0


def ours(
    url: str, meter: CpuMeter, sizes: list[int], reps: int, timing: Timing = TIMING
) -> dict[int, list[Sample]]:
    async def main() -> dict[int, list[Sample]]:
        link = await MavlinkLink.open(url)
        await link.wait_for(lambda m: m.get_type() == "HEARTBEAT", 30)
        client = MissionClient(link, 1, timing=timing)
        await client.upload(items(10, 99))  # warm-up: first-call costs (caches, imports)
        out = {}
        for n in sizes:
            runs = []
            for r in range(reps):
                mission = items(n, r)
                runs.append(await measured_async(meter, client.upload(mission)))
                await asyncio.sleep(0.05)  # let the mock's reply flush settle before the next
            out[n] = runs
        await link.close()
        return out

    return asyncio.run(main())


def mavsdk(url: str, meter: CpuMeter, sizes: list[int], reps: int) -> dict[int, list[Sample]]:
    from mavsdk import Configuration, Mavsdk, log_subscribe
    from mavsdk.plugins.mission_raw import MissionItem as RawItem
    from mavsdk.plugins.mission_raw import MissionRaw

    log_subscribe(lambda *args: True)
    sdk = Mavsdk(Configuration.create_manual(253, 190, True))
    sdk.add_any_connection(url.replace(":", "://", 1))
    raw = MissionRaw(sdk.first_autopilot(10.0))

    def mission(n: int, r: int) -> list:
        fields = ("seq", "frame", "command", "current", "autocontinue", "param1", "param2", "param3")
        fields += ("param4", "x", "y", "z")
        return [RawItem(*(getattr(i, f) for f in fields), 0) for i in items(n, r)]

    raw.upload_mission(mission(10, 99))  # warm-up, as for ours
    out = {}
    for n in sizes:
        runs = []
        for r in range(reps):
            m = mission(n, r)
            runs.append(measured(meter, lambda m=m: raw.upload_mission(m)))
            time.sleep(0.05)
        out[n] = runs
    sdk.destroy()
    return out


CLIENTS = {"ours": ours, "mavsdk": mavsdk}
PLACEMENTS = ("shared", "apart")


def place(placement: str, mock_pid: int) -> None:
    """``apart``: every thread of the mock on the last CPU, this process (and the threads it starts
    from now on, MAVSDK's included) on the others; ``shared``: every CPU for both."""
    cpus = set(range(os.cpu_count() or 1))
    mock, client = ({max(cpus)}, cpus - {max(cpus)}) if placement == "apart" else (cpus, cpus)
    for tid in os.listdir(f"/proc/{mock_pid}/task"):
        os.sched_setaffinity(int(tid), mock)
    os.sched_setaffinity(0, client)


Samples = dict[tuple[str, str], dict[int, list[Sample]]]  # (placement, client) -> size -> runs


def run(
    sizes: list[int],
    rounds: int,
    reps: int,
    profile: str,
    placements: list[str],
    timing: Timing = TIMING,
    sitl: tuple[int, int] | None = None,
) -> Samples:
    """Every client, placement and size; ``sitl`` = (UDP port, pid) of a real vehicle that sends to
    that port (ArduPilot ``--serial0 udpclient:127.0.0.1:PORT``, PX4's GCS port) instead of a mock."""
    clients = {**CLIENTS, "ours": functools.partial(ours, timing=timing)}
    samples: Samples = {(p, c): {n: [] for n in sizes} for p in placements for c in CLIENTS}
    for r in range(rounds):
        names = list(CLIENTS)[r % 2 :] + list(CLIENTS)[: r % 2]
        for placement in placements:
            for name in names:
                with vehicle(profile, sitl) as (url, pid):
                    place(placement, pid)
                    for n, runs in clients[name](url, CpuMeter(pid), sizes, reps).items():
                        samples[placement, name][n] += runs
                place("shared", os.getpid())  # this process back on every CPU
    return samples


@contextlib.contextmanager
def vehicle(profile: str, sitl: tuple[int, int] | None) -> Iterator[tuple[str, int]]:
    """(url, pid): a fresh mock for each client, or the real vehicle, whose port each client binds."""
    if sitl is not None:
        yield f"udpin:127.0.0.1:{sitl[0]}", sitl[1]
        return
    with Mock(1, profile) as mock:
        host, port = mock.addresses[0]
        yield f"udpout:{host}:{port}", mock._proc.pid


def table(samples: Samples, floor: bool) -> str:
    """The markdown table; ``floor``: add the mock's CPU over MAVSDK's wall (the module docstring)."""
    med = statistics.median
    rows = [
        "| items | placement | client | wall ms | wall / MAVSDK | client CPU us/item | CPU / MAVSDK"
        " | vehicle CPU us/item |" + (" vehicle / MAVSDK wall |" if floor else ""),
        "|---:|---|---|---:|---:|---:|---:|---:|" + ("---:|" if floor else ""),
    ]
    for placement, name in samples:
        if name != "mavsdk":
            continue
        for n, ref in samples[placement, "mavsdk"].items():
            ref_wall, ref_cpu = med(w for w, _, _ in ref), med(c for _, c, _ in ref)
            for client in CLIENTS:
                runs = samples[placement, client][n]
                wall, cpu, mock = (med(x[k] for x in runs) for k in range(3))
                rows.append(
                    f"| {n} | {placement} | {client} | {1e3 * wall:.1f} | {wall / ref_wall:.2f}"
                    f" | {1e6 * cpu / n:.1f} | {cpu / ref_cpu:.2f} | {1e6 * mock / n:.1f} |"
                    + (f" {mock / ref_wall:.2f} |" if floor else "")
                )
    return "\n".join(rows)


def uptime() -> str:
    return subprocess.run(["uptime"], capture_output=True, text=True).stdout.strip()


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--sizes", type=int, nargs="+", default=[100, 500])
    p.add_argument("--rounds", type=int, default=3)
    p.add_argument("--reps", type=int, default=5)
    p.add_argument("--profile", choices=("px4", "ardupilot"), default="px4")
    p.add_argument("--window", type=int, default=Timing.window, help="our items in flight (Timing.window)")
    p.add_argument("--batch", type=int, default=Timing.batch, help="our items per datagram (Timing.batch)")
    p.add_argument("--placement", nargs="+", choices=PLACEMENTS, default=list(PLACEMENTS))
    p.add_argument(
        "--sitl",
        nargs=2,
        type=int,
        metavar=("PORT", "PID"),
        help="a real vehicle sending to 127.0.0.1:PORT (process PID) instead of the mock",
    )
    p.add_argument("--out", type=Path, help="also write the markdown here")
    args = p.parse_args()
    before = uptime()
    timing = Timing(verdict_s=0, window=args.window, batch=args.batch)
    samples = run(args.sizes, args.rounds, args.reps, args.profile, args.placement, timing, args.sitl)
    text = "\n".join(
        [
            f"Machine: {platform.machine()}, {os.cpu_count()} CPUs, Python {platform.python_version()}."
            f" Date: {datetime.datetime.now(datetime.UTC):%Y-%m-%d %H:%M} UTC.",
            f"Load (`uptime`) before: {before}",
            f"Load (`uptime`) after: {uptime()}",
            f"Command: `{' '.join([Path(sys.executable).name, *sys.argv])}`"
            f" ({'real vehicle' if args.sitl else f'profile {args.profile}'},"
            f" our window {args.window} in datagrams of {args.batch},"
            f" placements {' and '.join(args.placement)},"
            f" medians of {args.rounds} rounds x {args.reps} uploads)",
            "",
            table(samples, floor=args.sitl is None),
            "",
        ]
    )
    print(text)
    if args.out:
        args.out.write_text(text)


if __name__ == "__main__":
    main()
