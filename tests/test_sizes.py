"""Counts are checked while reading: a huge WPL stops at the mission limit, with one line."""

from __future__ import annotations

import pytest

from gcs_planner.cli import main
from gcs_planner.missions.files import MissionFileError
from gcs_planner.missions.wpl import loads_wpl

ROW = "1\t0\t3\t16\t0\t0\t0\t0\t47.39\t8.54\t20\t1\n"


def test_a_wpl_over_the_mission_limit_stops_at_the_limit():
    text = "QGC WPL 110\n" + ROW * 65_535 + ROW * 5 + "garbage that is never parsed\n" * 10
    with pytest.raises(MissionFileError, match="line 65539: more than 65536 rows"):
        loads_wpl(text)
    loads_wpl("QGC WPL 110\n" + ROW * 65_536)  # home row + 65535 items: the limit itself


def test_convert_of_a_huge_wpl_is_one_line_and_writes_nothing(tmp_path, capsys):
    src = tmp_path / "big.waypoints"
    src.write_text("QGC WPL 110\n" + ROW * 200_000)
    assert main(["convert", str(src), str(tmp_path / "o.plan")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "65535" in err[0] and len(err[0]) < 300
    assert not (tmp_path / "o.plan").exists()
