"""docs/results/<name>.md: a figure's output with the facts needed to judge and redo it.

A results file states the machine (CPU model, cores, memory, OS, Python), the load (``uptime``)
before and after, the date, the code (git commit), and each command with its wall and CPU time.
Text below ``NOTES_MARK`` is written by hand (what the figure shows, caveats) and kept when the
file is regenerated.
"""

from __future__ import annotations

import os
import platform
import subprocess
from dataclasses import dataclass
from pathlib import Path

__all__ = ["NOTES_MARK", "StepResult", "load_line", "machine_line", "notes_of", "render"]

NOTES_MARK = "<!-- notes: kept by benchmarks/run_all.py -->"
ROOT = Path(__file__).resolve().parents[1]


@dataclass(frozen=True)
class StepResult:
    """One command of a figure as it ran: its output and what it cost."""

    command: str
    stdout: str
    stderr_tail: str
    wall_s: float
    cpu_s: float  # user + system of the command and the children it waited for
    returncode: int


def _cpu_model() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def _memory_gib() -> str:
    try:
        for line in Path("/proc/meminfo").read_text().splitlines():
            if line.startswith("MemTotal:"):
                return f"{int(line.split()[1]) / 2**20:.1f} GiB"
    except OSError:
        pass
    return "memory unknown"


def machine_line() -> str:
    """CPU model, cores, memory, OS and Python of this machine, on one line."""
    return (
        f"{_cpu_model()}, {os.cpu_count()} cores, {_memory_gib()}, {platform.system()} "
        f"{platform.release()} {platform.machine()}, Python {platform.python_version()}"
    )


def load_line() -> str:
    """What ``uptime`` prints (the load averages over 1, 5 and 15 minutes)."""
    try:
        return subprocess.run(["uptime"], capture_output=True, text=True, check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        one, five, fifteen = os.getloadavg()
        return f"load average: {one:.2f}, {five:.2f}, {fifteen:.2f}"


def code_line() -> str:
    """The git commit, and whether the code the figures run differs from it."""
    git = ["git", "-C", str(ROOT)]
    try:
        head = subprocess.run([*git, "rev-parse", "--short", "HEAD"], capture_output=True, text=True)
        dirty = subprocess.run(
            [
                *git,
                "status",
                "--porcelain",
                "--",
                "gcs_planner",
                "sitl_mock",
                "benchmarks",
                "missions",
                "studies",
            ],
            capture_output=True,
            text=True,
        )
    except OSError:
        return "not a git checkout"
    changed = "; uncommitted changes in the code" if dirty.stdout.strip() else ""
    return f"git {head.stdout.strip()}{changed}"


def notes_of(path: Path) -> str:
    """The hand-written notes of an existing results file ('' when none)."""
    if not path.exists():
        return ""
    text = path.read_text()
    return text.split(NOTES_MARK, 1)[1].strip("\n") if NOTES_MARK in text else ""


def _output(step: StepResult, markdown: bool) -> str:
    body = step.stdout.rstrip("\n") or "(no output)"
    if not markdown:
        body = f"```\n{body}\n```"
    if step.returncode != 0 and step.stderr_tail:
        body += f"\n\nExit status {step.returncode}; the end of its stderr:\n\n```\n{step.stderr_tail}\n```"
    return body


def render(
    name: str, title: str, facts: dict[str, str], steps: list[StepResult], markdown: bool, notes: str
) -> str:
    """The whole results file."""
    lines = [f"# {name}: {title}", ""]
    lines += [f"- {key}: {value}" for key, value in facts.items()]
    lines += ["", "| step | command | wall s | CPU s | exit |", "|---|---|---|---|---|"]
    for i, s in enumerate(steps, 1):
        lines.append(f"| {i} | `{s.command}` | {s.wall_s:.1f} | {s.cpu_s:.1f} | {s.returncode} |")
    for i, s in enumerate(steps, 1):
        heading = "## Output" if len(steps) == 1 else f"## Output of step {i}: `{s.command}`"
        lines += ["", heading, "", _output(s, markdown)]
    lines += ["", NOTES_MARK]
    if notes:
        lines += ["", notes]
    return "\n".join(lines) + "\n"
