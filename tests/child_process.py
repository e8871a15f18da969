"""Test helper: a child process that is killed, with everything it started, whatever the test does.

``with child(argv, ...) as proc:`` starts ``argv`` in its own session (its own process group),
and on leaving the block, by success, assertion failure, timeout (pytest-timeout raises in the
test) or KeyboardInterrupt, SIGKILLs that whole group if anything of it is still running and
reaps the child. A test that wants a graceful stop (SIGINT, SIGTERM) sends it itself inside the
block; the kill is only the backstop.
"""

from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import time
from collections.abc import Iterator
from pathlib import Path

__all__ = ["child", "group_alive", "kill_group"]


def group_alive(pgid: int) -> bool:
    """Whether any process of group ``pgid`` is still running (zombies waiting to be reaped by a
    parent or by init do not count: they run nothing)."""
    try:
        os.killpg(pgid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue  # exited meanwhile
        if int(fields[2]) == pgid and fields[0] != "Z":  # fields after "pid (comm)": state ppid pgrp
            return True
    return False


def kill_group(proc: subprocess.Popen) -> None:
    """SIGKILL the child's process group (its session: the child and all it started), reap the child
    and wait (up to 10 s) until nothing of the group runs any more."""
    with contextlib.suppress(ProcessLookupError, PermissionError):
        os.killpg(proc.pid, signal.SIGKILL)
    with contextlib.suppress(subprocess.TimeoutExpired):
        proc.wait(timeout=10.0)
    deadline = time.monotonic() + 10.0  # SIGKILL is delivered asynchronously: wait for the others too
    while group_alive(proc.pid) and time.monotonic() < deadline:
        time.sleep(0.01)
    for pipe in (proc.stdin, proc.stdout, proc.stderr):
        if pipe is not None:
            with contextlib.suppress(OSError):
                pipe.close()


@contextlib.contextmanager
def child(argv: list[str], **popen_kwargs) -> Iterator[subprocess.Popen]:
    """Popen(argv, start_new_session=True, **popen_kwargs), group-killed on exit (see module)."""
    proc = subprocess.Popen(argv, start_new_session=True, **popen_kwargs)
    try:
        yield proc
    finally:
        kill_group(proc)
