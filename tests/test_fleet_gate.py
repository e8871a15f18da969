"""The pre-flight gate of `fly --connect`: vehicles that are not at their planned starts, or whose
clocks run at another rate than the flight's, are refused before anything is armed."""

from __future__ import annotations

import re
import signal
import subprocess
import sys
from pathlib import Path

import pytest
from ports import free_port_run

from gcs_planner.cli import main
from gcs_planner.flight.limits import planned_vertical_mps
from gcs_planner.flight.starts import starts
from gcs_planner.model.plan import Plan
from gcs_planner.planning import load_scenario, plan_scenario

sitl_mock = pytest.importorskip("sitl_mock")

SCENARIO = Path(__file__).resolve().parents[1] / "missions" / "straight_4uav.toml"
FAST = {"arm_ready_s": 0, "position_fix_s": 0}


def connect_args(fleet) -> list[str]:
    return [arg for v in fleet.vehicles for arg in ("--connect", f"udpout:{v.address[0]}:{v.address[1]}")]


def nothing_armed_or_uploaded(fleet) -> bool:
    def look():
        return all(not v.armed and len(v.mission_server.items()) <= 1 for v in fleet.vehicles)

    return fleet.call(look)


def test_vehicles_sharing_one_home_are_refused_one_line_each_before_anything_is_sent(tmp_path, capsys):
    """The README's old recipe: four mocks on one spot. Vehicle 1 stands at its start; 2-4 are 30,
    60 and 90 m from theirs (bound 5 m) and would have taken off into each other."""
    plan = plan_scenario(load_scenario(SCENARIO))
    with sitl_mock.MockFleet(count=4, home=starts(plan.vehicles, plan.origin)[0].home, speedup=10,
                             flight=FAST) as fleet:  # fmt: skip
        argv = ["fly", str(SCENARIO), *connect_args(fleet), "-o", str(tmp_path / "out")]
        assert main(argv) == 2
        assert nothing_armed_or_uploaded(fleet)
    err = capsys.readouterr().err
    for sysid, off in ((2, 30.0), (3, 60.0), (4, 90.0)):
        assert f"sysid {sysid} (uav{sysid}) is {off:.1f} m from its start" in err
    assert "sysid 1 " not in err and "--homes" in err and "Traceback" not in err


def test_a_mock_at_another_speedup_is_refused_before_arming(tmp_path, capsys):
    plan = plan_scenario(load_scenario(SCENARIO))
    homes = [{"home": s.home} for s in starts(plan.vehicles, plan.origin)]
    with sitl_mock.MockFleet(vehicles=homes, speedup=5, flight=FAST) as fleet:
        assert main(["fly", str(SCENARIO), *connect_args(fleet), "-o", str(tmp_path / "out")]) == 2
        assert fleet.call(lambda: not any(v.armed for v in fleet.vehicles))
    err = capsys.readouterr().err
    assert "do not run at the flight's 1x real time" in err and "restart it at 1x" in err, err
    rates = [float(r) for r in re.findall(r"sysid \d runs at ([\d.]+)x", err)]
    assert len(rates) == 4 and all(2.0 < r <= 5.5 for r in rates), err  # a busy mock may slip below 5


def test_the_readme_recipe_sitl_mock_at_the_plans_starts_then_fly_connect_passes(tmp_path, capsys):
    """`sitl-mock --homes` stands each vehicle where `fly --homes` says, as SITL's --home, so `fly
    --connect` to it passes the gate (the old recipe put four vehicles on one spot); a privileged
    --base-port is refused."""
    from child_process import child

    plan_path, homes_path = tmp_path / "plan.json", tmp_path / "homes.txt"
    assert main(["plan", str(SCENARIO), "-o", str(plan_path)]) == 0
    capsys.readouterr()
    assert main(["fly", str(SCENARIO), "--plan", str(plan_path), "--homes"]) == 0
    homes_path.write_text(capsys.readouterr().out)
    base = free_port_run(4)
    cli = [sys.executable, "-m", "sitl_mock.cli", "--homes", str(homes_path), "--base-port", str(base),
           "--profile", "px4", "--speedup", "10"]  # fmt: skip
    with child(cli, stderr=subprocess.DEVNULL) as mock:
        argv = ["fly", str(SCENARIO), "--plan", str(plan_path), "--speedup", "10",
                "-o", str(tmp_path / "out"), "--connect", f"udpout:127.0.0.1:{base}-{base + 3}"]  # fmt: skip
        rc = main(argv)
        mock.send_signal(signal.SIGINT)
        mock.wait(timeout=30)
    out = capsys.readouterr().out
    assert rc == 0 and "PASS: 4/4 vehicles conform" in out, out
    refused = subprocess.run([*cli[:3], "--base-port", "80"], capture_output=True, text=True)
    assert refused.returncode == 2 and "privileged" in refused.stderr
    bad = tmp_path / "bad.txt"  # a typo in the first line's --home
    bad.write_text(homes_path.read_text().replace(",", ";", 1))
    refused = subprocess.run([*cli[:3], "--homes", str(bad)], capture_output=True, text=True)
    first = bad.read_text().splitlines()[0].split("  ")[0]  # "sysid 1 (uav1): --home LAT;LON,ALT,HDG"
    error = f"sitl-mock: error: --homes {bad} line 1 ({first}): could not convert string to float"
    assert refused.returncode == 2 and refused.stderr.splitlines()[-1].startswith(error), refused.stderr
    assert "Traceback" not in refused.stderr and refused.stderr.count("error:") == 1, refused.stderr


