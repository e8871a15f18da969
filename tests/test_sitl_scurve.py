"""The mock's ArduCopter waypoint legs (sitl_mock.scurve, sitl_mock.wpnav: its own port of SCurve.cpp
and AC_WPNav) against ArduCopter SITL, and flown by mock vehicles with ``scurve_legs``."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from sitl_legs import SITL_LEG_S, SITL_START_LAG_S, inner_leg_times_s, zigzag

from gcs_planner.cli import main
from sitl_mock.flight import AIRFRAMES, Arrival, Guidance, Kinematics
from sitl_mock.wpnav import STOCK_PARAMS, WaypointNav

DT = 0.05  # the mock fleet's physics step [s]


def fly(waypoints: np.ndarray, params: dict) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Times, positions and velocities of a mock copter from the hover at waypoints[0] through the
    others, each reached waypoint's successor preloaded as ArduCopter's mission does."""
    kin = Kinematics([AIRFRAMES["multirotor"]], waypoints[:1] - [0.0, 0.0, 50.0])
    kin.pos[0] = waypoints[0]
    nav = kin.wpnav[0] = WaypointNav(params)
    nav.init(waypoints[0], 10.0)
    k, t, rows = 0, 0.0, [(0.0, waypoints[0], np.zeros(3))]
    while k < len(waypoints) - 1:
        if k == 0 or kin.arrived()[0]:
            k += 1
            nav.set_destination(waypoints[k])
            if k + 1 < len(waypoints):
                nav.set_destination_next(waypoints[k + 1])
            kin.command(0, Guidance.TRACK, waypoints[k], Arrival.TRACKED)
        kin.step(DT)
        t += DT
        rows.append((t, kin.pos[0].copy(), kin.vel[0].copy()))
        assert t < 600.0
    while np.linalg.norm(kin.vel[0]) > 1e-3 or not kin.arrived()[0]:  # settle on the last one
        kin.step(DT)
        t += DT
        rows.append((t, kin.pos[0].copy(), kin.vel[0].copy()))
    return np.array([r[0] for r in rows]), np.array([r[1] for r in rows]), np.array([r[2] for r in rows])


