"""Checks the CLI tests share."""

from __future__ import annotations

from gcs_planner.cli import main


def refused(argv: list[str], capsys, *words: str) -> str:
    """main(argv) exits 2 with one stderr line that contains every one of ``words``; that line."""
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    for word in words:
        assert word in err[0], err[0]
    return err[0]
