"""import-log on the real logs of ../shared/corpus/logs (MANIFEST.tsv names their sources): the
format is told by the bytes, every record the format's own reader sees is in the MCAP (read back
with the stock mcap reader), positions reach the LocationFix channel and Rerun, junk is one line."""

from __future__ import annotations

import os
import shutil
from collections import Counter
from pathlib import Path

import pytest
from mcap.reader import make_reader

from gcs_planner.cli import main
from gcs_planner.telemetry.tlog import iter_tlog

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import DFReader  # noqa: E402

LOGS = (
    Path(os.environ.get("GCS_PLANNER_CORPUS", Path(__file__).resolve().parents[2] / "shared" / "corpus"))
    / "logs"
)
pytestmark = pytest.mark.skipif(not LOGS.is_dir(), reason=f"no corpus logs at {LOGS}")


def channel_counts(path: Path) -> Counter:
    with open(path, "rb") as f:
        return Counter(channel.topic for _, channel, _ in make_reader(f).iter_messages())


def imported(tmp_path: Path, source: Path, name: str = "in.log") -> tuple[Path, str]:
    """Copy ``source`` under a neutral name (the format must come from the bytes) and import it."""
    log = tmp_path / name
    shutil.copy(source, log)
    out = tmp_path / "out.mcap"
    assert main(["import-log", str(log), "-o", str(out)]) == 0
    return out, log.name


def test_dataflash_bin_records_match_dfreader(tmp_path, capsys):
    source = LOGS / "pymavlink/test.BIN"
    reader = DFReader.DFReader_binary(str(source), zero_time_base=False)
    expected, fixes = Counter(), 0
    while (m := reader.recv_msg()) is not None:
        expected[m.get_type()] += 1
        fixes += m.get_type() == "GPS" and m.Status >= 3
    out, _ = imported(tmp_path, source, "flight.tlog")  # a misleading name: still DataFlash
    assert "dataflash, 1731 records" in capsys.readouterr().out
    counts = channel_counts(out)
    assert {
        t.removeprefix("/dataflash/"): n for t, n in counts.items() if t.startswith("/dataflash/")
    } == expected
    assert counts["/vehicle/1/location"] == fixes > 0
    assert not any(
        t.startswith("/mavlink/") and t.split("/")[2] not in ("1",) for t in counts
    )  # no fake vehicles


def test_a_dataflash_record_with_a_damaged_time_is_skipped_and_said(tmp_path, caplog):
    """An ATT record whose TimeUS reads 2^64 - 1 (its Unix time past the year 2100; a mutated log
    once ended the import with a struct error): the rest is imported, the loss said once."""
    source = LOGS / "pymavlink/test.BIN"
    reader = DFReader.DFReader_binary(str(source), zero_time_base=False)
    att = reader.name_to_id["ATT"]
    data = bytearray(source.read_bytes())
    ofs = reader.offsets[att][5]
    data[ofs + 3 : ofs + 11] = b"\xff" * 8  # the first field after the 3-byte header: TimeUS (Q)
    (tmp_path / "damaged.bin").write_bytes(data)
    out = tmp_path / "out.mcap"
    assert main(["import-log", str(tmp_path / "damaged.bin"), "-o", str(out)]) == 0
    assert "1 records with a damaged time skipped" in caplog.text
    counts = channel_counts(out)
    assert counts["/dataflash/ATT"] == reader.counts[att] - 1


