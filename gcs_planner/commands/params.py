"""Get, set or diff a vehicle's parameters against a Mission Planner .param or QGroundControl .params file.

``params get --connect URL --sysid N -o FILE``: every parameter of the vehicle (PARAM_REQUEST_LIST,
the missing ones asked for again by index) written to FILE: QGroundControl's tab-separated format
(with each parameter's MAV_PARAM_TYPE) when FILE ends in .params, else Mission Planner's
NAME,VALUE lines, which MAVProxy's ``param load`` reads too.

``params set FILE --connect URL --sysid N``: FILE (either format, told by its content; MAVProxy's
``param save`` output too) is checked line by line before anything is sent; then the vehicle's list
is downloaded and a name it does not have refuses the whole file, before any PARAM_SET. Only the
values that differ are set, each in the parameter's own type and confirmed by the vehicle's
echo; the counts set and unchanged are printed.

``params diff FILE --connect URL --sysid N``: NAME, FILE's value and the vehicle's for each
difference (``-`` for a name the vehicle does not have); exit 0 when none differ, 1 when some do.

Values compare as the vehicle holds them: a REAL32 as float32 (0.3, 0.300000 and
0.300000011920928955 are one value), an integer exactly. A QGC file's rows for another component
than --compid are skipped with a note. Integers travel bytewise for PX4 (as its HEARTBEAT says, or
--autopilot px4) and cast to float for ArduPilot. Protocol and formats: gcs_planner/mavlink/params.py,
gcs_planner/missions/param_files.py, docs/mavlink-protocol.md.
"""

from __future__ import annotations

import argparse
import asyncio

from gcs_planner.autopilots import quirks_for, quirks_named
from gcs_planner.commands._mission_cli import add_connection_arguments, vehicle_link
from gcs_planner.commands.progress import counting_bar, progress_bar
from gcs_planner.core.errors import UserError
from gcs_planner.core.validation import InputError, number_flag, output_file
from gcs_planner.mavlink.params import (
    DOWNLOAD_TIMEOUT_S,
    INT_RANGES,
    Param,
    download_params,
    float32,
    set_param,
    to_wire,
)
from gcs_planner.missions.param_files import (
    ParamEntry,
    format_value,
    is_param_name,
    is_qgc_name,
    read_param_file,
    write_param_file,
)


def add_arguments(p: argparse.ArgumentParser) -> None:
    actions = p.add_subparsers(dest="action", required=True, metavar="ACTION")
    get = actions.add_parser("get", help="download every parameter to FILE", description=__doc__)
    add_connection_arguments(get)
    get.add_argument(
        "-o",
        "--output",
        required=True,
        metavar="FILE",
        help="FILE.params: QGroundControl format, else Mission Planner",
    )
    helps = {
        "set": "set the parameters FILE gives that differ on the vehicle",
        "diff": "print the parameters where FILE and the vehicle differ (exit 1 when some do)",
    }
    parsers = [get]
    for name, help_text in helps.items():
        sub = actions.add_parser(name, help=help_text, description=__doc__)
        add_connection_arguments(sub)
        sub.add_argument("file", metavar="FILE", help="Mission Planner / MAVProxy .param or QGC .params file")
        parsers.append(sub)
    for sub in parsers:
        sub.add_argument(
            "--timeout",
            type=number_flag(0, 3600, lo_open=True),
            default=DOWNLOAD_TIMEOUT_S,
            metavar="S",
            help=f"give up the download after S s without a new parameter [{DOWNLOAD_TIMEOUT_S:g} s]",
        )


def run(args: argparse.Namespace) -> int:
    if args.action == "get":
        output_file(args.output, "-o")  # before the vehicle is asked: a bad path costs no download
        return asyncio.run(_get(args))
    entries = _file_entries(args)  # the whole file checked before any network I/O
    return asyncio.run(_set(args, entries) if args.action == "set" else _diff(args, entries))


def _file_entries(args: argparse.Namespace) -> list[ParamEntry]:
    """FILE's parameters for --compid; a note for the rows of other components (QGC files)."""
    entries = read_param_file(args.file)
    others = [e for e in entries if e.compid is not None and e.compid != args.compid]
    if others:
        print(f"note: {len(others)} rows of {args.file} are for other components than {args.compid}"
              f" (first: line {others[0].line}, component {others[0].compid}); skipped")  # fmt: skip
    mine = [e for e in entries if e not in others]
    if not mine:
        raise InputError(f"{args.file}: no parameter for component {args.compid}")
    return mine


def _bytewise(heartbeat, choice: str) -> bool:
    if choice == "auto":
        return quirks_for(heartbeat.autopilot, heartbeat.type).params_bytewise
    return quirks_named(choice).params_bytewise


