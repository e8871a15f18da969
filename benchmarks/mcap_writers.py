"""MCAP writers on the same messages, in one run: this project's ChunkedMcapWriter (with message
indexes) against the stock Python writer (mcap.writer.Writer) and foxglove-sdk's (Rust, through
foxglove.open_mcap; its compression on the calling thread), all zstd, chunks of ~1 MB.

    python benchmarks/mcap_writers.py [--messages 200000] [--channels 40] [--repeat 3]

Messages are MAVLink-sized (40-80 bytes) on --channels channels, added in batches of 100 as
FlightLogger adds a datagram's frames; the time is process CPU time including closing the file,
best of --repeat. Prints messages/s for each and the ratio.
"""

from __future__ import annotations

import argparse
import os
import platform
import random
import tempfile
import time
from pathlib import Path

import foxglove
from foxglove.mcap import MCAPCompression, MCAPWriteOptions
from mcap.writer import CompressionType, Writer

from gcs_planner.telemetry.mcap_writer import ChunkedMcapWriter

CHUNK_BYTES = 1 << 20


def messages(n: int, channels: int) -> list[tuple[int, int, bytes]]:
    rng = random.Random(1)
    return [(1 + k % channels, 1_000_000 * k, rng.randbytes(rng.randint(40, 80))) for k in range(n)]


def ours(rows, channels: int, path: Path) -> None:
    w = ChunkedMcapWriter(path)
    schema = w.register_schema("mavlink", "", b"")
    for c in range(channels):
        w.register_channel(f"/mavlink/{c}/raw", "mavlink", schema)
    for k in range(0, len(rows), 100):
        w.add_messages(rows[k : k + 100])
        if w.chunk_bytes >= CHUNK_BYTES:
            w.flush()
    w.finish()


def stock(rows, channels: int, path: Path) -> None:
    with path.open("wb") as f:
        w = Writer(f, chunk_size=CHUNK_BYTES, compression=CompressionType.ZSTD)
        w.start()
        schema = w.register_schema("mavlink", "", b"")
        for c in range(channels):
            w.register_channel(f"/mavlink/{c}/raw", "mavlink", schema)
        for channel, t_ns, data in rows:
            w.add_message(channel, t_ns, data, t_ns)
        w.finish()


def foxglove_sdk(rows, channels: int, path: Path) -> None:
    context = foxglove.Context()
    zstd = MCAPCompression.Zstd
    options = MCAPWriteOptions(compression=zstd, chunk_size=CHUNK_BYTES, compression_threads=0)
    writer = foxglove.open_mcap(str(path), allow_overwrite=True, context=context, writer_options=options)
    schema = foxglove.Schema(name="mavlink", encoding="", data=b"")
    topics = [
        foxglove.Channel(f"/mavlink/{c}/raw", schema=schema, message_encoding="mavlink", context=context)
        for c in range(channels)
    ]
    for channel, t_ns, data in rows:
        topics[channel - 1].log(data, log_time=t_ns)
    writer.close()


def best_cpu_s(write, rows, channels: int, repeat: int) -> float:
    times = []
    with tempfile.TemporaryDirectory() as tmp:
        for _ in range(repeat):
            t0 = time.process_time()
            write(rows, channels, Path(tmp) / "x.mcap")
            times.append(time.process_time() - t0)
    return min(times)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--messages", type=int, default=200_000)
    p.add_argument("--channels", type=int, default=40)
    p.add_argument("--repeat", type=int, default=3)
    args = p.parse_args()
    rows = messages(args.messages, args.channels)
    ours_s = best_cpu_s(ours, rows, args.channels, args.repeat)
    stock_s = best_cpu_s(stock, rows, args.channels, args.repeat)
    sdk_s = best_cpu_s(foxglove_sdk, rows, args.channels, args.repeat)
    machine = platform.processor() or platform.machine()
    load = os.getloadavg()[0]
    print(f"machine: {machine}, {os.cpu_count()} cores, load {load:.1f}, {time.strftime('%Y-%m-%d')}\n")
    print("| writer | msg/s (CPU) |\n|---|---:|")
    print(f"| ChunkedMcapWriter (message indexes) | {args.messages / ours_s:,.0f} |")
    print(f"| mcap.writer.Writer (stock) | {args.messages / stock_s:,.0f} |")
    print(f"| foxglove-sdk MCAPWriter | {args.messages / sdk_s:,.0f} |")
    print(f"| ratio ours / stock | {stock_s / ours_s:.2f}x |")
    print(f"| ratio ours / foxglove-sdk | {sdk_s / ours_s:.2f}x |")


if __name__ == "__main__":
    main()