def test_a_damaged_format_loses_its_records_not_the_import(tmp_path, caplog):
    """Formats whose column names were damaged (mutated logs once ended the import with a KeyError):
    DataFlash GPS without "Alt" makes no positions, a ULog topic without "timestamp" is skipped."""
    bin_data = (LOGS / "pymavlink/test.BIN").read_bytes()
    (tmp_path / "gps.bin").write_bytes(bin_data.replace(b"Lat,Lng,Alt", b"Lat,Lng,Alx"))
    assert main(["import-log", str(tmp_path / "gps.bin"), "-o", str(tmp_path / "gps.mcap")]) == 0
    counts = channel_counts(tmp_path / "gps.mcap")
    assert counts["/dataflash/GPS"] > 0 and counts["/vehicle/1/location"] == 0

    ulog = (LOGS / "pyulog/sample_log_small.ulg").read_bytes()
    topic = b"actuator_controls_1:uint64_t "
    (tmp_path / "a.ulg").write_bytes(ulog.replace(topic + b"timestamp;", topic + b"timestamq;"))
    assert main(["import-log", str(tmp_path / "a.ulg"), "-o", str(tmp_path / "a.mcap")]) == 0
    assert "records with a damaged time skipped" in caplog.text
    counts = channel_counts(tmp_path / "a.mcap")
    assert "/ulog/actuator_controls_1" not in counts and any(t.startswith("/ulog/") for t in counts)


def test_ulog_topics_match_pyulog_and_replay_to_rerun(tmp_path):
    from pyulog import ULog

    source = LOGS / "pyulog/sample_log_small.ulg"
    ulog = ULog(str(source))
    expected = {
        d.name if d.multi_id == 0 else f"{d.name}/{d.multi_id}": len(d.data["timestamp"])
        for d in ulog.data_list
    }
    out, _ = imported(tmp_path, source)
    counts = channel_counts(out)
    assert {t.removeprefix("/ulog/"): n for t, n in counts.items() if t.startswith("/ulog/")} == expected
    gps = next(d for d in ulog.data_list if d.name == "vehicle_gps_position")
    assert counts["/vehicle/1/location"] == len(gps.data["timestamp"])
    assert counts["/events"] >= len(ulog.logged_messages)
    assert main(["replay", str(out), "--rrd", str(tmp_path / "u.rrd")]) == 0
    assert (tmp_path / "u.rrd").stat().st_size > 0


@pytest.mark.parametrize("name", ["UAVLogViewer/vtol.tlog", "pymavlink/capture.mav2.battery_status.tlog"])
def test_tlog_frames_match_mavutil(tmp_path, name):
    expected = sum(1 for _ in iter_tlog(LOGS / name))
    out, _ = imported(tmp_path, LOGS / name, "capture.bin")
    raw = sum(n for t, n in channel_counts(out).items() if t.endswith("/raw"))
    assert raw == expected > 0
    assert main(["replay", str(out), "--rrd", str(tmp_path / "t.rrd")]) == 0


@pytest.mark.parametrize(
    ("content", "found"),
    [
        (b"# gcs-planner\nnot a log\n", "unknown content"),
        (b"QGC WPL 110\n0\t1\t0\t16\t0\t0\t0\t0\t0\t0\t0\t1\n", "a QGC WPL mission file"),
        (b"\x89MCAP0\r\n" + bytes(40), "an MCAP file"),
        (b"", "an empty file"),
    ],
)
def test_a_file_that_is_no_log_is_one_line_and_writes_nothing(tmp_path, capsys, content, found):
    log = tmp_path / "x.tlog"
    log.write_bytes(content)
    assert main(["import-log", str(log), "-o", str(tmp_path / "x.mcap")]) == 2
    err = capsys.readouterr().err
    assert found in err and err.count("\n") == 1
    assert sorted(p.name for p in tmp_path.iterdir()) == ["x.tlog"]


def test_pymavlinks_malformed_capture_is_refused_in_one_line(tmp_path, capsys):
    """capture.mavlink (pymavlink's JavaScript test data): little-endian times and frames whose
    length byte disagrees with their size; mavlogdump reads one bogus frame of it."""
    assert main(["import-log", str(LOGS / "pymavlink/capture.mavlink"), "-o", str(tmp_path / "c.mcap")]) == 2
    assert "not a telemetry log" in capsys.readouterr().err and not (tmp_path / "c.mcap").exists()


def test_import_tlog_is_the_same_command(tmp_path, capsys):
    assert main(["import-tlog", str(LOGS / "pymavlink/test.BIN"), "-o", str(tmp_path / "t.mcap")]) == 0
    assert "dataflash" in capsys.readouterr().out
