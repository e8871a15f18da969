"""CPU a receiver pays per UDP datagram when each datagram wakes it: the floor under the upload's CPU.

A vehicle that sends every MISSION_REQUEST in a datagram of its own (PX4, the mock's PX4 profile)
wakes the client once per item; this measures what one wake-up costs before any MAVLink work.
A sender process on the last CPU sends N MISSION_REQUEST_INT frames, one per datagram, --gap-us
apart (PX4 SITL asks for an item every ~120-130 us); the receiver, on the other CPUs, is one of:
  blocking   a blocking ``recvfrom`` loop: the kernel's wake-up and copy, nothing else;
  asyncio    asyncio's DatagramTransport with a protocol that does nothing;
  link       our UdpProtocol (framing.frames, the address key) handing frames to a no-op.
Receiver CPU (this process, every thread) per datagram, median of --rounds. The receiver imports
the upload client first, so its allocator is in the state the client's is. Add the upload's hot
path per item (upload_hot_path.py) to the ``link`` row for the client's CPU per item against PX4.

    .venv/bin/python benchmarks/udp_wakeup.py [--count 5000] [--gap-us 120] [--rounds 3]
"""

from __future__ import annotations

import argparse
import asyncio
import multiprocessing
import os
import socket
import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from pymavlink.dialects.v20 import ardupilotmega as mavlink  # noqa: E402
from results_md import machine_line  # noqa: E402

import gcs_planner.mavlink.mission  # noqa: E402, F401  (the client's imports: its allocator state)
from gcs_planner.mavlink.transports import UdpProtocol  # noqa: E402
from gcs_planner.wire import codec  # noqa: E402

END = b"end"


def request_frame() -> bytes:
    mav = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    msg = mavlink.MAVLink_mission_request_int_message(255, 190, 7, 0)
    return codec.encode(msg, mav) or msg.pack(mav)


def sender(port: int, count: int, gap_s: float) -> None:
    """Send ``count`` request frames to 127.0.0.1:port, ``gap_s`` apart (a busy wait: sub-ms gaps)."""
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    frame = request_frame()
    time.sleep(0.2)  # the receiver is waiting by now
    due = time.perf_counter()
    for _ in range(count):
        sock.sendto(frame, ("127.0.0.1", port))
        due += gap_s
        while time.perf_counter() < due:
            pass
    sock.sendto(END, ("127.0.0.1", port))


def receive_blocking(sock: socket.socket) -> int:
    n = 0
    while sock.recvfrom(65536)[0] != END:
        n += 1
    return n


async def receive_asyncio(sock: socket.socket, ours: bool) -> int:
    loop = asyncio.get_running_loop()
    done: asyncio.Future[None] = loop.create_future()
    count = [0]

    def on_frames(found, junk, key, transport, address) -> None:
        count[0] += 1

    class Plain(asyncio.DatagramProtocol):
        def datagram_received(self, data: bytes, addr) -> None:
            if data == END:
                done.set_result(None)
            else:
                count[0] += 1

    class Ours(UdpProtocol):
        def datagram_received(self, data: bytes, addr) -> None:
            if data == END:
                done.set_result(None)
            else:
                super().datagram_received(data, addr)

    protocol = (lambda: Ours(on_frames)) if ours else Plain
    transport, _ = await loop.create_datagram_endpoint(protocol, sock=sock)
    await done
    transport.close()
    return count[0]


RECEIVERS = {
    "blocking": receive_blocking,
    "asyncio": lambda sock: asyncio.run(receive_asyncio(sock, ours=False)),
    "link": lambda sock: asyncio.run(receive_asyncio(sock, ours=True)),
}


def one_round(receiver: str, count: int, gap_s: float) -> float:
    """Receiver CPU seconds per datagram for one run of ``count`` datagrams."""
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind(("127.0.0.1", 0))
    cpus = set(range(os.cpu_count() or 1))
    proc = multiprocessing.get_context("spawn").Process(
        target=sender, args=(sock.getsockname()[1], count, gap_s)
    )
    proc.start()
    os.sched_setaffinity(proc.pid, {max(cpus)})
    os.sched_setaffinity(0, (cpus - {max(cpus)}) or cpus)
    try:
        c0 = time.process_time()
        n = RECEIVERS[receiver](sock)
        cpu = time.process_time() - c0
    finally:
        proc.join()
        os.sched_setaffinity(0, cpus)
        sock.close()
    if n != count:
        raise SystemExit(f"{receiver}: received {n} of {count} datagrams (loopback dropped some)")
    return cpu / n


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--count", type=int, default=5000)
    p.add_argument("--gap-us", type=float, default=120.0)
    p.add_argument("--rounds", type=int, default=3)
    args = p.parse_args()
    per = {name: [] for name in RECEIVERS}
    for _ in range(args.rounds):  # interleaved: drifting load hits every receiver alike
        for name in RECEIVERS:
            per[name].append(one_round(name, args.count, args.gap_us * 1e-6))
    floor = statistics.median(per["blocking"])
    print(
        f"Machine: {machine_line()}; {args.count} datagrams {args.gap_us:g} us apart,"
        f" medians of {args.rounds} rounds\n"
    )
    print("| receiver | CPU us per datagram | / blocking |\n|---|---:|---:|")
    for name, runs in per.items():
        cpu = statistics.median(runs)
        print(f"| {name} | {1e6 * cpu:.1f} | {cpu / floor:.2f} |")


if __name__ == "__main__":
    main()
