"""The mission commands end to end: export, and upload / download / clear / start against a real mock
vehicle over UDP on 127.0.0.1; user mistakes are one line on stderr with exit code 2."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from gcs_planner.cli import main
from gcs_planner.geo import Origin
from gcs_planner.mavlink.files import load_mission_file
from gcs_planner.mavlink.items import plan_to_items
from gcs_planner.plan import Plan, VehiclePlan

ORIGIN = Origin(47.397742, 8.545594, 488.0)
SCENARIO = """
name = "cli"
[origin]
lat_deg = 47.397742
lon_deg = 8.545594
alt_m = 488.0
[planner]
name = "straight"
[[vehicles]]
id = "a"
sysid = 1
start = [0.0, 0.0, 0.0]
goal = [200.0, 0.0, 20.0]
[[obstacles.cylinders]]
x = 100.0
y = 40.0
radius_m = 10.0
z_max_m = 50.0
[bounds]
x = [-50.0, 300.0]
y = [-100.0, 100.0]
"""


def make_plan(tmp_path: Path, sysids=(1, 2)) -> Path:
    vehicles = []
    for sysid in sysids:
        wps = np.array([[0.0, 10.0 * sysid, 0.0], [80.0, 10.0 * sysid, 20.0], [160.0, 10.0 * sysid, 25.0]])
        times = np.array([0.0, 8.0, 16.0])
        speeds = np.array([0.0, 10.0, 10.0])
        vehicles.append(VehiclePlan(f"uav{sysid}", sysid, wps, times, speeds, wps, times))
    path = tmp_path / "plan.json"
    Plan(ORIGIN, "test", vehicles).save(path)
    return path


def test_export_qgc_and_wpl(tmp_path, capsys):
    plan_path = make_plan(tmp_path)
    scenario = tmp_path / "s.toml"
    scenario.write_text(SCENARIO)
    out = tmp_path / "out"
    assert main(["export", str(plan_path), "--scenario", str(scenario), "-o", str(out)]) == 0
    table = capsys.readouterr().out
    assert "uav1" in table and "uav2" in table and "uav1.plan" in table
    plan = Plan.load(plan_path)
    mf = load_mission_file(out / "uav2.plan")
    assert mf.items("ardupilot") == plan_to_items(plan.vehicles[1], ORIGIN, "ardupilot")
    assert len(mf.fence) == 5 and len(mf.rally) == 1  # 4 bound vertices + 1 cylinder; 1 vehicle start
    assert main(["export", str(plan_path), "--format", "wpl", "--autopilot", "px4", "--vehicle", "uav1",
                 "-o", str(out)]) == 0  # fmt: skip
    assert load_mission_file(out / "uav1.waypoints", autopilot="px4").items("px4") == plan_to_items(
        plan.vehicles[0], ORIGIN, "px4"
    )
    assert not (out / "uav2.waypoints").exists()


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["export", "{tmp}/missing.json"], "no such file"),
        (["export", "{plan}", "--vehicle", "ghost"], "'ghost' is not in the plan"),
        (["export", "{plan}", "--format", "wpl", "--scenario", "{tmp}/s.toml"], "needs --format qgc"),
    ],
)
def test_export_errors_are_one_line(tmp_path, capsys, argv, message):
    plan_path = make_plan(tmp_path)
    argv = [a.format(tmp=tmp_path, plan=plan_path) for a in argv]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1 and "Traceback" not in err


def test_cli_error_in_a_real_process_has_no_traceback(tmp_path):
    bad = tmp_path / "bad.waypoints"
    bad.write_text("QGC WPL 110\n0\t1\t0\t16\t0\t0\t0\t0\t91.0\t8.5\t10\n")
    proc = subprocess.run(
        [sys.executable, "-m", "gcs_planner.cli", "export", str(bad)],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert proc.returncode == 2 and "Traceback" not in proc.stderr and proc.stderr.count("\n") == 1
