"""A command imports only its own module: `upload` or `convert` do not pay for the planners."""

from __future__ import annotations

import subprocess
import sys


def test_a_command_does_not_import_the_other_commands():
    heavy = "('gcs_planner.planning', 'gcs_planner.coalition_hil', 'scipy', 'rerun')"
    code = (
        "import sys; from gcs_planner.cli import main; main(['convert', '/nonexistent.plan', '/tmp/x.plan']);"
        f" print(sorted(m for m in sys.modules if m.startswith({heavy})))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert out.stdout.strip() == "[]", out.stdout
    assert "no such file" in out.stderr


def test_help_still_lists_every_command():
    from gcs_planner.cli import COMMANDS

    out = subprocess.run(
        [sys.executable, "-m", "gcs_planner.cli", "--help"], capture_output=True, text=True, timeout=60
    )
    assert all(name in out.stdout for name in COMMANDS)
