"""Replay a flight log (MCAP) to Rerun (.rrd or a live viewer) or as MAVLink over UDP.

    gcs-planner replay FLIGHT.mcap --rrd out.rrd
    gcs-planner replay FLIGHT.mcap --to udpout:127.0.0.1:14550 --speed 4
    gcs-planner replay FLIGHT.mcap --viewer --speed 4   (spawns the Rerun viewer, paced)

MAVLink replay re-emits every recorded frame byte for byte with its flight-time timing (the
log's receive times x its clock rate) divided by --speed, so QGroundControl or MAVProxy
listening on that port sees the flight again; a silence longer than --max-gap seconds is cut to it
(and said so). Truncated logs (a killed recorder) are replayed up
to their last complete chunk. On Linux without a display (neither DISPLAY nor WAYLAND_DISPLAY
set) --viewer is refused before anything is read or
spawned: a spawned viewer there waits for a display that never comes.
"""

from __future__ import annotations

import argparse
import time

from gcs_planner.commands._viewer import check_display
from gcs_planner.commands.progress import progress_bar
from gcs_planner.core.errors import UserError
from gcs_planner.core.validation import number_flag, output_file
from gcs_planner.telemetry.reader import read_flight
from gcs_planner.telemetry.replay import (
    MAX_GAP_S,
    long_gaps,
    parse_udp_url,
    replay_to_mavlink,
    replay_to_rerun_live,
)

MCAP_MAGIC = b"\x89MCAP0\r\n"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("flight", help="flight log (.mcap) written by fly / import-tlog")
    p.add_argument("--rrd", help="write Rerun views to this .rrd file (headless)")
    p.add_argument("--viewer", action="store_true", help="show the views in a spawned Rerun viewer")
    p.add_argument("--to", metavar="udpout:HOST:PORT", help="re-emit the raw MAVLink frames to this address")
    p.add_argument(
        "--speed",
        type=number_flag(0, 1000),
        default=1.0,
        help="replay speed for --to / --viewer, times the pace the vehicles flew (1: as flown; 0 = max) [1]",
    )
    p.add_argument(
        "--max-gap",
        type=number_flag(0, 1e9, lo_open=True),
        default=MAX_GAP_S,
        metavar="S",
        help=f"--to / --viewer: a silence in the log over S seconds of replay is cut to S [{MAX_GAP_S:g}]",
    )


def run(args: argparse.Namespace) -> int:
    if not (args.rrd or args.to or args.viewer):
        raise UserError("nothing to do: give --rrd FILE, --viewer and/or --to udpout:HOST:PORT")
    if args.speed < 0:
        raise UserError(f"--speed must be >= 0, got {args.speed}")
    if args.viewer:
        check_display("--viewer")
    if args.to:
        parse_udp_url(args.to)
    if args.rrd:
        output_file(args.rrd, "--rrd", [args.flight])
    _check_mcap(args.flight)
    flight = read_flight(args.flight)
    if not flight.frames:
        why = f" ({flight.error})" if flight.error else ""
        raise UserError(f"flight log {args.flight!r}: no MAVLink frames in it{why}")
    note = f" (truncated log: recovered {flight.recovered_messages} messages)" if flight.truncated else ""
    damage = []
    if flight.damaged_chunks:
        damage.append(f"{flight.damaged_chunks} chunks failing their CRC")
    if flight.misplaced_messages:
        damage.append(f"{flight.misplaced_messages} messages at an impossible time")
    if damage:
        note += f" (damaged log: {' and '.join(damage)} left out)"
    gcs = flight.gcs_sysids
    kept = f"; ground station {gcs}: frames kept, not replayed" if gcs else ""
    print(f"{args.flight}: {len(flight.vehicle_frames)} frames from vehicles {flight.sysids}{kept}{note}")
    gaps = long_gaps(flight, args.speed, args.max_gap) if args.to or args.viewer else []
    if gaps:
        longest = f"{gaps[0]:.0f} s"
        print(f"{len(gaps)} silences over {args.max_gap:g} s cut to it (longest {longest}; --max-gap S)")
    if args.rrd or args.viewer:
        _to_rerun(flight, args.rrd, args.viewer, args.speed, args.max_gap)
    if args.to:
        with progress_bar(len(flight.vehicle_frames), f"replaying to {args.to}") as bar:

            def progress(sent: int, total: int) -> None:
                bar.n = sent
                bar.refresh()

            start = time.monotonic()
            sent = replay_to_mavlink(
                flight, args.to, speed=args.speed, progress=progress, max_gap_s=args.max_gap
            )
        print(f"sent {sent} frames to {args.to} in {time.monotonic() - start:.1f} s")
    return 0


def _check_mcap(path: str) -> None:
    """UserError unless ``path`` is a readable file that starts with the MCAP magic."""
    try:
        with open(path, "rb") as f:
            head = f.read(len(MCAP_MAGIC))
    except FileNotFoundError:
        raise UserError(f"flight log {path!r}: no such file") from None
    except OSError as exc:
        raise UserError(f"flight log {path!r}: cannot read: {exc.strerror or exc}") from None
    if head != MCAP_MAGIC:
        raise UserError(f"flight log {path!r} is not an MCAP file (it does not start with the MCAP magic)")


def _to_rerun(flight, rrd_path: str | None, viewer: bool, speed: float, max_gap_s: float) -> None:
    import rerun as rr

    from gcs_planner.telemetry.rerun_views import (
        APPLICATION_ID,
        flight_blueprint,
        log_flight_to_rerun,
        recording_id,
        rrd_recording,
    )

    start = time.monotonic()
    if rrd_path:  # written whole or not at all: a full disk is one line, no partial .rrd
        with rrd_recording(rrd_path, recording_id(flight.path.name)) as rec:
            log_flight_to_rerun(flight, rec=rec)
        print(f"wrote {rrd_path} in {time.monotonic() - start:.1f} s; open it with: rerun {rrd_path}")
    if viewer:
        rec = rr.RecordingStream(APPLICATION_ID, recording_id=recording_id(flight.path.name))
        try:
            rec.spawn(default_blueprint=flight_blueprint())
        except Exception as exc:  # noqa: BLE001 - no viewer binary / no display
            raise UserError(f"cannot start the Rerun viewer ({exc}); use --rrd FILE instead") from None
        if speed > 0:
            replay_to_rerun_live(flight, rec, speed, max_gap_s)
        else:
            log_flight_to_rerun(flight, rec=rec)
        rec.flush()
