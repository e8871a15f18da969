"""A full disk or a read-only folder ends import-log, replay --rrd, sweep and the flight report in
one line naming the path and the OS reason (exit 2), and leaves no partial file at the output."""

from __future__ import annotations

import builtins
import errno
import os
from pathlib import Path

import matplotlib.figure
import pytest
from telemetry_frames import flight_frames

from gcs_planner.cli import main
from gcs_planner.core.errors import UserError

MISSIONS = Path(__file__).resolve().parents[1] / "missions"
as_root = pytest.mark.skipif(os.geteuid() == 0, reason="root writes into a read-only folder")


class FullDisk:
    """A file that takes ``room`` bytes, then fails as a full disk does (ENOSPC), mid-write."""

    def __init__(self, f, room: int) -> None:
        self.f, self.room = f, room

    def write(self, data) -> int:
        n = min(len(data), self.room)
        self.f.write(data[:n])
        self.room -= n
        if n < len(data):
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        return n

    def __getattr__(self, name):
        return getattr(self.f, name)

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        self.f.close()


def full_disk_open(room: int, suffix: str):
    """An ``open`` whose files for writing, named ``*suffix``, hold ``room`` bytes."""

    def fake(file, mode="r", *args, **kwargs):
        f = builtins.open(file, mode, *args, **kwargs)  # noqa: SIM115 - the caller closes it
        return FullDisk(f, room) if str(file).endswith(suffix) and mode[0] in "wax" else f

    return fake


def one_line(capsys, *words) -> str:
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    for word in words:
        assert word in err[0], err[0]
    return err[0]


def leftovers(folder: Path, keep: set[str]) -> list[str]:
    return sorted(p.name for p in folder.iterdir() if p.name not in keep)


@pytest.fixture
def tlog(tmp_path) -> Path:
    rows = [(round(t * 1e6) & ~3, raw) for _, raw, t in flight_frames([1, 2], samples=40)]
    path = tmp_path / "in" / "f.tlog"
    path.parent.mkdir()
    path.write_bytes(b"".join(t_us.to_bytes(8, "big") + raw for t_us, raw in rows))
    return path


@pytest.fixture
def mcap(tmp_path, tlog) -> Path:
    out = tmp_path / "in" / "f.mcap"
    assert main(["import-log", str(tlog), "-o", str(out)]) == 0
    return out


def test_import_log_on_a_full_disk_is_one_line_and_leaves_nothing(tmp_path, tlog, capsys, monkeypatch):
    import gcs_planner.telemetry.mcap_writer as mcap_writer

    monkeypatch.setattr(mcap_writer, "open", full_disk_open(300, ".part"), raising=False)
    out = tmp_path / "o" / "f.mcap"
    out.parent.mkdir()
    assert main(["import-log", str(tlog), "-o", str(out)]) == 2
    one_line(capsys, str(out), "No space left on device")
    assert leftovers(out.parent, set()) == []


def test_replay_rrd_on_a_full_disk_is_one_line_and_leaves_nothing(tmp_path, mcap, capsys, monkeypatch):
    import gcs_planner.telemetry.rerun_views as rerun_views

    monkeypatch.setattr(rerun_views, "open", full_disk_open(1000, ".rrd"), raising=False)
    out = tmp_path / "o" / "f.rrd"
    out.parent.mkdir()
    capsys.readouterr()
    assert main(["replay", str(mcap), "--rrd", str(out)]) == 2
    one_line(capsys, str(out), "No space left on device")
    assert leftovers(out.parent, set()) == []


def _report(path: Path):
    from test_flight_report import plan_and_tracks

    from gcs_planner.analysis.flight_report import write_flight_report
    from gcs_planner.safety.conformance import conformance_report

    plan, tracks = plan_and_tracks(0.0)
    reports = conformance_report(plan, tracks, {1: 5.0, 2: 5.0}, [], [], max_cross_track_m=10.0)
    return write_flight_report(path, plan, tracks, reports, max_cross_track_m=10.0)


