"""Shared plumbing of the vehicle commands (upload, download, clear, start): arguments, connection, tables.

Not a subcommand itself (it is not in gcs_planner.cli.COMMANDS).

Signing: --signing-passphrase, or the environment variable GCS_PLANNER_SIGNING_PASSPHRASE.

Autopilot conventions (home at seq 0 or not) are those of the vehicle's family, chosen from its
HEARTBEAT (gcs_planner.autopilots), unless --autopilot says otherwise.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import logging
import os
from collections.abc import AsyncIterator, Sequence

from pymavlink.dialects.v20 import ardupilotmega as mavlink

from gcs_planner.autopilots import Conventions, mode_of, quirks_for
from gcs_planner.core.errors import UserError
from gcs_planner.core.fleet_ids import MAX_NETWORK, network_of, wire_sysid
from gcs_planner.core.validation import number_flag
from gcs_planner.mavlink.command import CommandClient
from gcs_planner.mavlink.link import GCS_COMPID, GCS_SYSID, MavlinkLink, check_signing
from gcs_planner.mavlink.networks import NetworkLinks, open_networks
from gcs_planner.mavlink.transfer import Timing
from gcs_planner.wire.signing import key_from_passphrase
from gcs_planner.wire.types import MissionItem, MissionType

log = logging.getLogger(__name__)

MISSION_TYPES = {"mission": MissionType.MISSION, "fence": MissionType.FENCE, "rally": MissionType.RALLY}
HEARTBEAT_TIMEOUT_S = 5.0
SIGNING_ENV = "GCS_PLANNER_SIGNING_PASSPHRASE"  # keeps the passphrase out of shell history


def add_connection_arguments(
    p: argparse.ArgumentParser, fleet: bool = False, all_of: str | None = None
) -> None:
    """--connect (repeatable), --sysid, --compid, --autopilot, --heartbeat-timeout.

    fleet: --sysid also takes a list "1,2,5" or, where ``all_of`` says what it means, "all".
    """
    p.add_argument(
        "--connect",
        required=True,
        action="append",
        metavar="URL",
        help="MAVLink endpoint, e.g. udpout:127.0.0.1:14550 (to a vehicle), udpin:0.0.0.0:14550 (listen),"
        " tcp:127.0.0.1:5760 (SITL's TCP port) or serial:/dev/ttyUSB0:57600 (radio / USB); repeat for"
        " vehicles on several ports (any mix)",
    )
    if fleet:
        p.add_argument(
            "--sysid",
            required=True,
            type=_sysids,
            help=f"target system id (1..255), a list 1,2,5{f', or all ({all_of})' if all_of else ''}; a"
            " fleet id over 255 is network x 256 + sysid, with one --connect per network in order",
        )
    else:
        p.add_argument(
            "--sysid", required=True, type=_sysid, help="target vehicle's MAVLink system id (1..255)"
        )
    p.add_argument(
        "--compid",
        type=number_flag(0, 255, whole=True),
        default=1,
        help="target component id [1 = autopilot]",
    )
    p.add_argument(
        "--gcs-sysid",
        type=_sysid,
        default=GCS_SYSID,
        help=f"our own MAVLink system id [{GCS_SYSID}]: give each GCS on a vehicle its own, an autopilot"
        " tells uploaders apart by it",
    )
    p.add_argument(
        "--gcs-compid", type=_sysid, default=GCS_COMPID, help=f"our own MAVLink component id [{GCS_COMPID}]"
    )
    p.add_argument(
        "--signing-passphrase",
        metavar="TEXT",
        default=os.environ.get(SIGNING_ENV),
        help=f"MAVLink 2 signing: sign every frame, accept only signed ones (key = SHA-256 of TEXT, as"
        f" MAVProxy and QGroundControl); default: ${SIGNING_ENV}",
    )
    p.add_argument(
        "--autopilot",
        choices=("auto", *Conventions),
        default="auto",
        help="mission conventions: auto = from the vehicle's HEARTBEAT [auto]",
    )
    p.add_argument(
        "--heartbeat-timeout",
        type=number_flag(0, 3600, lo_open=True),
        default=HEARTBEAT_TIMEOUT_S,
        metavar="S",
        help=f"how long to wait for the vehicle's first HEARTBEAT [{HEARTBEAT_TIMEOUT_S:g} s]",
    )


def _sysid(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be an integer 1..255, got {text!r}") from None
    if not 1 <= value <= 255:
        raise argparse.ArgumentTypeError(f"must be an integer 1..255, got {value}")
    return value


def _fleet_id(text: str) -> int:
    """A system id, or a fleet id ``network x 256 + sysid`` (gcs_planner/core/fleet_ids.py)."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be an integer 1..255 or a fleet id, got {text!r}") from None
    if not (1 <= wire_sysid(value) <= 255 and 0 <= network_of(value) <= MAX_NETWORK):
        raise argparse.ArgumentTypeError(
            f"must be a system id 1..255 or a fleet id network x 256 + sysid (networks 0..{MAX_NETWORK}),"
            f" got {value}"
        )
    return value


