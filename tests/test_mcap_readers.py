"""Every MCAP the tool writes reads completely in Foxglove's own reader (@mcap/core through node,
tests/js) and in the stock Python reader: a flown log and an imported one."""

from __future__ import annotations

import json
import shutil
import subprocess
from collections import Counter
from pathlib import Path

import pytest
from mcap.reader import make_reader

from gcs_planner.cli import main

ROOT = Path(__file__).resolve().parents[1]
READER = ROOT / "tests" / "js" / "read_mcap.mjs"
NODE_MODULES = ROOT / "tests" / "js" / "node_modules" / "@mcap" / "core"

pytestmark = pytest.mark.skipif(
    shutil.which("node") is None or not NODE_MODULES.exists(),
    reason="Foxglove's reader not installed: node and `npm ci --prefix tests/js` (.ci/run does both)",
)


def foxglove_reads(path: Path) -> dict:
    out = subprocess.run(["node", str(READER), str(path)], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    return json.loads(out.stdout)


def stock_reads(path: Path) -> Counter:
    with path.open("rb") as f:
        return Counter(channel.topic for _, channel, _ in make_reader(f).iter_messages())


def test_a_flown_log_and_its_imported_tlog_read_completely_in_foxglove_and_python(tmp_path):
    out = tmp_path / "out"
    argv = ["fly", str(ROOT / "missions" / "straight_4uav.toml"), "--tlog", "--no-rrd",
            "-o", str(out)]  # fmt: skip
    assert main(argv) == 0
    assert main(["import-log", str(out / "flight.tlog"), "-o", str(tmp_path / "imported.mcap")]) == 0
    for path in (out / "flight.mcap", tmp_path / "imported.mcap"):
        fox, stock = foxglove_reads(path), stock_reads(path)
        assert fox["error"] is None, (path.name, fox["error"])
        assert fox["topics"] == dict(stock) and fox["messages"] == fox["summary_messages"] > 1000, path.name
        assert any(topic.endswith("/location") for topic in fox["topics"])  # the Map panel's channels