@pytest.mark.parametrize(
    ("profile", "limits"),
    [("ardupilot", "WP_SPD_(UP is 2.5|DN is 1.5)"), ("px4", "MPC_Z_V_AUTO_(UP is 3|DN is 1.5)")],
)
def test_a_plan_climbing_faster_than_the_autopilot_will_is_refused_before_anything_is_sent(
    tmp_path, capsys, profile, limits
):
    """swarm_small climbs and descends its 20-degree legs at up to 3-3.4 m/s; stock ArduCopter
    climbs at most 2.5 m/s in a mission and descends 1.5 m/s (PX4: 3 and 1.5), slowing over ground
    to keep to them (ArduCopter SITL flew four of five vehicles 18-31 s late). Stock mocks, which
    fly the same limits, are refused in one line before anything is sent."""
    scenario = Path(__file__).resolve().parents[1] / "missions" / "swarm_small.toml"
    plan = plan_scenario(load_scenario(scenario))
    plan.save(tmp_path / "plan.json")
    for vp, saved in zip(plan.vehicles, Plan.load(tmp_path / "plan.json").vehicles, strict=True):
        assert planned_vertical_mps(saved) == pytest.approx(planned_vertical_mps(vp), abs=0.01)  # rounding
    homes = [{"home": s.home, "profile": profile} for s in starts(plan.vehicles, plan.origin)]
    with sitl_mock.MockFleet(vehicles=homes, speedup=10, flight=FAST) as fleet:
        argv = ["fly", str(scenario), "--plan", str(tmp_path / "plan.json"), *connect_args(fleet),
                "--speedup", "10", "-o", str(tmp_path / "out")]  # fmt: skip
        assert main(argv) == 2
        assert nothing_armed_or_uploaded(fleet)
        stock = {
            "ardupilot": {"WP_SPD_UP": 2.5, "WP_SPD_DN": 1.5},
            "px4": {"MPC_Z_V_AUTO_UP": 3.0, "MPC_Z_V_AUTO_DN": 1.5},
        }
        served = fleet.call(lambda: {n: fleet.vehicle(1).params[n] for n in stock[profile]})
        assert served == stock[profile]  # the autopilots' defaults, which the mock flies
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "Traceback" not in err[0] and "safe end" not in err[0], err  # nothing to end
    line = rf"\(sysid \d\): {limits} m/s, but the plan (climbs|descends) at up to [23]\.\d\d m/s; raise it"
    assert re.search(line, err[0]), err[0]
    assert main(["fly", str(scenario), "--plan", str(tmp_path / "plan.json"), "--homes"]) == 0
    homes = capsys.readouterr()  # what to start a SITL with: the homes on stdout, the limits on stderr
    assert len(homes.out.splitlines()) == len(plan.vehicles)
    assert re.search(r"descends at up to 2\.\d\d m/s \(uav\d\); set WP_SPD_UP / WP_SPD_DN", homes.err), (
        homes.err
    )


def test_short_legs_arducopter_flies_late_are_refused_and_fly_with_the_values_offered(tmp_path, capsys):
    """swarm_small on mock ArduCopters that fly their legs as ArduCopter does (``scurve_legs``: the
    mock's own port of SCurve.cpp) at stock WP_ACC 2.5 / WP_JERK 1, with the climb it needs: SITL
    flew its ~45 m legs at 7.7 m/s and one vehicle 4.0 s late (docs/real-autopilots.md). The
    parameters are read from the vehicles, the legs flown in advance, and the flight refused; the
    values offered, set over MAVLink (`params set`), fly it."""
    scenario = Path(__file__).resolve().parents[1] / "missions" / "swarm_small.toml"
    plan = plan_scenario(load_scenario(scenario))
    homes = [{"home": s.home} for s in starts(plan.vehicles, plan.origin)]
    with sitl_mock.MockFleet(vehicles=homes, speedup=10, flight={**FAST, "scurve_legs": True}) as fleet:
        served = fleet.call(lambda: [(v.params["WP_ACC"], v.params["WP_JERK"]) for v in fleet.vehicles])
        assert served == [(2.5, 1.0)] * len(homes)  # ArduCopter's stock values, which they fly by
        fleet.call(lambda: [v.params.update(WP_SPD_UP=4.0, WP_SPD_DN=4.0) for v in fleet.vehicles])
        argv = ["fly", str(scenario), *connect_args(fleet), "--speedup", "10", "-o", str(tmp_path / "out")]
        assert main(argv) == 2
        assert nothing_armed_or_uploaded(fleet)
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and "Traceback" not in err[0], err
        assert re.search(r"with WP_ACC 2\.5 and WP_JERK 1 its short legs never reach their speed", err[0]), (
            err[0]
        )
        offered = re.search(r"WP_ACC ([\d.]+) and WP_JERK ([\d.]+) predict \d\.\d s", err[0])
        assert offered, err[0]
        values = tmp_path / "offered.parm"
        values.write_text(f"WP_ACC,{offered[1]}\nWP_JERK,{offered[2]}\n")
        for vehicle, address in zip(fleet.vehicles, connect_args(fleet)[1::2], strict=True):
            assert (
                main(["params", "set", str(values), "--connect", address, "--sysid", str(vehicle.sysid)]) == 0
            )
        assert main(argv) == 0
        assert "PASS: 5/5 vehicles conform" in capsys.readouterr().out
    assert main(["fly", str(scenario), "--homes"]) == 0  # what to start a SITL fleet with
    note = capsys.readouterr().err
    stock = r"stock WP_ACC 2\.5 / WP_JERK 1 the plan's short legs put uav\d \d\.\d s late \(bound 3 s\)"
    offered = r"; set WP_ACC ([\d.]+) and WP_JERK ([\d.]+) \(fly checks them; `fly --mock-legs scurve"
    offered += r" --mock-param WP_ACC=\1 --mock-param WP_JERK=\2` flies that on mock ArduCopters\)"
    assert re.search(stock + offered, note), note