def target_track(waypoints: np.ndarray, params: dict) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Times, positions and velocities of the S-curve target alone over the first leg, a copter
    exactly on it (the plan AC_WPNav makes, without the copter's lag)."""
    nav = WaypointNav(params)
    nav.init(waypoints[0], 10.0)
    nav.set_destination(waypoints[1])
    rows = [(0.0, waypoints[0], np.zeros(3))]
    while not nav.reached_destination:
        position, velocity, _ = nav.update(DT, *nav.target[:2])
        rows.append((rows[-1][0] + DT, position, velocity))
    return np.array([r[0] for r in rows]), np.array([r[1] for r in rows]), np.array([r[2] for r in rows])


def params(**values: float) -> dict[str, float]:
    return {**STOCK_PARAMS, "WP_SPD_UP": 4.0, "WP_SPD_DN": 4.0, **values}


@pytest.mark.parametrize(("accel", "jerk", "turn"), list(SITL_LEG_S))
def test_the_mock_flies_each_leg_in_the_time_arducopter_sitl_took(accel, jerk, turn):
    """20-160 m legs at 10 m/s, 20 and 60 degree turns: within 0.2 s of SITL (the physics step is
    0.05 s); a short leg peaks low on its own ramp, and the copter ends at rest on the last waypoint."""
    waypoints = zigzag(turn)
    times, positions, velocities = fly(waypoints, params(WP_ACC=accel, WP_JERK=jerk))
    assert inner_leg_times_s(times, positions, waypoints) == pytest.approx(
        SITL_LEG_S[(accel, jerk, turn)], abs=0.2
    )
    assert np.linalg.norm(positions[-1] - waypoints[-1]) < 0.05
    speed = np.linalg.norm(velocities, axis=1)
    assert np.mean(np.abs(speed - 10.0) < 0.1) > 0.1  # cruising at WP_SPD on the long legs
    assert speed.max() < 11.5  # catching up its target after a turn (SITL's copter peaks at 10.3-10.6 m/s)
    assert np.abs(np.diff(speed)).max() / DT <= 2.0 * accel  # within WP_ACC_CNR's default at the corners


def test_a_climbing_leg_keeps_wp_spd_up_and_wp_acc_z():
    """A 30-degree climb at stock WP_SPD_UP 2.5: 5 m/s along the leg (kinematic_limit), the vertical
    acceleration within WP_ACC_Z 1."""
    waypoints = np.array([[0.0, 0.0, 0.0], [200.0 * np.cos(np.pi / 6), 0.0, 100.0]])
    _, _, velocities = target_track(waypoints, {**STOCK_PARAMS, "WP_SPD_UP": 2.5, "WP_SPD_DN": 1.5})
    assert velocities[:, 2].max() == pytest.approx(2.5, abs=1e-6)
    assert np.linalg.norm(velocities, axis=1).max() == pytest.approx(5.0, abs=1e-6)
    assert np.abs(np.diff(velocities[:, 2])).max() / DT <= 1.0 + 1e-6


def test_the_copter_trails_its_s_curve_as_arducopter_sitl_did():
    """Leaving the hover on a 189 m leg at WP_ACC 3.5 / WP_JERK 2, the copter falls behind its target
    and the target's time slows with it (AC_WPNav's track_dt_scalar): 0.5-0.8 s behind the S-curve's
    own timeline 4-8 s into the leg, as SITL's were (what the autopilot's start latency measures)."""
    waypoints = np.array([[0.0, 0.0, 30.0], [189.0, 0.0, 30.0], [400.0, 0.0, 30.0]])
    times, positions, _ = fly(waypoints, params(WP_ACC=3.5, WP_JERK=2.0))
    nominal_t, nominal, _ = target_track(waypoints, params(WP_ACC=3.5, WP_JERK=2.0))
    nominal_m = nominal[:, 0]
    for at_s, sitl_s in SITL_START_LAG_S.items():
        flown_m = np.interp(at_s, times, positions[:, 0])
        assert at_s - np.interp(flown_m, nominal_m, nominal_t) == pytest.approx(sitl_s, abs=0.15)


@pytest.mark.parametrize(("at_s", "speed_mps"), [(3.0, 6.0), (15.0, 6.0), (15.0, 13.0), (0.0, 7.0)])
def test_a_speed_change_replans_the_rest_of_the_leg(at_s, speed_mps):
    """DO_CHANGE_SPEED on a 400 m leg, while accelerating, cruising or before it starts: the copter
    settles at the new speed within WP_ACC, and still stops on the destination."""
    nav = WaypointNav(params())
    nav.init(np.zeros(3), 10.0)
    nav.set_destination(np.array([400.0, 0.0, 0.0]))
    t, speeds, position = 0.0, [], np.zeros(3)
    while not nav.reached_destination:
        if abs(t - at_s) < DT / 2:
            nav.set_speed(speed_mps)
        position, velocity, _ = nav.update(DT, *nav.target[:2])  # a copter exactly on its target
        speeds.append(float(np.linalg.norm(velocity)))
        t += DT
        assert t < 200.0
    speeds = np.array(speeds)
    assert speeds[round(28.0 / DT)] == pytest.approx(speed_mps, abs=1e-3)  # cruising at the new speed
    assert np.abs(np.diff(speeds)).max() / DT <= 2.5 + 1e-3  # WP_ACC
    assert np.linalg.norm(position - [400.0, 0.0, 0.0]) < 1e-6 and speeds[-1] < 1e-6


SWARM_SMALL = Path(__file__).resolve().parents[1] / "missions" / "swarm_small.toml"


def test_fly_on_mock_arducopter_legs_is_refused_at_stock_values_and_passes_with_the_values_offered(
    tmp_path, capsys
):
    """`fly --mock-legs scurve`, in lockstep: the mocks serve ArduCopter's stock WP_ACC / WP_JERK and
    fly by them, so swarm_small's ~45 m legs are refused before anything is sent, as on SITL; with the
    values the refusal offers (--mock-param, as SITL's --defaults) the five fly it and conform."""
    argv = ["fly", str(SWARM_SMALL), "--mock-legs", "scurve", "-o", str(tmp_path / "stock")]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "its short legs never reach their speed" in err[0], err
    accel, jerk = re.search(r"WP_ACC ([\d.]+) and WP_JERK ([\d.]+) predict", err[0]).groups()
    argv = ["fly", str(SWARM_SMALL), "--mock-legs", "scurve", "--mock-param", f"WP_ACC={accel}",
            "--mock-param", f"WP_JERK={jerk}", "-o", str(tmp_path / "offered")]  # fmt: skip
    assert main(argv) == 0
    out = capsys.readouterr().out
    assert "PASS: 5/5 vehicles conform" in out, out


@pytest.mark.parametrize(
    ("extra", "words"),
    [
        (["--mock-param", "WP_ACC"], "--mock-param must be NAME=VALUE with a finite number, got 'WP_ACC'"),
        (
            ["--mock-param", "WP_ACC=nan"],
            "--mock-param must be NAME=VALUE with a finite number, got 'WP_ACC=nan'",
        ),
        (["--mock-param", "WP_ACCEL=3"], "--mock-param: vehicle 1 has no parameter 'WP_ACCEL' to set"),
        (["--mock-legs", "scurve", "--autopilot", "px4"], "--mock-legs scurve flies ArduCopter's legs"),
        (["--mock-param", "WP_ACC=3", "--connect", "udpout:127.0.0.1:9"], "not with --connect"),
    ],
)
def test_bad_mock_options_are_refused_in_one_line_before_anything_is_written(tmp_path, capsys, extra, words):
    out = tmp_path / "out"
    assert main(["fly", str(SWARM_SMALL), *extra, "-o", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and words in err[0] and "Traceback" not in err[0], err
    assert not out.exists()


def test_sitl_mock_scurve_legs_are_arducopter_only():
    refused = subprocess.run(
        [sys.executable, "-m", "sitl_mock.cli", "--scurve-legs", "--profile", "px4"],
        capture_output=True,
        text=True,
    )
    assert refused.returncode == 2 and "--scurve-legs are ArduCopter's" in refused.stderr, refused.stderr
    assert "Traceback" not in refused.stderr


@pytest.mark.parametrize(("accel", "jerk"), [(2.5, 1.0), (3.5, 2.0)])
def test_the_clients_model_and_the_mocks_port_pass_swarm_small_waypoints_together(accel, jerk):
    """Two S-curve implementations that share no code: the client's (geometry.scurve, sampled, for
    the pre-flight check) and the mock's (a port of SCurve.cpp's closed forms) put the target at
    every waypoint of swarm_small's missions within 0.15 s of each other."""
    from gcs_planner.geometry.scurve import WaypointNav as ClientNav
    from gcs_planner.geometry.scurve import fly_legs
    from gcs_planner.missions.items import mission_waypoints
    from gcs_planner.planning import load_scenario, plan_scenario

    for vp in plan_scenario(load_scenario(SWARM_SMALL)).vehicles:
        route = mission_waypoints(vp)
        waypoints = route["waypoints"][
            np.r_[True, np.linalg.norm(np.diff(route["waypoints"], axis=0), axis=1) > 1e-3]
        ]
        client_t, client_p = fly_legs(
            waypoints, np.full(len(waypoints), 10.0), ClientNav(accel, jerk, 4.0, 4.0)
        )
        nav = WaypointNav(params(WP_ACC=accel, WP_JERK=jerk))
        nav.init(waypoints[0], 10.0)
        k, t, times, positions = 0, 0.0, [0.0], [waypoints[0]]
        while k < len(waypoints) - 1:
            if k == 0 or nav.reached_destination:
                k += 1
                nav.set_destination(waypoints[k])
                if k + 1 < len(waypoints):
                    nav.set_destination_next(waypoints[k + 1])
            position, _, _ = nav.update(0.01, *nav.target[:2])
            t += 0.01
            times.append(t)
            positions.append(position)
        while not nav.reached_destination:
            position, _, _ = nav.update(0.01, *nav.target[:2])
            t += 0.01
            times.append(t)
            positions.append(position)
        times, positions = np.array(times), np.array(positions)
        for w in waypoints[1:-1]:  # passed at speed
            mock_s = times[np.linalg.norm(positions - w, axis=1).argmin()]
            client_s = client_t[np.linalg.norm(client_p - w, axis=1).argmin()]
            assert mock_s == pytest.approx(client_s, abs=0.15), vp.vehicle_id
        stopped = [t[np.argmax(np.linalg.norm(p - waypoints[-1], axis=1) < 0.1)] for t, p in
                   ((times, positions), (client_t, client_p))]  # fmt: skip
        assert stopped[0] == pytest.approx(stopped[1], abs=0.15), vp.vehicle_id  # within 10 cm of the end
