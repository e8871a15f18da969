"""SIGTERM (a service manager, a CI runner) and SIGHUP end a flight as Ctrl-C does: every vehicle is
sent home, the log runs on until they have landed, and the report is still written."""

from __future__ import annotations

import asyncio
import os
import signal
from pathlib import Path

import pytest

from gcs_planner.fly import FlyOptions, fly
from gcs_planner.planning import plan_scenario
from gcs_planner.scenario import load_scenario
from gcs_planner.telemetry import read_flight

sitl_mock = pytest.importorskip("sitl_mock")
from sitl_mock.plan_fleet import MockVehicles  # noqa: E402

SCENARIO = Path(__file__).resolve().parents[1] / "missions" / "straight_4uav.toml"


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGHUP])
def test_a_signal_mid_flight_brings_the_fleet_home_and_still_reports(sig, tmp_path):
    scenario = load_scenario(SCENARIO)
    plan = plan_scenario(scenario)
    sent = []

    def progress(stage: str, done, total) -> None:
        if stage == "fly" and not sent:  # the routes are flying
            sent.append(sig)
            os.kill(os.getpid(), sig)

    options = FlyOptions(out_dir=tmp_path, rrd=False)
    vehicles = MockVehicles(plan.vehicles, plan.origin, 20.0, "ardupilot")
    result = asyncio.run(fly(scenario, plan, options, vehicles, progress))
    assert sent and result.interrupted == sig.name and not result.passed
    assert set(result.end_states.values()) == {"landed (disarmed)"}, result.end_states
    assert result.report_path is not None and result.report_path.stat().st_size > 0
    assert all("mission not completed" in r.failures for r in result.reports)
    events = [e for _, e in read_flight(result.mcap_path).events]
    wait = next(e for e in events if e["event"] == "end_wait")
    assert wait["still_armed"] == []
    assert any(e["event"] == "safe_end" for e in events)
    assert signal.getsignal(sig) in (signal.SIG_DFL, signal.default_int_handler)  # handlers removed
