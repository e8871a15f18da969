"""A command imports only its own module: `upload` or `convert` do not pay for the planners."""

from __future__ import annotations

import importlib
import subprocess
import sys

import pytest


@pytest.mark.parametrize(
    "argv",
    [
        ["convert", "/nonexistent.plan", "/tmp/x.plan"],
        ["upload", "--connect", "udpout:127.0.0.1:9", "--sysid", "1", "/nonexistent.plan"],
    ],
)
def test_a_command_does_not_import_the_other_commands(argv):
    """Nor numpy or pyproj: a mission file read and sent needs neither (the plan.json reader loads them)."""
    heavy = repr(("gcs_planner.planning", "gcs_planner.flight.coalition", "scipy", "rerun", "sitl_mock",
                  "numpy", "pyproj"))  # fmt: skip
    code = (
        f"import sys; from gcs_planner.cli import main; main({argv!r});"
        f" print(sorted(m for m in sys.modules if m.startswith({heavy})))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert out.stdout.strip() == "[]", out.stdout
    assert "no such file" in out.stderr.lower()


def test_help_lists_every_command_without_importing_them():
    from gcs_planner.cli import COMMANDS

    code = (
        "import sys; from gcs_planner.cli import main; main(['--help']);"
        " print([m for m in sys.modules if m.startswith('gcs_planner.commands.')])"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    listed = " ".join(out.stdout.split())
    assert all(name in listed and " ".join(text.split()) in listed for name, text in COMMANDS.items())
    assert out.stdout.strip().endswith("[]")  # no command module imported


def test_each_help_line_is_its_modules_docstring():
    from gcs_planner.cli import COMMANDS

    for name, text in COMMANDS.items():
        module = importlib.import_module(f"gcs_planner.commands.{name.replace('-', '_')}")
        assert module.__doc__.strip().splitlines()[0] == text, name
