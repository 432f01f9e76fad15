"""Hard kills: `pecli train` and `pecli selfplay` killed with SIGKILL at chosen moments resume and finish,
losing at most one checkpoint interval. The moments are files appearing on disk, not wall-clock guesses."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from typer.testing import CliRunner

from pecli.cli import app

TINY = [
    "--set",
    "buffer_size=2000",
    "--set",
    "batch_size=32",
    "--set",
    "learning_starts=100",
    "--set",
    "net_arch=[16,16]",
    "--set",
    "n_envs=4",
    "--set",
    "checkpoint_every=5",
]
EVERY = 5  # episodes between checkpoints


def pecli(*args: str) -> subprocess.Popen:
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    return subprocess.Popen(
        [sys.executable, "-m", "pecli", *args], stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=env
    )


def kill_when(process: subprocess.Popen, ready, timeout: float = 120.0) -> None:
    """SIGKILL ``process`` as soon as ``ready()`` is true; fail if it ends or never gets there."""
    deadline = time.monotonic() + timeout
    while not ready():
        if process.poll() is not None:
            pytest.fail(f"ended before the moment to kill it: {process.stdout.read()}")
        if time.monotonic() > deadline:
            process.kill()
            pytest.fail("the moment to kill never came")
        time.sleep(0.02)
    process.send_signal(signal.SIGKILL)
    process.wait(timeout=30)


def finish(*args: str) -> str:
    """Run a command to its end in this process (no kill follows, so no subprocess is needed)."""
    result = CliRunner().invoke(app, list(args))
    assert result.exit_code == 0, result.output
    return result.output


def committed(role_dir: Path) -> dict | None:
    path = role_dir / "resume" / "state.json"
    try:
        return json.loads(path.read_text())
    except (OSError, json.JSONDecodeError):
        return None


def test_train_killed_at_checkpoints_resumes_and_finishes(tmp_path: Path) -> None:
    zoo, role = tmp_path / "zoo", tmp_path / "zoo" / "k" / "pursuer"
    start = ["train", "pursuer", "-c", "quick", "--steps", "2500", "--name", "k", "--zoo", str(zoo), "-q", *TINY]
    resume = ["train", "pursuer", "--name", "k", "--zoo", str(zoo), "--resume", "-q"]
    kill_when(pecli(*start), lambda: (role / f"ep{EVERY:07d}.zip").is_file())  # after the 1st checkpoint
    first = committed(role)
    assert first is not None and first["episodes"] >= EVERY

    process = pecli(*resume)
    kill_when(process, lambda: (committed(role) or first)["episodes"] >= first["episodes"] + 2 * EVERY)
    second = committed(role)  # two intervals later: the resumed run went on from the first commit
    assert second["steps"] > first["steps"] and second["replay"]["added"] > first["replay"]["added"]
    (role / "resume" / ".model-000000001.zip").write_bytes(b"half-written")  # what a kill mid-save leaves
    (role / "resume" / "replay-99999990-99999999.npz").write_bytes(b"")

    output = finish(*resume)
    final = json.loads((role / "final.json").read_text())
    assert final["steps"] == 2500 and "done:" in output
    assert final["episodes"] > second["episodes"]
    assert sorted(p.name for p in (role / "resume").iterdir() if not p.name.startswith("replay-")) == [
        "model-000002500.zip",
        "state.json",
    ]  # the garbage is gone
    assert "train pursuer" in (zoo / "k" / "command.txt").read_text()


def test_train_killed_before_its_first_checkpoint_starts_over(tmp_path: Path) -> None:
    zoo, run = tmp_path / "zoo", tmp_path / "zoo" / "k"
    start = [
        "train",
        "pursuer",
        "-c",
        "quick",
        "--steps",
        "4000",
        "--name",
        "k",
        "--zoo",
        str(zoo),
        "-q",
        *TINY[:-2],
        "--set",
        "checkpoint_every=1000",
    ]
    kill_when(pecli(*start), lambda: (run / "run.json").is_file())
    again = CliRunner().invoke(app, ["train", "pursuer", "-c", "quick", "--name", "k", "--zoo", str(zoo), "-q", *TINY])
    assert again.exit_code == 1 and "already exists" in again.output and "--resume" in again.output  # it says how
    resumed = finish("train", "pursuer", "--name", "k", "--zoo", str(zoo), "--resume", "-q", "--steps", "600")
    assert "stopped before its first checkpoint" in resumed and "starting it over" in resumed
    assert json.loads((run / "pursuer" / "final.json").read_text())["steps"] == 600


def test_selfplay_killed_inside_a_turn_resumes_there(tmp_path: Path) -> None:
    zoo, run = tmp_path / "zoo", tmp_path / "zoo" / "sp"
    start = [
        "selfplay",
        "-c",
        "quick",
        "--rounds",
        "2",
        "--steps-per-round",
        "600",
        "--name",
        "sp",
        "--zoo",
        str(zoo),
        "-q",
        *TINY,
        "--set",
        "learning_starts=50",
    ]
    # killed once the evader has committed part of its round-1 turn (the pursuer's turn is finished)
    kill_when(pecli(*start), lambda: ((committed(run / "evader") or {}).get("extra") or {}).get("round") == 1)
    inside = committed(run / "evader")
    assert inside["steps"] - inside["extra"]["start_steps"] < 600  # killed inside the turn
    finish("selfplay", "--name", "sp", "--zoo", str(zoo), "--resume", "-q")
    state = json.loads((run / "selfplay.json").read_text())
    assert [(t["round"], t["role"]) for t in state["turns"]] == [
        (1, "pursuer"),
        (1, "evader"),
        (2, "pursuer"),
        (2, "evader"),
    ]
    for role in ("pursuer", "evader"):
        assert json.loads((run / role / "round-002.json").read_text())["steps"] == 1200  # the budget, not more
