"""Upload a mission (plus fence and rally points) to one vehicle or many, and print what each accepted.

FILE is a QGroundControl .plan (mission, geofence, rally points), a QGC WPL 110 file
(.waypoints / .txt), or plan.json from `gcs-planner plan` (the vehicle named by --vehicle, else the
one whose sysid is --sysid; --scenario adds that scenario's fence and rally points). Every list is
validated before anything is sent; an upload succeeds only on the vehicle's MISSION_ACK(ACCEPTED).

Lists: the ones FILE defines are sent, an empty one as an empty list (it clears the vehicle's): a
.plan defines all three (QGroundControl's PlanMasterController::sendToVehicle sends all three
every time), a WPL file one (mission, fence or rally), plan.json the mission (+ --scenario's fence
and rally). A list FILE does not define is left as the vehicle has it, and the table says so;
--clear-absent clears it instead, as QGroundControl would.

Many vehicles: --sysid 1,2,3 or --sysid all (every vehicle of plan.json), with one --connect per
vehicle port if they are on several; uploads run concurrently (--workers, default 8) with
automatic retries (gcs_planner.mavlink.fleet) and one table row per vehicle and list. A fleet
over several MAVLink networks names its vehicles by fleet id (network x 256 + sysid, as plan.json
does) and takes one --connect per network in order, as `fly` does.
"""

from __future__ import annotations

import argparse
import asyncio
import time
from typing import TYPE_CHECKING

from gcs_planner.autopilots import AutopilotQuirks, Conventions, quirks_for
from gcs_planner.commands._mission_cli import (
    add_connection_arguments,
    add_force_argument,
    add_in_flight_argument,
    autopilot_of,
    check_not_flying_mission,
    fleet_link,
    vehicle_link,
)
from gcs_planner.commands.progress import progress_bar
from gcs_planner.core.errors import UserError
from gcs_planner.core.fleet_ids import network_of
from gcs_planner.core.validation import number_flag
from gcs_planner.mavlink.errors import MissionRejectedError
from gcs_planner.mavlink.fleet import DEFAULT_WORKERS, upload_fleet
from gcs_planner.mavlink.link import MavlinkLink
from gcs_planner.mavlink.mission import MissionClient
from gcs_planner.mavlink.networks import NetworkLinks
from gcs_planner.mavlink.params import set_param
from gcs_planner.mavlink.transfer import Timing
from gcs_planner.missions.files import (
    MissionFile,
    load_plan_json,
    mission_input,
    plan_mission_file,
    select_vehicles,
)
from gcs_planner.missions.validate import validate_items
from gcs_planner.wire.types import MissionItem, MissionType

if TYPE_CHECKING:  # numpy-backed: loaded only with a plan.json
    from gcs_planner.model.plan import VehiclePlan


def add_arguments(p: argparse.ArgumentParser) -> None:
    add_connection_arguments(p, fleet=True, all_of="every vehicle in plan.json")
    p.add_argument("file", metavar="FILE", help="mission: .plan, .waypoints/.txt (QGC WPL 110) or plan.json")
    p.add_argument("--vehicle", help="vehicle id in plan.json [the one with --sysid]")
    p.add_argument("--scenario", help="scenario file whose fence and rally points to upload too")
    p.add_argument("--verify", action="store_true", help="download each list again and compare")
    p.add_argument(
        "--workers",
        type=number_flag(1, 255, whole=True),
        default=DEFAULT_WORKERS,
        help="concurrent uploads for many vehicles",
    )
    p.add_argument(
        "--retries",
        type=number_flag(0, 100, whole=True),
        default=2,
        help="extra attempts per failed vehicle [2]",
    )
    add_clear_absent_argument(p)
    add_force_argument(p)
    add_in_flight_argument(p)


def add_clear_absent_argument(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--clear-absent",
        action="store_true",
        help="also clear the lists FILE does not define (QGroundControl sends all three every time)",
    )


def lists_to_upload(
    mf: MissionFile, autopilot: str, clear_absent: bool = False
) -> list[tuple[MissionType, list[MissionItem]]]:
    """(mission_type, items) to send, validated: the lists ``mf`` defines (``clear_absent``: all
    three, the others empty). A mission without items goes as an empty list, home item or not,
    as QGroundControl sends it (PlanManager: no possibly bogus home position)."""
    lists = []
    for mission_type in (MissionType.MISSION, MissionType.FENCE, MissionType.RALLY):
        if mission_type in mf.lists:
            empty = mission_type == MissionType.MISSION and not mf.mission
            lists.append((mission_type, [] if empty else mf.list_items(mission_type, autopilot)))
        elif clear_absent:
            lists.append((mission_type, []))
    for mission_type, items in lists:
        validate_items(items, mission_type=mission_type)
    return lists


def absent_lists(mf: MissionFile, clear_absent: bool) -> list[str]:
    """One line per list the file does not define and the upload leaves alone."""
    if clear_absent:
        return []
    return [
        f"{t.name.lower()}: not in the file; the vehicle's list is kept (--clear-absent clears it)"
        for t in (MissionType.MISSION, MissionType.FENCE, MissionType.RALLY)
        if t not in mf.lists
    ]


