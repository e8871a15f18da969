"""`sitl-mock`: run a fleet of mock autopilots on UDP or TCP until Ctrl-C.

Vehicle i (system id i) listens on 127.0.0.1:base_port+i-1 (``--host`` to change) and streams to
whoever sends it a packet first, like ArduPilot SITL's udpin. ``--tcp``: it listens on that TCP
port instead and serves one GCS connection (ArduPilot SITL's ``tcp:5760``; ``--connect
tcp:HOST:PORT``). ``--out HOST:PORT``: every vehicle sends from its own ephemeral UDP port to a GCS
listening at HOST:PORT from the start (PX4 SITL, ArduPilot ``--serial0 udpclient:HOST:PORT``; the
GCS uses ``--connect udpin:HOST:PORT``). One log line per vehicle at start.

A fleet larger than ``--per-network`` (default 250; a MAVLink network has 254 system ids beside the
GCS) runs as several networks, one process each on one shared simulated clock: network k holds
vehicles k x per + 1 ... with system ids 1, 2, ... on consecutive ports, and one log line per
network gives its ``--connect udpout:HOST:FIRST-LAST`` for `gcs-planner fly`.

``--homes FILE``: one vehicle per line of FILE, the lines `gcs-planner fly SCENARIO --homes` prints
(``sysid N (ID): --home LAT,LON,ALT,HEADING  ...``): vehicle N stands at that home, as an operator
starts ArduPilot SITL with ``--home``, and the vehicles take the file's order on consecutive ports
(the world's ENU frame is centred on the first home).
Blank lines and ``#`` comments are skipped. The mock's fixed wing takes off heading north whatever
the heading (its fleets from a plan place its home south of the first waypoint: plan_fleet).
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import logging
import math
import re
import signal
import sys
import threading
import time

from gcs_planner.wire.signing import key_from_passphrase
from sitl_mock.faults import LinkFaults
from sitl_mock.fleet import MockFleet
from sitl_mock.flight import AIRFRAMES
from sitl_mock.geodesy import Home
from sitl_mock.process import MockFleetProcess
from sitl_mock.profiles import PROFILES
from sitl_mock.vehicle import DEFAULT_HOME

log = logging.getLogger("sitl_mock")


def _home(text: str) -> Home:
    try:
        parts = [float(p) for p in text.split(",")]
        if len(parts) not in (2, 3):
            raise ValueError("expected lat,lon[,alt]")
        return Home(*parts)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(f"--home {text!r}: {exc}") from None


def _host_port(text: str) -> tuple[str, int]:
    host, _, port = text.rpartition(":")
    if not host or not port.isdigit() or not 0 < int(port) <= 65535:
        raise argparse.ArgumentTypeError(f"--out {text!r}: expected HOST:PORT")
    return host, int(port)


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="sitl-mock", description=__doc__.splitlines()[0])
    which = p.add_mutually_exclusive_group()
    which.add_argument("--vehicles", type=int, default=1, help="number of vehicles (system ids 1..N)")
    which.add_argument(
        "--homes",
        metavar="FILE",
        help="one vehicle (of --type) per line of FILE, the output of `gcs-planner fly SCENARIO --homes`"
        " ('sysid N (ID): --home LAT,LON,ALT,HDG ...'): vehicle N at that home, as SITL's --home;"
        " replaces --vehicles",
    )
    p.add_argument("--base-port", type=int, default=14550, help="UDP port of vehicle 1 (0: ephemeral ports)")
    p.add_argument("--host", default="127.0.0.1", help="address to bind (0.0.0.0 for other machines)")
    where = p.add_mutually_exclusive_group()
    where.add_argument(
        "--tcp", action="store_true", help="listen on TCP ports instead of UDP (SITL's tcp:5760)"
    )
    where.add_argument(
        "--out",
        type=_host_port,
        metavar="HOST:PORT",
        help="send to a GCS listening at HOST:PORT from ephemeral UDP ports (PX4 SITL, ArduPilot udpclient)",
    )
    p.add_argument("--profile", choices=sorted(PROFILES), default="ardupilot")
    p.add_argument("--type", dest="vehicle_type", choices=sorted(AIRFRAMES), default="multirotor")
    p.add_argument("--speedup", type=float, default=1.0, help="simulated seconds per wall second")
    p.add_argument(
        "--home", type=_home, default=None, help="lat,lon[,alt AMSL] of every vehicle's home [PX4 SITL's]"
    )
    p.add_argument("--rate", type=float, default=10.0, help="position telemetry rate [Hz, wall clock]")
    p.add_argument("--loss", type=float, default=0.0, help="datagram loss probability, each direction")
    p.add_argument("--delay", type=float, default=0.0, help="one-way delay [s]")
    p.add_argument("--jitter", type=float, default=0.0, help="extra uniform delay up to this [s]")
    p.add_argument("--duplicate", type=float, default=0.0, help="duplication probability")
    p.add_argument("--reorder", type=float, default=0.0, help="reordering probability")
    p.add_argument("--seed", type=int, default=0, help="fault generator seed")
    p.add_argument(
        "--signing-passphrase",
        metavar="TEXT",
        help="MAVLink 2 signing: sign every frame and drop unsigned ones (key = SHA-256 of TEXT)",
    )
    p.add_argument(
        "--per-network", type=int, default=250, help="vehicles per MAVLink network (one process each) [250]"
    )
    p.add_argument(
        "--scurve-legs",
        action="store_true",
        help="ArduCopters fly their waypoints as ArduCopter does, each leg an S-curve from rest to rest"
        " (AC_WPNav / SCurve.cpp), and serve its stock WP_ACC, WP_JERK, WP_ACC_Z, WP_RADIUS_M, WP_ACC_CNR"
        " and ATC_INPUT_TC (default: the mock's own kinematics at its airframe's acceleration)",
    )
    p.add_argument("-v", "--verbose", action="store_true", help="debug logging")
    return p


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    logging.basicConfig(
        level=logging.DEBUG if args.verbose else logging.INFO, format="%(asctime)s %(name)s: %(message)s"
    )
    if not 1 <= args.per_network <= 254:
        parser.error(f"--per-network must be in 1..254, got {args.per_network}")
    if 0 < args.base_port < 1024:
        parser.error(f"--base-port {args.base_port} is a privileged port: use 0 (ephemeral) or 1024..65535")
    if args.scurve_legs and (args.profile, args.vehicle_type) != ("ardupilot", "multirotor"):
        parser.error("--scurve-legs are ArduCopter's: they need --profile ardupilot --type multirotor")
    if args.homes and args.home:
        parser.error("--homes gives each vehicle its home: no --home")
    try:
        homes = _homes_vehicles(args.homes) if args.homes else None
        frame = homes[0]["home"] if homes else args.home or DEFAULT_HOME  # with --homes: the first home
        faults = LinkFaults(args.loss, args.delay, args.jitter, args.duplicate, args.reorder, args.seed)
        options = dict(
            speedup=args.speedup, home=frame, profile=args.profile, vehicle_type=args.vehicle_type,
            host=args.host, faults=faults, rate_hz=args.rate,
            signing_key=key_from_passphrase(args.signing_passphrase) if args.signing_passphrase else None,
            transport="tcp" if args.tcp else "udpclient" if args.out else "udpin", gcs=args.out,
            flight={"scurve_legs": True} if args.scurve_legs else None,
        )  # fmt: skip
        if args.vehicles > args.per_network:
            if args.tcp or args.out:
                raise ValueError("a fleet over several networks runs on UDP ports: no --tcp or --out")
            return _serve_networks(args, options)
        if homes:
            fleet = MockFleet(vehicles=homes, base_port=args.base_port, **options)
        else:
            fleet = MockFleet(count=args.vehicles, base_port=args.base_port, **options)
    except ValueError as exc:
        parser.error(str(exc))
    try:
        asyncio.run(_serve(fleet, args))
    except OSError as exc:
        print(f"sitl-mock: error: {exc}", file=sys.stderr)
        return 2
    return 0


# a line of `gcs-planner fly --homes` (gcs_planner/flight/starts.py format_homes):
# "sysid N (ID): --home LAT,LON,ALT,HEADING  (MAV_SYSID N; ...) | PX4: ..."
HOMES_LINE = re.compile(r"sysid\s+(?P<sysid>\d+)\s+\(.*\):\s+--home\s+(?P<home>\S+)(?:\s.*)?")
HOMES_FORMAT = "'sysid N (ID): --home LAT,LON,ALT,HEADING', as `gcs-planner fly SCENARIO --homes` prints"


def _homes_vehicles(path: str) -> list[dict]:
    """A vehicle spec per home line of ``path`` (module docstring); ValueError naming a bad line."""
    try:
        with open(path, encoding="utf-8") as f:
            lines = f.read().splitlines()
    except (OSError, UnicodeDecodeError) as exc:
        raise ValueError(f"--homes {path}: cannot read it ({exc})") from None
    specs: list[dict] = []
    for number, line in enumerate(lines, 1):
        if not line.strip() or line.lstrip().startswith("#"):
            continue
        try:
            sysid, home = _home_line(line.strip())
            if sysid in {s["sysid"] for s in specs}:
                raise ValueError(f"sysid {sysid} stands at two homes")
        except ValueError as exc:
            shown = line.strip().split("  ")[0]  # without format_homes' notes for ArduPilot and PX4
            raise ValueError(f"--homes {path} line {number} ({shown}): {exc}") from None
        specs.append({"sysid": sysid, "home": home})
    if not specs:
        raise ValueError(f"--homes {path}: no home line; expected {HOMES_FORMAT}")
    return specs


def _home_line(line: str) -> tuple[int, Home]:
    """The system id and home of one line of `gcs-planner fly --homes`."""
    match = HOMES_LINE.fullmatch(line)
    if match is None:
        raise ValueError(f"expected {HOMES_FORMAT}")
    sysid = int(match["sysid"])
    if not 1 <= sysid <= 254:
        raise ValueError(f"sysid {sysid} is not a system id of one MAVLink network (1..254)")
    parts = match["home"].split(",")
    if len(parts) not in (3, 4):
        raise ValueError("--home must be LAT,LON,ALT[,HEADING]")
    lat, lon, alt, *heading = (float(p) for p in parts)  # a ValueError names the bad number
    if heading and not (math.isfinite(heading[0]) and 0.0 <= heading[0] <= 360.0):
        raise ValueError(f"heading must be in [0, 360] degrees, got {heading[0]!r}")
    return sysid, Home(lat, lon, alt)


def _serve_networks(args: argparse.Namespace, options: dict) -> int:
    """The fleet as networks of ``--per-network`` vehicles, a process each (module docstring),
    until SIGINT or SIGTERM."""
    if args.base_port <= 0 or args.base_port + args.vehicles - 1 > 65535:
        raise ValueError("a fleet over several networks needs --base-port > 0 with room for every vehicle")
    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.set())
    zero = time.monotonic()
    with contextlib.ExitStack() as stack:
        for first in range(0, args.vehicles, args.per_network):
            count = min(args.per_network, args.vehicles - first)
            port = args.base_port + first
            stack.enter_context(MockFleetProcess(count=count, base_port=port, clock_zero_s=zero, **options))
            log.info(
                "network %d: sysids 1..%d on udp %s:%d-%d (fly --connect udpout:%s:%d-%d)",
                first // args.per_network, count, args.host, port, port + count - 1,
                args.host, port, port + count - 1,
            )  # fmt: skip
        log.info("%d vehicles, speed-up %g; Ctrl-C to stop", args.vehicles, args.speedup)
        stop.wait()
        log.info("stopped")
    return 0


async def _serve(fleet: MockFleet, args: argparse.Namespace) -> None:
    """Serve until SIGINT (Ctrl-C) or SIGTERM, then close every socket. The handlers are installed
    here, so the mock also stops when started where SIGINT is inherited as ignored (a background
    job of a non-interactive shell, nohup)."""
    stop = asyncio.Event()
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGINT, signal.SIGTERM):
        loop.add_signal_handler(sig, stop.set)
    await fleet.start()
    try:
        for v in fleet.vehicles:
            host, port = v.address
            where = {"tcp": "tcp", "udpin": "udp"}.get(v.transport, "udp")
            to = f" -> {v.gcs[0]}:{v.gcs[1]}" if v.transport == "udpclient" else ""
            log.info(
                "sysid %d: %s %s:%d%s %s %s home %.7f,%.7f,%.1f",
                v.sysid, where, host, port, to, args.profile, args.vehicle_type,
                v.home.lat_deg, v.home.lon_deg, v.home.alt_m,
            )  # fmt: skip
        log.info("%d vehicles, speed-up %g; Ctrl-C to stop", len(fleet.vehicles), fleet.speedup)
        await stop.wait()
        log.info("stopped")
    finally:
        await fleet.stop()


if __name__ == "__main__":
    sys.exit(main())
