"""What pecli reads of other processes (their children and CPU time), and the pool of workers that stop like Ctrl-C."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from pecli.process import cpu_seconds, descendants, live_parents, stoppable_pool

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


def test_a_stoppable_pool_interrupts_its_running_tasks_when_the_driver_stops(tmp_path: Path) -> None:
    started, marker, queued = time.monotonic(), tmp_path / "started", tmp_path / "queued"
    with pytest.raises(RuntimeError, match="the driver stops"), stoppable_pool(1, grace=30.0) as pool:
        # a task that would run a minute: the worker's Python waits on its child, as a training run would compute
        future = pool.submit(subprocess.run, ["sh", "-c", f"touch {marker}; exec sleep 60"])
        behind = pool.submit(subprocess.run, ["touch", str(queued)])  # handed to the worker, queued behind it
        while not marker.exists():
            time.sleep(0.05)
        workers = [process.pid for process in pool._processes.values()]  # type: ignore[attr-defined]
        raise RuntimeError("the driver stops")
    assert isinstance(future.exception(timeout=5), KeyboardInterrupt)  # stopped like Ctrl-C, its own code ran on
    assert behind.cancelled() or isinstance(behind.exception(timeout=5), KeyboardInterrupt)
    assert not queued.exists()  # the task queued behind it never started
    assert time.monotonic() - started < 30  # not waited out, not killed at the end of the grace
    assert not set(workers) & set(live_parents())