class UploadSource:
    """FILE and --scenario, each read once. A plan.json's vehicles are looked up by fleet id, so
    preparing the uploads of N vehicles is linear in N (docs/results/fleet_upload.md)."""

    def __init__(self, args: argparse.Namespace) -> None:
        self.args = args
        self.plan = load_plan_json(args.file) if args.file.lower().endswith(".json") else None
        self.by_sysid: dict[int, VehiclePlan] = {}
        for vp in self.plan.vehicles if self.plan is not None else ():
            self.by_sysid.setdefault(vp.sysid, vp)  # the first one, as select_vehicles
        self.scenario = None
        if args.scenario:
            from gcs_planner.planning import load_scenario  # only with --scenario: upload starts lean

            self.scenario = load_scenario(args.scenario)

    def vehicle(self, sysid: int) -> VehiclePlan | None:
        """The plan's vehicle for ``sysid`` (or --vehicle); None for a .plan or WPL file."""
        if self.plan is None:
            return None
        if not self.args.vehicle and sysid in self.by_sysid:
            return self.by_sysid[sysid]
        vehicle_ids = [self.args.vehicle] if self.args.vehicle else None  # select_vehicles words errors
        return select_vehicles(self.plan, vehicle_ids, sysid=None if vehicle_ids else sysid)[0]

    def fence_ceiling(self, sysid: int) -> float | None:
        """--scenario's fence ceiling for vehicle ``sysid`` [m above its home]; None without one."""
        if self.scenario is None:
            return None
        from gcs_planner.safety.geofence import vehicle_geofence

        return vehicle_geofence(self.scenario, self.vehicle(sysid)).ceiling_m

    def mission_file(self, autopilot: str, sysid: int) -> MissionFile:
        """FILE for vehicle ``sysid`` with ``autopilot``'s conventions."""
        vp = self.vehicle(sysid)
        if vp is None:
            return mission_input(self.args.file, autopilot=autopilot)
        return plan_mission_file(vp, self.plan.origin, autopilot)


def read_input(
    args: argparse.Namespace, autopilot: str, sysid: int, source: UploadSource | None = None
) -> MissionFile:
    """FILE (+ --scenario's fence and rally) for vehicle ``sysid`` with ``autopilot``'s conventions;
    ``source``: FILE and --scenario already read (else they are read now)."""
    source = source or UploadSource(args)
    mf = source.mission_file(autopilot, sysid)
    if source.scenario is not None:
        from gcs_planner.missions.items import scenario_fence_items, scenario_rally_items
        from gcs_planner.safety.geofence import check_fence

        vp = source.vehicle(sysid)  # plan.json: the fence its plan keeps to
        if vp is not None:
            check_fence(source.scenario, vp)
        mf.fence = scenario_fence_items(source.scenario, vp)
        mf.rally = scenario_rally_items(source.scenario, vp)
        mf.lists = mf.lists | {MissionType.FENCE, MissionType.RALLY}
    return mf


def prepare(
    args: argparse.Namespace, autopilot: str, sysid: int, source: UploadSource | None = None
) -> list[tuple[MissionType, list[MissionItem]]]:
    """Read FILE for vehicle ``sysid`` with ``autopilot``'s conventions; validate every list.

    Called once before any network I/O (with --autopilot, or "px4" when it is auto) so bad input
    never reaches a vehicle, and again with the vehicle's autopilot: a WPL file is uploaded row
    for row either way; .plan and plan.json get ArduPilot's home item only for ArduPilot.
    ``source``: FILE and --scenario read once for many vehicles (UploadSource).
    """
    return lists_to_upload(read_input(args, autopilot, sysid, source), autopilot, args.clear_absent)


def target_sysids(args: argparse.Namespace, source: UploadSource) -> list[int]:
    """--sysid as a list; 'all' means every vehicle of plan.json."""
    if args.sysid is not None:
        sysids = args.sysid
    elif source.plan is not None:
        sysids = [v.sysid for v in source.plan.vehicles]
    else:
        raise UserError("--sysid all needs a plan.json FILE (a .plan or WPL file has no vehicles)")
    if len(sysids) > 1 and args.vehicle:
        raise UserError("--vehicle picks one vehicle of plan.json; give a single --sysid with it")
    return sysids


def run(args: argparse.Namespace) -> int:
    source = UploadSource(args)  # FILE and --scenario read once, whatever the fleet
    sysids = target_sysids(args, source)
    for sysid in sysids:  # fail on bad input before touching the network
        prepare(args, args.autopilot if args.autopilot != "auto" else Conventions.PX4, sysid, source)
    mf = read_input(args, Conventions.ARDUPILOT, sysids[0], source)
    for line in mf.notes + absent_lists(mf, args.clear_absent):
        print(f"note: {line}")
    if len(sysids) == 1 and network_of(sysids[0]) == 0:
        args.sysid = sysids[0]
        return asyncio.run(_upload_one(args, source))
    return asyncio.run(_upload_many(args, sysids, source))


