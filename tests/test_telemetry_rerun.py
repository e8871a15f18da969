"""Rerun views (issue 34): the ``flight`` timeline counts seconds of flight, every .rrd is its own
recording, the events are in the default layout, ``replay --viewer`` refuses without a display,
``--serve-web`` serves on free ports."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from telemetry_frames import ORIGIN, SCENARIO_TEXT, flight_frames, make_plan

from gcs_planner.cli import main
from gcs_planner.telemetry import FlightLogger, read_flight

SCENARIO = Path(__file__).resolve().parents[1] / "missions" / "straight_4uav.toml"
T0_S = 1.7e9


def _timeline_span_s(rrd: Path) -> float:
    """Span [s] of the ``flight`` timeline over every temporal chunk of the .rrd's recording."""
    from rerun.chunk import RrdReader

    lo, hi = np.inf, -np.inf
    for chunk in RrdReader(rrd).stream():
        if chunk.is_static or "flight" not in chunk.timeline_names:
            continue
        t_ns = chunk.to_record_batch().column("flight").cast("int64").to_numpy()
        lo, hi = min(lo, t_ns.min()), max(hi, t_ns.max())
    return (hi - lo) * 1e-9


def _boot_span_s(flight) -> float:
    """Span [s] of the vehicles' own clocks over the log (time_boot_ms of every GLOBAL_POSITION_INT,
    those before a position fix included): the flight time it covers."""
    boot_s = [fields["time_boot_ms"] * 1e-3 for _, _, fields in flight.messages("GLOBAL_POSITION_INT")]
    return max(boot_s) - min(boot_s)


def _log(path: Path, slowdown: float = 1.0, clock_rate: float | None = None, samples: int = 100) -> Path:
    """Three vehicles at 10 Hz of their own clocks; receive times run at 1/``slowdown`` of them
    (``slowdown`` 10: frames stamped with the wall time of a fleet flown at speed-up 10)."""
    with FlightLogger(path, ORIGIN, make_plan([1, 2, 3]), SCENARIO_TEXT, clock_rate=clock_rate) as logger:
        for msg, raw, t_s in flight_frames([1, 2, 3], samples=samples, t0_s=T0_S):
            logger.on_frame(msg, raw, T0_S + (t_s - T0_S) / slowdown)
        logger.log_event({"event": "end"}, t_s=T0_S + (t_s - T0_S) / slowdown)
    return path


def test_paced_flight_at_speedup_10_gives_an_rrd_timeline_in_flight_time(tmp_path):
    """`fly --speedup 10` against the mock: frames carry wall time, so a second of log time is ten
    of flight; the .rrd's timeline spans the flight time, not a tenth of it."""
    code = main(["fly", str(SCENARIO), "--speedup", "10", "-o", str(tmp_path)])
    assert code == 0
    flight = read_flight(tmp_path / "flight.mcap")
    assert flight.metadata["gcs_planner"]["clock_rate"] == "10.0" and flight.clock_rate == 10.0
    flight_s = _boot_span_s(flight)
    assert flight_s > 100.0  # ~140 s of flight (10 s of it before the mock's position fix)
    span_s = _timeline_span_s(tmp_path / "flight.rrd")
    assert span_s == pytest.approx(flight_s, rel=0.1)
    assert span_s > 5 * (flight.end_time_s - flight.start_time_s)  # log (wall) time is a tenth


def test_lockstep_flight_records_clock_rate_1(tmp_path):
    """In lockstep the log's receive time already is flight time: rate 1, recorded."""
    from gcs_planner.core import lockstep
    from gcs_planner.flight import FlyOptions, fly
    from gcs_planner.planning import load_scenario, plan_scenario
    from sitl_mock.plan_fleet import MockVehicles

    scenario = load_scenario(SCENARIO)
    plan = plan_scenario(scenario)
    vehicles = MockVehicles(plan.vehicles, plan.origin, None)
    result = lockstep.run(fly(scenario, plan, FlyOptions(out_dir=tmp_path), vehicles), vehicles.lockstep)
    flight = read_flight(result.mcap_path)
    assert flight.metadata["gcs_planner"]["clock_rate"] == "1.0"
    assert _timeline_span_s(result.rrd_path) == pytest.approx(_boot_span_s(flight), rel=0.1)


def test_clock_rate_metadata_first_then_time_boot_then_1(tmp_path):
    assert read_flight(_log(tmp_path / "real.mcap")).clock_rate == 1.0
    # no metadata (an older log, watch): the vehicles' time_boot_ms against the receive time
    old = read_flight(_log(tmp_path / "old.mcap", slowdown=10.0))
    assert "clock_rate" not in old.metadata["gcs_planner"]
    assert old.clock_rate == pytest.approx(10.0, rel=0.01)
    # recorded: taken as it is
    assert read_flight(_log(tmp_path / "rec.mcap", slowdown=10.0, clock_rate=10.0)).clock_rate == 10.0
    # no position reports: 1
    with FlightLogger(tmp_path / "empty.mcap", ORIGIN):
        pass
    assert read_flight(tmp_path / "empty.mcap").clock_rate == 1.0


