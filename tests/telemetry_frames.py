"""Shared helpers for the telemetry tests: real MAVLink 2 frames from pymavlink's encoder."""

from __future__ import annotations

import os

import numpy as np

os.environ.setdefault("MAVLINK20", "1")
from pymavlink.dialects.v20 import ardupilotmega as mavlink  # noqa: E402

from gcs_planner.core.geo import Origin, enu_to_geodetic  # noqa: E402
from gcs_planner.model.plan import Plan, VehiclePlan  # noqa: E402

ORIGIN = Origin(47.397742, 8.545594, 488.0)

SCENARIO_TEXT = """
name = "telemetry test"
[origin]
lat_deg = 47.397742
lon_deg = 8.545594
alt_m = 488.0
[planner]
name = "straight"
[[vehicles]]
sysid = 1
start = [0, 0, 30]
goal = [200, 0, 30]
[[obstacles.cylinders]]
x = 100
y = 20
radius_m = 10
z_max_m = 60
[[obstacles.hemispheres]]
x = 50
y = -80
radius_m = 40
"""


def make_plan(sysids: list[int]) -> Plan:
    vehicles = []
    for s in sysids:
        wps = np.array([[0.0, 10.0 * s, 30.0], [200.0, 10.0 * s, 30.0]])
        vehicles.append(
            VehiclePlan(
                vehicle_id=f"uav{s}",
                sysid=s,
                waypoints=wps,
                times_s=[0.0, 20.0],
                speeds_mps=[0.0, 10.0],
                path=wps,
                path_times_s=[0.0, 20.0],
            )
        )
    return Plan(origin=ORIGIN, planner="straight", vehicles=vehicles)


def flight_frames(
    sysids: list[int], samples: int, rate_hz: float = 10.0, t0_s: float = 1.7e9, no_fix_first: int = 0
):
    """(msg, raw, t_s) for each vehicle flying east at 10 m/s, interleaved in time.

    Each vehicle sends GLOBAL_POSITION_INT every sample (the first ``no_fix_first`` at lat = lon =
    alt = 0, as ArduPilot before it has a position), MISSION_CURRENT and HEARTBEAT every 10th
    sample, and one STATUSTEXT at the start.
    """
    encoders = {s: mavlink.MAVLink(None, srcSystem=s, srcComponent=1) for s in sysids}
    parser = mavlink.MAVLink(None)
    out = []

    def add(sysid: int, msg, t_s: float) -> None:
        raw = bytes(msg.pack(encoders[sysid]))
        encoders[sysid].seq = (encoders[sysid].seq + 1) % 256  # pack() does not advance it; send() would
        out.append((parser.decode(bytearray(raw)), raw, t_s))  # as a receiving link sees it

    for s in sysids:
        add(s, mavlink.MAVLink_statustext_message(6, b'vehicle "%d" ready' % s, 0, 0), t0_s)
    for k in range(samples):
        t = t0_s + k / rate_hz
        for s in sysids:
            lat, lon, alt = enu_to_geodetic(10.0 * k / rate_hz, 10.0 * s, 30.0, ORIGIN)
            if k < no_fix_first:
                lat = lon = alt = 0.0
            msgs = [
                mavlink.MAVLink_global_position_int_message(
                    int(k * 1000 / rate_hz),
                    round(lat * 1e7),
                    round(lon * 1e7),
                    round(alt * 1e3),
                    30000 if k >= no_fix_first else 0,
                    1000,
                    0,
                    0,
                    9000,
                )
            ]
            if k % 10 == 0:
                msgs.append(mavlink.MAVLink_heartbeat_message(2, 3, 217, 3, 4, 3))
                msgs.append(mavlink.MAVLink_mission_current_message(k // 10))
            for i, msg in enumerate(msgs):
                add(s, msg, t + 1e-3 * s + 1e-4 * i)
    out.sort(key=lambda row: row[2])  # receive order
    return out


class FakeClock:
    """A clock for paced replay that moves only when slept on; ``sleeps`` records each sleep."""

    def __init__(self) -> None:
        self.now = 0.0
        self.sleeps: list[float] = []

    def sleep(self, dt: float) -> None:
        self.sleeps.append(dt)
        self.now += dt

    def __call__(self) -> float:
        return self.now
