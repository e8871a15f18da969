"""The test helper that starts child processes kills them, and what they started, whatever happens."""

import signal
import sys

import pytest
from child_process import child, group_alive

# ignores Ctrl-C and SIGTERM; the first starts a second that does the same (a grandchild of the test)
STUBBORN = r"""
import signal, subprocess, sys, time
signal.signal(signal.SIGINT, signal.SIG_IGN)
signal.signal(signal.SIGTERM, signal.SIG_IGN)
if sys.argv[1:] != ["grandchild"]:
    grandchild = subprocess.Popen([sys.executable, __file__, "grandchild"], stdout=subprocess.PIPE, text=True)
    grandchild.stdout.readline()
    print("ready", grandchild.pid, flush=True)
else:
    print("ready", flush=True)
time.sleep(600)
"""


def _running(pid: int) -> bool:
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().rsplit(")", 1)[1].split()[0] != "Z"
    except FileNotFoundError:
        return False


def test_a_failing_test_leaves_neither_the_child_nor_its_children_running(tmp_path):
    script = tmp_path / "stubborn.py"
    script.write_text(STUBBORN)
    seen = []
    failing = pytest.raises(AssertionError, match="the test failed")
    with failing, child([sys.executable, str(script)], stdout=-1, text=True) as proc:
        word, grandchild = proc.stdout.readline().split()
        seen.append((proc, int(grandchild)))
        assert word == "ready" and _running(int(grandchild))
        proc.send_signal(signal.SIGINT)  # ignored, as by a hung child
        raise AssertionError("the test failed")
    ((proc, grandchild),) = seen
    assert proc.returncode == -signal.SIGKILL
    assert not _running(grandchild) and not group_alive(proc.pid)