def _sysids(text: str) -> list[int] | None:
    """'3' -> [3]; '1,2,5' -> [1, 2, 5]; 'all' -> None; fleet ids over 255 allowed."""
    if text.strip().lower() == "all":
        return None
    ids = [_fleet_id(part.strip()) for part in text.split(",")]
    if len(set(ids)) != len(ids):
        raise argparse.ArgumentTypeError(f"system ids repeat in {text!r}")
    return ids


async def open_link(args: argparse.Namespace, networks: int = 1) -> MavlinkLink | NetworkLinks:
    """The link to --connect's URLs; over ``networks`` > 1, NetworkLinks with one URL per network."""
    per_network = [[url] for url in args.connect] if networks > 1 else [args.connect]
    try:
        key = key_from_passphrase(args.signing_passphrase) if args.signing_passphrase else None
        sysid, compid = getattr(args, "gcs_sysid", GCS_SYSID), getattr(args, "gcs_compid", GCS_COMPID)
        return await open_networks(per_network, signing_key=key, sysid=sysid, compid=compid)
    except (OSError, ValueError) as exc:
        raise UserError(f"cannot open --connect {' '.join(args.connect)!r}: {exc}") from None


def check_networks(args: argparse.Namespace, sysids: Sequence[int]) -> int:
    """How many MAVLink networks ``sysids`` (fleet ids) span; UserError unless there is one
    --connect per network when they span more than one."""
    networks = max(network_of(s) for s in sysids) + 1
    if networks > 1 and len(args.connect) != networks:
        raise UserError(
            f"--sysid: fleet id {max(sysids)} is on MAVLink network {networks - 1}; give one --connect"
            f" per network 0..{networks - 1} in order ({len(args.connect)} given)"
        )
    return networks


@contextlib.asynccontextmanager
async def fleet_link(
    args: argparse.Namespace, sysids: Sequence[int]
) -> AsyncIterator[MavlinkLink | NetworkLinks]:
    """Open the link (one per network for fleet ids over 255) and wait until every vehicle in
    ``sysids`` sent a HEARTBEAT; always close."""
    link = await open_link(args, check_networks(args, sysids))
    try:
        loop = asyncio.get_running_loop()
        deadline = loop.time() + args.heartbeat_timeout
        missing = list(sysids)
        while missing and loop.time() < deadline:
            await asyncio.sleep(0.05)
            missing = [s for s in sysids if getattr(link.vehicles.get(s), "autopilot", None) is None]
        check_signing(link, sysids)
        if missing:
            raise UserError(
                f"no HEARTBEAT from system(s) {missing} on {' '.join(args.connect)}"
                f" within {args.heartbeat_timeout:g} s"
            )
        yield link
    finally:
        await link.close()


def autopilot_of(autopilot: int | None, mav_type: int | None, choice: str) -> str:
    """The item conventions for a vehicle whose HEARTBEAT says ``autopilot`` and ``mav_type``
    (see module docstring)."""
    return choice if choice != "auto" else quirks_for(autopilot, mav_type).conventions


@contextlib.asynccontextmanager
async def vehicle_link(args: argparse.Namespace) -> AsyncIterator[tuple[MavlinkLink, object]]:
    """Open the link, wait for the target's HEARTBEAT; yield (link, heartbeat); always close."""
    link = await open_link(args)
    try:
        try:
            heartbeat = await link.wait_for(
                lambda msg: (
                    msg.get_type() == "HEARTBEAT"
                    and msg.get_srcSystem() == args.sysid
                    and msg.get_srcComponent() == args.compid
                ),
                timeout_s=args.heartbeat_timeout,
            )
        except TimeoutError:
            heartbeat = None
        check_signing(link, [args.sysid])
        if heartbeat is None:
            raise UserError(
                f"no HEARTBEAT from system {args.sysid} component {args.compid} on {' '.join(args.connect)}"
                f" within {args.heartbeat_timeout:g} s"
            )
        yield link, heartbeat
    finally:
        await link.close()


