"""Fly the ACMPSO paper plan on the mock fixed wing and check the flown track against the threats.

Plans missions/acmpso_paper.toml, converts the plan to an ArduPilot mission, uploads it over real
UDP (127.0.0.1) to one mock fixed-wing vehicle, arms, starts the mission and records the reported
position every ``--sample-s`` simulated seconds until the last waypoint is reached. Prints the
mission size, flight time, the largest horizontal and vertical deviation from the planned
polyline, and dense-resample violations (radar, obstacle, terrain + h_safe) of the flown track.

    nice .venv/bin/python benchmarks/acmpso_fly.py --speedup 200
"""

from __future__ import annotations

import argparse
import asyncio
import time
from pathlib import Path

import numpy as np
from pymavlink.dialects.v20 import ardupilotmega as mavlink

from gcs_planner.core.geo import Origin, enu_to_geodetic, geodetic_to_enu
from gcs_planner.mavlink.fleet import start_fleet, upload_fleet
from gcs_planner.mavlink.link import MavlinkLink
from gcs_planner.mavlink.preflight import request_streams
from gcs_planner.missions.items import plan_to_items
from gcs_planner.planning import config_of, load_scenario, plan_scenario
from gcs_planner.planning.threat_env import ThreatEnv, resample_path, validate_path
from sitl_mock.fleet import MockFleet

ROOT = Path(__file__).resolve().parents[1]


def deviation(track: np.ndarray, planned: np.ndarray) -> tuple[float, float, float]:
    """Largest horizontal distance of flown samples from the planned polyline, and the lowest and
    highest flown-minus-planned altitude at the nearest planned point [m]."""
    dense = resample_path(planned, 20.0)
    d = np.linalg.norm(dense[None, :, :2] - track[:, None, :2], axis=2)
    k = np.argmin(d, axis=1)
    dz = track[:, 2] - dense[k, 2]
    return float(d[np.arange(len(track)), k].max()), float(dz.min()), float(dz.max())


async def fly(args: argparse.Namespace) -> int:
    scenario = load_scenario(args.scenario)
    plan = plan_scenario(scenario, seed=args.seed)
    vp = plan.vehicles[0]
    items = plan_to_items(vp, plan.origin, "ardupilot")
    lat, lon, _ = enu_to_geodetic(vp.waypoints[0, 0], vp.waypoints[0, 1], 0.0, plan.origin)
    home = Origin(float(lat), float(lon), plan.origin.alt_m)  # home under the start, at the origin altitude
    params = config_of(scenario)
    env = ThreatEnv.from_scenario(scenario, params.h_safe_m)
    vehicles = [{"sysid": vp.sysid, "home": home, "vehicle_type": vp.vehicle_type, "profile": "ardupilot"}]
    fleet_kw = {"speedup": args.speedup, "physics_dt_s": args.physics_dt_s, "rate_hz": args.rate_hz}
    async with MockFleet(vehicles=vehicles, home=plan.origin, **fleet_kw) as fleet:
        link = await MavlinkLink.open(*(f"udpout:{h}:{p}" for h, p in fleet.addresses))
        await link.wait_for(lambda m: m.get_type() == "HEARTBEAT" and m.get_srcSystem() == vp.sysid, 5)
        # the mock, as stock ArduPilot, streams positions only when asked
        await request_streams(link, [vp.sysid], {mavlink.MAVLINK_MSG_ID_GLOBAL_POSITION_INT: args.rate_hz})
        positions: list[tuple[float, float, float]] = []

        def record(msg, raw, t_s) -> None:  # telemetry at the mock's rate in simulated time
            if msg.get_type() == "GLOBAL_POSITION_INT" and msg.get_srcSystem() == vp.sysid:
                positions.append((msg.lat * 1e-7, msg.lon * 1e-7, msg.relative_alt * 1e-3))

        link.subscribe(record)
        up = await upload_fleet(link, {vp.sysid: items})
        if not up[vp.sysid].ok:
            print(f"upload failed: {up[vp.sysid].error}")
            return 1
        started = await start_fleet(link, [vp.sysid])
        if not started[vp.sysid].ok:
            print(f"start failed: {started[vp.sysid].error}")
            return 1
        t0_sim, t0_wall = fleet.sim_time_s, time.monotonic()
        last = len(items) - 1
        while fleet.sim_time_s - t0_sim < args.timeout_s and fleet.snapshot()[0].state.mission_seq < last:
            await asyncio.sleep(0.2)
        flight_s, wall_s = fleet.sim_time_s - t0_sim, time.monotonic() - t0_wall
        await link.close()
    lat_deg, lon_deg, rel_alt_m = np.asarray(positions).T
    e, n, _ = geodetic_to_enu(lat_deg, lon_deg, plan.origin.alt_m, plan.origin)
    track = np.column_stack([e, n, rel_alt_m])  # home is at the origin altitude: relative alt = ENU up
    # compare from the first pass near waypoint 1 on (the take-off climb-out is not part of the track)
    near = np.linalg.norm(track[:, :2] - vp.waypoints[1, :2], axis=1) < 100.0
    cruise = track[int(np.argmax(near)) :] if near.any() else track
    horizontal, below, above = deviation(cruise, vp.waypoints)
    report = validate_path(env, cruise, spacing=100.0)
    if args.save_track:
        np.savez(args.save_track, flown=track, planned=vp.waypoints)
    print(f"mission: {len(items)} items ({len(vp.waypoints)} waypoints), planned {vp.times_s[-1]:.0f} s")
    print(f"flown: {flight_s:.0f} s simulated in {wall_s:.1f} s wall, {len(track)} position reports")
    print(
        f"deviation from the planned polyline: horizontal <= {horizontal:.1f} m,"
        f" altitude {below:+.1f} .. {above:+.1f} m (flown - planned)"
    )
    print(f"flown-track violations (dense resample): {report.summary()}")
    for v in report.violations[:10]:
        print(f"  {v.kind} {v.index}: depth {v.depth:.1f} m at {np.round(v.where, 0)}")
    return 0


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenario", type=Path, default=ROOT / "missions" / "acmpso_paper.toml")
    ap.add_argument("--seed", type=int, default=None)
    ap.add_argument("--speedup", type=float, default=200.0)
    ap.add_argument("--physics-dt-s", type=float, default=0.2, help="mock physics step (simulated s)")
    ap.add_argument("--rate-hz", type=float, default=1.0, help="position telemetry rate (simulated Hz)")
    ap.add_argument("--save-track", type=Path, help="write flown and planned tracks (npz) here")
    ap.add_argument("--timeout-s", type=float, default=20000.0, help="simulated seconds")
    return asyncio.run(fly(ap.parse_args()))


if __name__ == "__main__":
    raise SystemExit(main())
