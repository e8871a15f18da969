"""Give a vehicle a MAVLink 2 signing key (SETUP_SIGNING), or turn its signing off, and check it took.

The new key is SHA-256 of --new-passphrase (or $GCS_PLANNER_NEW_SIGNING_PASSPHRASE), as MAVProxy's
``signing setup`` derives it; --disable sends the all-zero key, which turns signing off. A vehicle
that already signs drops unsigned frames, so then the link signs with its current key
(--signing-passphrase). SETUP_SIGNING has no answer: the command sends it up to SETUP_ATTEMPTS
times and succeeds once a HEARTBEAT of the vehicle verifies with the new key (after --disable: once
one arrives unsigned). The key crosses the link in clear: use a link nobody else hears (USB, cable).
"""

from __future__ import annotations

import argparse
import asyncio
import os

from pymavlink.dialects.v20.ardupilotmega import MAVLINK_IFLAG_SIGNED

from gcs_planner.autopilots import quirks_for
from gcs_planner.commands._mission_cli import add_connection_arguments, vehicle_link
from gcs_planner.core.errors import UserError
from gcs_planner.mavlink.link import MavlinkLink
from gcs_planner.wire.signing import NO_KEY, key_from_passphrase, setup_signing_message

NEW_SIGNING_ENV = "GCS_PLANNER_NEW_SIGNING_PASSPHRASE"
SETUP_ATTEMPTS = 3
HEARTBEAT_WAIT_S = 2.5  # per attempt: autopilots send HEARTBEAT at 1 Hz


def add_arguments(p: argparse.ArgumentParser) -> None:
    add_connection_arguments(p)
    group = p.add_mutually_exclusive_group()
    group.add_argument(
        "--new-passphrase",
        metavar="TEXT",
        default=os.environ.get(NEW_SIGNING_ENV),
        help=f"the key to give the vehicle: SHA-256 of TEXT; default: ${NEW_SIGNING_ENV}",
    )
    group.add_argument("--disable", action="store_true", help="turn the vehicle's signing off")


def run(args: argparse.Namespace) -> int:
    if not args.disable and not args.new_passphrase:
        raise UserError(f"give --new-passphrase (or ${NEW_SIGNING_ENV}) or --disable")
    new_key = NO_KEY if args.disable else key_from_passphrase(args.new_passphrase)
    return asyncio.run(_setup(args, new_key))


async def _setup(args: argparse.Namespace, new_key: bytes) -> int:
    current = key_from_passphrase(args.signing_passphrase) if args.signing_passphrase else None
    after = None if new_key == NO_KEY else new_key
    async with vehicle_link(args) as (link, heartbeat):
        for attempt in range(1, SETUP_ATTEMPTS + 1):
            link.set_signing_key(current)  # the vehicle checks the request with the key it has
            link.send(setup_signing_message(new_key, args.sysid, args.compid))
            link.set_signing_key(after)
            if await _heartbeat_with(link, args.sysid, args.compid, signed=after is not None):
                state = "signing off" if after is None else "signs with the new key"
                print(f"vehicle {args.sysid}: {state} (HEARTBEAT checked; SETUP_SIGNING sent {attempt}x)")
                note = quirks_for(heartbeat.autopilot, heartbeat.type).signing_note
                if after is not None and note:
                    print(f"note: {note}")
                return 0
    raise UserError(
        f"vehicle {args.sysid} did not take the key: no HEARTBEAT {'signed with it' if after else 'unsigned'}"
        f" after {SETUP_ATTEMPTS} SETUP_SIGNING (is --signing-passphrase the vehicle's current key?)"
    )


async def _heartbeat_with(link: MavlinkLink, sysid: int, compid: int, *, signed: bool) -> bool:
    """True when a HEARTBEAT of the vehicle's component ``sysid``/``compid`` arrives signed (the
    link dropped those not signed with its key) or, for ``signed=False``, unsigned, within
    HEARTBEAT_WAIT_S. Only that component counts: a gimbal or camera of the same system that never
    signed would otherwise pass for an autopilot that still signs."""
    try:
        await link.wait_for(
            lambda m: (
                m.get_type() == "HEARTBEAT"
                and (m.get_srcSystem(), m.get_srcComponent()) == (sysid, compid)
                and bool(m.get_header().incompat_flags & MAVLINK_IFLAG_SIGNED) is signed
            ),
            HEARTBEAT_WAIT_S,
        )
        return True
    except TimeoutError:
        return False