def add_in_flight_argument(p: argparse.ArgumentParser) -> None:
    """--in-flight: items sent ahead of the vehicle's requests during an upload (Timing.window)."""
    p.add_argument(
        "--in-flight",
        type=number_flag(1, 64, whole=True),
        default=Timing.window,
        help=f"mission items sent ahead of the vehicle's requests [{Timing.window}]; 2 for a telemetry"
        " radio with a small buffer, 1 for one item per request",
    )


def add_force_argument(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--force",
        action="store_true",
        help="act on a vehicle that is armed and flying its mission in AUTO (it changes the mission it"
        " flies); without it that is refused",
    )


def check_not_flying_mission(link: MavlinkLink, sysid: int, force: bool, what: str) -> None:
    """UserError when ``sysid`` is armed in its mission mode (AUTO) and ``force`` is not given."""
    info = link.vehicles.get(sysid)
    if info is None or not info.armed or mode_of(info) != "AUTO" or force:
        return
    raise UserError(
        f"vehicle {sysid} is armed and flying its mission in AUTO: {what} changes the mission it flies;"
        " add --force to do it anyway"
    )


def command_name(command: int) -> str:
    entry = mavlink.enums["MAV_CMD"].get(command)
    return entry.name.removeprefix("MAV_CMD_") if entry else str(command)


def print_items(items: Sequence[MissionItem], title: str) -> None:
    """One row per item: seq, current, frame, command, params, lat/lon [deg], alt [m]."""
    print(title)
    print(
        f"{'seq':>5} {'cur':>3} {'frame':>5} {'command':<24} {'param1':>9} {'param2':>9} {'param3':>9}"
        f" {'param4':>9} {'lat_deg':>12} {'lon_deg':>13} {'alt_m':>9}"
    )
    for it in items:
        params = " ".join(f"{p:>9.6g}" for p in (it.param1, it.param2, it.param3, it.param4))
        print(
            f"{it.seq:>5} {it.current:>3} {it.frame:>5} {command_name(it.command):<24} {params}"
            f" {it.x / 1e7:>12.7f} {it.y / 1e7:>13.7f} {it.z:>9.2f}"
        )


def print_losses(losses) -> None:
    """One 'warning:' line per thing the file format could not carry (files.Loss)."""
    for loss in losses:
        print(f"warning: {loss}")


def print_table(headers: Sequence[str], rows: Sequence[Sequence[object]]) -> None:
    """Right-aligned columns sized to their content; floats with 3 decimals."""
    cells = [[f"{v:.3f}" if isinstance(v, float) else str(v) for v in row] for row in rows]
    widths = [max([len(h)] + [len(r[i]) for r in cells]) for i, h in enumerate(headers)]
    print("  ".join(h.rjust(w) for h, w in zip(headers, widths, strict=True)))
    for r in cells:
        print("  ".join(c.rjust(w) for c, w in zip(r, widths, strict=True)))


async def home_position(link: MavlinkLink, sysid: int, compid: int, timeout_s: float = 2.0):
    """The vehicle's home (lat [deg], lon [deg], alt [m AMSL]) via REQUEST_MESSAGE(HOME_POSITION), or None."""
    waiting = asyncio.ensure_future(
        link.wait_for(
            lambda m: m.get_type() == "HOME_POSITION" and m.get_srcSystem() == sysid, timeout_s=timeout_s
        )
    )
    try:
        await CommandClient(link, sysid, compid).command_long(
            mavlink.MAV_CMD_REQUEST_MESSAGE, mavlink.MAVLINK_MSG_ID_HOME_POSITION
        )
        msg = await waiting
    except (TimeoutError, UserError) as exc:
        log.warning("vehicle %d: no HOME_POSITION (%s); the file gets no planned home", sysid, exc)
        waiting.cancel()
        return None
    return msg.latitude / 1e7, msg.longitude / 1e7, msg.altitude / 1000.0