def test_flight_report_on_a_full_disk_leaves_no_partial_png(tmp_path, monkeypatch):
    real = matplotlib.figure.Figure.savefig

    def savefig(self, fname, *args, **kwargs):
        real(self, fname, *args, **kwargs)  # the bytes are there, then the disk is full
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(matplotlib.figure.Figure, "savefig", savefig)
    with pytest.raises(UserError) as err:  # fly's result() lets it through: the CLI's one line, exit 2
        _report(tmp_path / "report.png")
    assert str(tmp_path / "report.png") in str(err.value) and "No space left" in str(err.value)
    assert "\n" not in str(err.value)
    assert leftovers(tmp_path, set()) == []


@as_root
def test_flight_report_in_a_read_only_folder_is_one_line(tmp_path):
    folder = tmp_path / "ro"
    folder.mkdir(mode=0o500)
    with pytest.raises(UserError, match="Permission denied"):
        _report(folder / "report.png")
    assert leftovers(folder, set()) == []


@as_root
def test_import_log_into_a_read_only_folder_is_one_line(tmp_path, tlog, capsys):
    folder = tmp_path / "ro"
    folder.mkdir(mode=0o500)
    assert main(["import-log", str(tlog), "-o", str(folder / "f.mcap")]) == 2
    one_line(capsys, str(folder / "f.mcap"), "Permission denied")
    assert leftovers(folder, set()) == []


@as_root
def test_replay_rrd_into_a_read_only_folder_is_one_line(tmp_path, mcap, capsys):
    folder = tmp_path / "ro"
    folder.mkdir(mode=0o500)
    capsys.readouterr()
    assert main(["replay", str(mcap), "--rrd", str(folder / "f.rrd")]) == 2
    one_line(capsys, str(folder / "f.rrd"), "Permission denied")
    assert leftovers(folder, set()) == []


def _study(tmp_path: Path) -> Path:
    path = tmp_path / "study.toml"
    path.write_text(
        f'name = "t"\nscenario = "{MISSIONS / "straight_4uav"}.toml"\nseeds = [0]\n'
        'metrics = ["feasible_fraction"]\n[grid]\nwaypoint_spacing_m = [50.0, 100.0]\n'
    )
    return path


def test_sweep_results_csv_on_a_full_disk_is_one_line(tmp_path, capsys, monkeypatch):
    import pathlib

    real = pathlib.Path.open
    out = tmp_path / "o" / "r.csv"
    out.parent.mkdir()

    def fake(self, mode="r", *args, **kwargs):
        f = real(self, mode, *args, **kwargs)
        return FullDisk(f, 20) if self == out and mode[0] == "a" else f

    monkeypatch.setattr(pathlib.Path, "open", fake)
    assert main(["sweep", str(_study(tmp_path)), "-o", str(out), "--workers", "1"]) == 2
    one_line(capsys, str(out), "No space left on device")
    assert leftovers(out.parent, {"r.csv"}) == []  # the rows written so far stay: a rerun resumes


def test_sweep_summary_on_a_full_disk_leaves_no_partial_file(tmp_path, capsys, monkeypatch):
    import pathlib

    real = pathlib.Path.write_text

    def write_text(self, data, *args, **kwargs):
        real(self, data[: len(data) // 2], *args, **kwargs)
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    study = _study(tmp_path)
    monkeypatch.setattr(pathlib.Path, "write_text", write_text)
    out = tmp_path / "o" / "r.csv"
    out.parent.mkdir()
    assert main(["sweep", str(study), "-o", str(out), "--workers", "1"]) == 2
    one_line(capsys, "r_summary.csv", "No space left on device")
    assert leftovers(out.parent, {"r.csv"}) == []


def test_sweep_plots_on_a_full_disk_leave_no_partial_png(tmp_path, monkeypatch):
    from gcs_planner.analysis.sweep import load_study, run_study
    from gcs_planner.analysis.sweep_plots import write_plots

    study, base = load_study(_study(tmp_path))
    out = tmp_path / "r.csv"
    run_study(study, base, out, workers=1)
    real = matplotlib.figure.Figure.savefig

    def savefig(self, fname, *args, **kwargs):
        real(self, fname, *args, **kwargs)
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(matplotlib.figure.Figure, "savefig", savefig)
    with pytest.raises(UserError, match="No space left on device"):
        write_plots(study, out, tmp_path / "p.png")
    assert leftovers(tmp_path, {"r.csv", "study.toml"}) == []
