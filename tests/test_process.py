"""What pecli reads of other processes: their children and their CPU time."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from pecli.process import cpu_seconds, descendants, live_parents

pytestmark = pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="reads /proc")


def test_a_child_and_its_child_are_descendants() -> None:
    script = "import subprocess, sys; subprocess.run([sys.executable, '-c', 'import time; time.sleep(30)'])"
    child = subprocess.Popen([sys.executable, "-c", script])
    try:
        for _ in range(100):  # the grandchild appears once the child's interpreter has started
            below = descendants(child.pid)
            if below:
                break
            time.sleep(0.1)
        assert live_parents()[child.pid] == os.getpid()
        assert child.pid in descendants(os.getpid()) and len(below) == 1
        assert live_parents()[next(iter(below))] == child.pid
        assert cpu_seconds(child.pid) >= 0.0
    finally:
        for pid in descendants(child.pid):
            os.kill(pid, signal.SIGKILL)
        child.kill()
        child.wait()
    assert child.pid not in live_parents()