def test_rrd_and_live_replay_timelines_of_an_old_paced_log_count_flight_seconds(tmp_path):
    import rerun as rr

    from gcs_planner.telemetry.replay import replay_to_rerun_live

    path = _log(tmp_path / "flight.mcap", slowdown=10.0)
    flight = read_flight(path)
    flight_s = _boot_span_s(flight)
    assert flight_s == pytest.approx(9.9)
    rrd = tmp_path / "replay.rrd"
    assert main(["replay", str(path), "--rrd", str(rrd)]) == 0
    assert _timeline_span_s(rrd) == pytest.approx(flight_s, rel=0.02)
    live = tmp_path / "live.rrd"
    rec = rr.RecordingStream("gcs-planner", recording_id="live-timeline-test")
    rec.save(str(live))
    replay_to_rerun_live(flight, rec, speed=0)
    rec.flush()
    rec.disconnect()
    assert _timeline_span_s(live) == pytest.approx(flight_s, rel=0.02)


def test_every_rrd_is_a_recording_of_its_own(tmp_path):
    """Two replays of one log, and the logs of two runs, get different recording ids."""
    from rerun.chunk import RrdReader

    a, b = _log(tmp_path / "a.mcap"), _log(tmp_path / "b.mcap")
    rrds = [tmp_path / f"{k}.rrd" for k in range(3)]
    for log_path, rrd in zip((a, a, b), rrds, strict=True):
        assert main(["replay", str(log_path), "--rrd", str(rrd)]) == 0
    ids = [RrdReader(rrd).recordings()[0].recording_id for rrd in rrds]
    assert len(set(ids)) == 3
    assert ids[0].startswith("a.mcap-") and ids[2].startswith("b.mcap-")


def test_default_blueprint_has_a_text_log_view_of_the_events(tmp_path):
    import rerun.blueprint as rrb

    from gcs_planner.telemetry.rerun_views import EVENTS, flight_blueprint

    def views(item):
        if isinstance(item, rrb.Container):
            for child in item.contents:
                yield from views(child)
        else:
            yield item

    found = list(views(flight_blueprint().root_container))
    assert [(v.class_identifier, v.origin) for v in found if v.class_identifier == "TextLog"] == [
        ("TextLog", EVENTS)
    ]
    assert EVENTS == "events"  # the entity FlightViews.log_event writes to


def test_replay_viewer_without_a_display_is_refused_in_one_line(tmp_path, monkeypatch, capsys):
    import rerun as rr

    import gcs_planner.commands._viewer as viewer

    spawned = []
    monkeypatch.setattr(rr.RecordingStream, "spawn", lambda *a, **k: spawned.append(1))
    monkeypatch.setattr(viewer.sys, "platform", "linux")
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    path = _log(tmp_path / "flight.mcap", samples=10)
    assert main(["replay", str(path), "--viewer"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "--viewer needs a display" in err and "--rrd FILE" in err
    assert "--serve-web" in err and spawned == []
    monkeypatch.setenv("WAYLAND_DISPLAY", "wayland-0")
    viewer.check_display("--viewer")  # a display: no refusal
    monkeypatch.delenv("WAYLAND_DISPLAY")
    fly = ["fly", str(SCENARIO), "--live", "-o", str(tmp_path / "fly")]
    watch = ["watch", "--connect", "udpin:127.0.0.1:0", "--live", "-o", str(tmp_path / "watch")]
    for argv in (fly, watch):
        assert main(argv) == 2, argv
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and "--live needs a display" in err, err
        assert not (tmp_path / argv[-1].rpartition("/")[2]).exists()  # refused before anything is written
    assert spawned == []


def test_serve_web_chooses_free_ports_and_prints_the_url(monkeypatch, capsys):
    """No viewer is started: Rerun's two servers are replaced by recorders of their ports."""
    import socket

    import rerun as rr

    from gcs_planner.commands._viewer import free_ports, live_recording

    ports = free_ports(2)
    assert len(set(ports)) == 2 and all(0 < p < 65536 for p in ports)
    for port in ports:  # free: a server can bind it
        with socket.socket() as sock:
            sock.bind(("127.0.0.1", port))
    served = {}

    def serve_grpc(self, grpc_port=None, default_blueprint=None, **kw):
        served["grpc"] = grpc_port
        return f"rerun+http://127.0.0.1:{grpc_port}/proxy"

    monkeypatch.setattr(rr.RecordingStream, "serve_grpc", serve_grpc)
    monkeypatch.setattr(rr, "serve_web_viewer", lambda **kw: served.update(web=kw["web_port"]))
    rec = live_recording(spawn=False, serve_web=True)
    assert rec is not None
    grpc_port, web_port = served["grpc"], served["web"]
    assert grpc_port != web_port and not {grpc_port, web_port} & {0, 9090, 9876}
    out = capsys.readouterr().out
    assert f"http://localhost:{web_port}/?url=rerun%2Bhttp%3A%2F%2F127.0.0.1%3A{grpc_port}%2Fproxy" in out


@pytest.mark.parametrize(
    "name", sorted(p.stem for p in (Path(__file__).resolve().parents[1] / "missions").glob("*.toml"))
)
def test_every_bundled_scenario_attachment_is_drawn(name, caplog):
    """A log's scenario attachment is parsed with its planner's own tables (a coalition's targets,
    4-D traffic): replaying a coalition or 4-D flight draws its world, not a warning."""
    from gcs_planner.telemetry.rerun_views import scenario_from_text

    text = (Path(__file__).resolve().parents[1] / "missions" / f"{name}.toml").read_text()
    scenario = scenario_from_text(text)
    assert scenario is not None and scenario.vehicles, caplog.text
    assert "not drawn" not in caplog.text
