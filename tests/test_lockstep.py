"""One clock (gcs_planner.core.lockstep): a flight against in-process mock vehicles is the same flight
every time, however busy the machine, and a thread's work takes no flight time."""

import asyncio
import subprocess
import sys
import time
from pathlib import Path

import pytest

from gcs_planner.core import lockstep
from gcs_planner.flight import FlyOptions, fly
from gcs_planner.flight.coalition import HilOptions
from gcs_planner.flight.coalition.run import run_coalition_hil
from gcs_planner.flight.vehicles import ConnectedVehicles
from gcs_planner.planning import load_scenario, plan_scenario
from gcs_planner.safety.conformance import format_report
from sitl_mock.plan_fleet import MockVehicles, MockVehiclesProcess

MISSIONS = Path(__file__).resolve().parents[1] / "missions"
HOGS = 2  # busy processes beside the second flight (the machine has 2 cores)


def test_the_clock_jumps_over_idle_time_and_stands_still_while_a_thread_works():
    async def main():
        loop = asyncio.get_running_loop()
        t0 = loop.time()
        await asyncio.sleep(3600.0)
        slept = loop.time() - t0
        t1 = loop.time()
        await asyncio.to_thread(time.sleep, 0.2)  # the coalition planner's work, in a thread
        return slept, loop.time() - t1, lockstep.unix_s() - lockstep.now_s()

    slept, thread_s, offset = lockstep.run(main(), True)
    assert slept == 3600.0 and thread_s == 0.0
    assert offset > 1.7e9  # Unix time of the run: its start plus the virtual time since


def test_vehicles_and_loop_must_agree_on_the_clock(tmp_path):
    scenario = load_scenario(MISSIONS / "straight_4uav.toml")
    plan = plan_scenario(scenario)
    options = FlyOptions(out_dir=tmp_path, rrd=False)
    mocks = MockVehicles(plan.vehicles, plan.origin)
    with pytest.raises(RuntimeError, match="on a LockstepLoop"):
        asyncio.run(fly(scenario, plan, options, mocks))
    real = ConnectedVehicles(["udpout:127.0.0.1:9"])  # on a virtual clock, real time would race away
    with pytest.raises(RuntimeError, match="on the wall clock"):
        lockstep.run(fly(scenario, plan, options, real), True)
    assert not (tmp_path / "flight.mcap").exists()


def _hogs():
    return [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(HOGS)]


def _stop(hogs) -> None:
    for hog in hogs:
        hog.kill()
        hog.wait()


def _fly_rows(tmp_path: Path) -> tuple[str, list]:
    scenario = load_scenario(MISSIONS / "swarm_small.toml")
    plan = plan_scenario(scenario)
    vehicles = MockVehicles(plan.vehicles, plan.origin)
    result = lockstep.run(fly(scenario, plan, FlyOptions(out_dir=tmp_path, rrd=False), vehicles), True)
    return format_report(result.reports), result.reports


def test_the_demo_flight_is_the_same_on_an_idle_and_a_loaded_machine(tmp_path):
    idle_rows, idle = _fly_rows(tmp_path / "idle")
    hogs = _hogs()
    try:
        busy_rows, busy = _fly_rows(tmp_path / "busy")
    finally:
        _stop(hogs)
    assert busy_rows == idle_rows
    assert repr(busy) == repr(idle)  # every field at full precision (repr: a NaN equals a NaN)
    assert all(r.passed for r in idle), idle_rows


def test_a_coalition_run_is_the_same_on_an_idle_and_a_loaded_machine(tmp_path):
    """T1's awards planned live in a thread while the planes fly: the clock waits for the planner."""
    scenario = load_scenario(MISSIONS / "coalition_paper.toml")

    def rows(out: Path):
        options = HilOptions(out_dir=out, targets=("T1",))
        result = lockstep.run(run_coalition_hil(scenario, options, MockVehiclesProcess), True)
        return result.rows, [{k: v for k, v in u.items() if k != "plan_wall_ms"} for u in result.uploads]

    idle = rows(tmp_path / "idle")
    hogs = _hogs()
    try:
        busy = rows(tmp_path / "busy")
    finally:
        _stop(hogs)
    assert repr(busy) == repr(idle)  # every field at full precision (repr: a NaN equals a NaN)
    assert idle[0] and all(r.passed for r in idle[0]), idle[0]