def outcome_word(error: Exception | None) -> str:
    """The result column of an upload that did not succeed."""
    return "REJECTED" if isinstance(error, MissionRejectedError) else "FAILED"


async def _upload_one(args: argparse.Namespace, source: UploadSource) -> int:
    async with vehicle_link(args) as (link, heartbeat):
        autopilot = autopilot_of(heartbeat.autopilot, heartbeat.type, args.autopilot)
        lists = prepare(args, autopilot, args.sysid, source)
        check_not_flying_mission(link, args.sysid, args.force, "an upload")
        client = MissionClient(link, args.sysid, args.compid, timing=Timing(window=args.in_flight))
        print(f"vehicle {args.sysid} ({autopilot})")
        print(f"{'list':<8} {'items':>6} {'result':<10} {'opaque_id':>10} {'time_s':>7} verified")
        for mission_type, items in lists:
            t0 = time.monotonic()
            name = mission_type.name.lower()
            try:
                result = await client.upload(items, mission_type=mission_type, verify=args.verify)
            except UserError as exc:
                verdict = outcome_word(exc)
                print(f"{name:<8} {len(items):>6} {verdict:<10} {'-':>10} {time.monotonic() - t0:>7.2f}")
                raise
            elapsed_s = time.monotonic() - t0
            print(
                f"{name:<8} {len(items):>6} {'ACCEPTED':<10} {result.opaque_id:>10} {elapsed_s:>7.2f}"
                f" {'yes' if result.verified else 'no'}"
            )
        family = quirks_for(heartbeat.autopilot, heartbeat.type)
        if line := await _set_ceiling(link, args.sysid, family, source):
            print(line)
    return 0


async def _set_ceiling(link, sysid: int, family: AutopilotQuirks, source: UploadSource) -> str | None:
    """Set the fence's ceiling as the vehicle's autopilot keeps it (a fence item has no altitude);
    the line that says so. Nothing without --scenario, a [bounds] z or such a parameter."""
    ceiling = source.fence_ceiling(sysid)
    name = family.fence_alt_param
    if ceiling is None or name is None:
        return None
    value = await set_param(link, sysid, name, ceiling)
    return f"vehicle {sysid}: fence ceiling {name} = {value:g} m above home"


async def _upload_many(args: argparse.Namespace, sysids: list[int], source: UploadSource) -> int:
    async with fleet_link(args, sysids) as link:
        await upload_fleet_on(link, args, sysids, source)
    return 0


async def upload_fleet_on(
    link: MavlinkLink | NetworkLinks, args: argparse.Namespace, sysids: list[int], source: UploadSource
) -> None:
    """Upload FILE to every vehicle of ``sysids`` over ``link`` (--workers at once, --retries each);
    print one row per vehicle and list; UserError naming the first failure."""
    by_type: dict[MissionType, dict[int, list[MissionItem]]] = {}
    for sysid in sysids:
        check_not_flying_mission(link, sysid, args.force, "an upload")
        autopilot = autopilot_of(
            link.vehicles[sysid].autopilot, link.vehicles[sysid].mav_type, args.autopilot
        )
        for mission_type, items in prepare(args, autopilot, sysid, source):
            by_type.setdefault(mission_type, {})[sysid] = items
    results = {}
    with progress_bar(sum(len(m) for m in by_type.values()), "uploading", unit="list") as bar:
        for mission_type, missions in by_type.items():
            results[mission_type] = await upload_fleet(
                link,
                missions,
                workers=args.workers,
                retries=args.retries,
                progress=lambda done, total, result: bar.update(1),
                mission_type=mission_type,
                compid=args.compid,
                verify=args.verify,
                timing=Timing(window=args.in_flight),
            )
    uploaded = [s for s in sysids if all(per[s].ok for per in results.values())]
    families = {s: quirks_for(link.vehicles[s].autopilot, link.vehicles[s].mav_type) for s in uploaded}
    ceilings = await asyncio.gather(*(_set_ceiling(link, s, families[s], source) for s in uploaded))
    verified = f" {'verified':>8}" if args.verify else ""  # a list that reads back unequal fails
    print(
        f"{'sysid':>5} {'list':<8} {'items':>6} {'result':<10} {'tries':>5} {'opaque_id':>10} {'time_s':>7}"
        + verified
    )
    failures = []
    for line in filter(None, ceilings):
        print(line)
    for sysid in sysids:
        for mission_type, per_vehicle in results.items():
            r = per_vehicle[sysid]
            name = mission_type.name.lower()
            count = len(by_type[mission_type][sysid])
            verdict = "ACCEPTED" if r.ok else outcome_word(r.error)
            row = f"{sysid:>5} {name:<8} {count:>6} {verdict:<10} {r.attempts:>5} {r.opaque_id:>10}"
            print(f"{row} {r.elapsed_s:>7.2f}" + (f" {'yes' if r.ok else '-':>8}" if args.verify else ""))
            if not r.ok:
                failures.append(f"vehicle {sysid} {name}: {r.error}")
    if failures:
        raise UserError(
            f"{len(failures)} of {sum(len(m) for m in results.values())} uploads failed; {failures[0]}"
        )
