"""Upload time against items in flight (Timing.window) on lossy and slow links, in fake time.

The client's UploadTransfer against the mock's MissionServer (ArduPilot's and PX4's rules: the item
whose seq the vehicle waits for is stored, others refused or dropped), through the fake-time channel
of tests/test_mission_transfer.py (one-way delay, loss each way, each frame on its own). Per window,
loss and delay: the median transfer time over the seeds (fake seconds, from MISSION_COUNT to the
outcome) and how many uploads did not end ACCEPTED (errors, lost final ACKs included). No wall
clock: the figures are the protocol's, the same on any machine.

    .venv/bin/python benchmarks/upload_window.py [--items 100] [--seeds 20] [--windows 1 2 8 16]
"""

from __future__ import annotations

import argparse
import statistics
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from test_mission_transfer import Channel, Sim, mission, server, upload  # noqa: E402

from gcs_planner.mavlink.transfer import Timing  # noqa: E402

LINKS = [(0.0, 0.002), (0.0, 0.05), (0.05, 0.002), (0.05, 0.05), (0.2, 0.002), (0.2, 0.05)]


def one(profile: str, window: int, loss: float, delay_s: float, items: int, seeds: int) -> tuple[float, int]:
    """(median fake seconds of the uploads that ended ACCEPTED, count of those that did not)."""
    times, failed = [], 0
    for seed in range(seeds):
        sim = Sim(server(profile), Channel(loss=loss, delay_s=delay_s, seed=seed))
        outcome = upload(sim, mission(items), timing=Timing(window=window)).outcome
        if outcome.error is None:
            times.append(sim.now)
        else:
            failed += 1
    return (statistics.median(times) if times else float("nan")), failed


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--items", type=int, default=100)
    p.add_argument("--seeds", type=int, default=20)
    p.add_argument("--windows", type=int, nargs="+", default=[1, 2, 8, 16])
    args = p.parse_args()
    command = " ".join([Path(sys.executable).name, *sys.argv])
    print(f"Command: `{command}` ({args.items} items, {args.seeds} seeds)")
    print()
    head = " | ".join(f"window {w}: s (not ACCEPTED)" for w in args.windows)
    print(f"| profile | loss each way | one-way delay | {head} |")
    print("|---|---:|---:|" + "---:|" * len(args.windows))
    for profile in ("ardupilot", "px4"):
        for loss, delay_s in LINKS:
            cells = []
            for window in args.windows:
                median_s, failed = one(profile, window, loss, delay_s, args.items, args.seeds)
                cells.append(f"{median_s:.2f} ({failed})")
            print(f"| {profile} | {loss:.0%} | {delay_s * 1e3:.0f} ms | {' | '.join(cells)} |")


if __name__ == "__main__":
    main()