async def _vehicle_params(link, heartbeat, args: argparse.Namespace) -> tuple[dict[str, Param], bool]:
    """The vehicle's parameters by name (a progress bar on a terminal); whether its integers are bytewise."""
    bytewise = _bytewise(heartbeat, args.autopilot)
    with counting_bar(f"vehicle {args.sysid} parameters", unit="param") as progress:
        params = await download_params(
            link, args.sysid, args.compid, bytewise=bytewise, timeout_s=args.timeout, progress=progress
        )
    return _by_name(params, args.sysid), bytewise


def _by_name(params: list[Param], sysid: int) -> dict[str, Param]:
    """The parameters by name; UserError for a name no file line can hold (a vehicle could write
    a line of its choosing into the backup) or one the vehicle gives twice (which to set?)."""
    by_name: dict[str, Param] = {}
    for p in params:
        if not is_param_name(p.name):
            raise UserError(f"vehicle {sysid}: parameter {p.index} is named {p.name!r}, not 1-16 letters, "
                            "digits or _; nothing written or set")  # fmt: skip
        if p.name in by_name:
            raise UserError(f"vehicle {sysid}: parameters {by_name[p.name].index} and {p.index} are both "
                            f"named {p.name}; nothing written or set")  # fmt: skip
        by_name[p.name] = p
    return by_name


async def _get(args: argparse.Namespace) -> int:
    async with vehicle_link(args) as (link, heartbeat):
        params, _ = await _vehicle_params(link, heartbeat, args)
    stack = quirks_for(heartbeat.autopilot, heartbeat.type).stack
    write_param_file(args.output, params.values(), args.sysid, args.compid, stack)
    kind = "QGroundControl .params" if is_qgc_name(args.output) else "Mission Planner .param"
    print(f"vehicle {args.sysid}: {len(params)} parameters written to {args.output} ({kind})")
    return 0


def same_value(value: int | float, param: Param) -> bool:
    """Whether a file's ``value`` is what the vehicle holds: an integer type exactly, else as float32."""
    if param.param_type in INT_RANGES:
        return value == param.value
    return float32(value) == param.value


def _changes(
    args: argparse.Namespace, entries: list[ParamEntry], params: dict[str, Param], bytewise: bool
) -> list[tuple[ParamEntry, Param]]:
    """(entry, the vehicle's parameter) for each value that differs, each checked against the
    parameter's type; InputError for a name the vehicle lacks or a value its type cannot hold."""
    unknown = [e for e in entries if e.name not in params]
    if unknown:
        first = unknown[0]
        raise InputError(f"{args.file} line {first.line}: vehicle {args.sysid} has no parameter {first.name}"
                         f" ({len(unknown)} of {len(entries)} names unknown); nothing was set")  # fmt: skip
    changes = [(e, params[e.name]) for e in entries if not same_value(e.value, params[e.name])]
    for entry, param in changes:
        try:
            to_wire(entry.value, param.param_type, bytewise, entry.name)
        except UserError as exc:
            raise InputError(f"{args.file} line {entry.line}: {exc}; nothing was set") from None
    return changes


async def _set(args: argparse.Namespace, entries: list[ParamEntry]) -> int:
    async with vehicle_link(args) as (link, heartbeat):
        params, bytewise = await _vehicle_params(link, heartbeat, args)
        changes = _changes(args, entries, params, bytewise)
        with progress_bar(len(changes), f"setting vehicle {args.sysid}", unit="param") as bar:
            for done, (entry, param) in enumerate(changes):
                try:
                    echoed = await set_param(link, args.sysid, entry.name, entry.value, args.compid,
                                             param_type=param.param_type, bytewise=bytewise)  # fmt: skip
                except UserError as exc:
                    raise UserError(f"{exc} ({done} of {len(changes)} changes set before it)") from None
                print(f"set {entry.name}: {format_value(param.value)} -> {format_value(echoed)}")
                bar.update(1)
    print(f"vehicle {args.sysid}: {len(changes)} set, {len(entries) - len(changes)} unchanged")
    return 0


async def _diff(args: argparse.Namespace, entries: list[ParamEntry]) -> int:
    async with vehicle_link(args) as (link, heartbeat):
        params, _ = await _vehicle_params(link, heartbeat, args)
    rows = []
    for entry in entries:
        param = params.get(entry.name)
        if param is None or not same_value(entry.value, param):
            vehicle = "-" if param is None else format_value(param.value)
            rows.append((entry.name, format_value(entry.value), vehicle))
    width = max([16] + [len(r[1]) for r in rows])
    for name, in_file, on_vehicle in rows:
        print(f"{name:<16} {in_file:>{width}} {on_vehicle:>{width}}")
    print(f"{len(rows)} of {len(entries)} parameters in {args.file} differ from vehicle {args.sysid}")
    return 1 if rows else 0
