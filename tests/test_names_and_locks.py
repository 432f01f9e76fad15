"""Run names stay inside their zoo, and a run folder has one writer at a time."""

from __future__ import annotations

import sys
from pathlib import Path
from unittest import mock

import pytest
from conftest import hold
from typer.testing import CliRunner

from pecli.cli import app
from pecli.errors import PecliError
from pecli.locks import FolderLocked, acquire, locked, release
from pecli.rl.train import default_run_name
from pecli.scenario import Scenario
from pecli.zoo import Run, ZooError, check_run_name

runner = CliRunner()
TINY = [
    "--set",
    "learning_starts=4",
    "--set",
    "n_envs=2",
    "--set",
    "net_arch=[8]",
    "--set",
    "buffer_size=100",
    "--set",
    "batch_size=4",
    "-q",
]
BUDGET = {"train": ["--steps", "8"], "selfplay": ["--rounds", "1", "--steps-per-round", "8"]}
BAD_NAMES = ["../../escape", "../x", "/tmp/anywhere", "a/b", ".", "..", ".hidden", "a b", "x\ny", "é", "-" * 129]


def invoke(*args: str):
    with mock.patch.object(sys, "argv", ["pecli", *args]):
        return runner.invoke(app, list(args))


@pytest.mark.parametrize("name", BAD_NAMES)
def test_run_names_are_single_folder_names(name: str) -> None:
    with pytest.raises(ZooError, match="is not allowed: use one folder name"):
        check_run_name(name)


@pytest.mark.parametrize("name", ["run", "k5", "quick-pursuer-s0-20260101-120000", "a.b_c-1", "-x", "x..y"])
def test_good_run_names_pass(name: str) -> None:
    assert check_run_name(name) == name


@pytest.mark.parametrize("command", [["train", "pursuer"], ["selfplay"]])
@pytest.mark.parametrize("name", ["../../escape", "a/b", "/tmp/pecli-escape"])
def test_train_and_selfplay_refuse_a_name_that_leaves_the_zoo(tmp_path: Path, command: list[str], name: str) -> None:
    zoo = tmp_path / "deep" / "zoo"
    result = invoke(*command, "-c", "quick", "--zoo", str(zoo), "--name", name, *BUDGET[command[0]], *TINY)
    assert result.exit_code == 1 and "is not allowed" in result.output, result.output
    assert len(result.output.strip().splitlines()) == 1
    assert not list(tmp_path.rglob("*.yaml")) and not Path("/tmp/pecli-escape").exists()
    result = invoke(*command, "--zoo", str(zoo), "--name", name, "--resume", "-q")
    assert result.exit_code == 1 and "is not allowed" in result.output, result.output


def test_default_run_names_are_valid(quick: Scenario) -> None:
    odd = quick.model_copy(update={"name": "../my game/v2"})
    check_run_name(default_run_name("pursuer", odd, 3))
    assert default_run_name("selfplay", quick, 0).startswith("quick-selfplay-s0-")


def test_the_lock_is_reentrant_in_a_process_and_released_by_the_last_taker(tmp_path: Path) -> None:
    acquire(tmp_path, "x")
    with locked(tmp_path, "x"):
        pass
    holder = hold(tmp_path)
    try:
        assert holder.poll() is not None and holder.returncode == 3  # still held here: the other process is refused
    finally:
        holder.kill()
    release(tmp_path)
    holder = hold(tmp_path)
    try:
        assert holder.poll() is None  # released: the other process holds it now
        with pytest.raises(FolderLocked, match=rf"x \({tmp_path}\) is being written by process {holder.pid}"):
            acquire(tmp_path, "x")
    finally:
        holder.kill()
        holder.wait()
    with locked(tmp_path, "x"):  # the OS dropped the killed holder's lock
        pass


def test_a_run_has_one_writer(tmp_path: Path, quick: Scenario) -> None:
    """A run being written (here by another process that opened it) refuses a resume, a second opener and rm."""
    run = Run.create(tmp_path, "r", quick, {"command": "train", "role": "pursuer", "opponent": "greedy", "seed": 0})
    run.close()
    holder = hold(
        tmp_path, "from pathlib import Path; from pecli.zoo import Run; run = Run.open(Path({folder!r}), 'r')"
    )
    try:
        assert holder.poll() is None
        with pytest.raises(PecliError, match=rf"run 'r' \(.*\) is being written by process {holder.pid}"):
            Run.open(tmp_path, "r")
        for command in (["train", "pursuer", "--resume"], ["selfplay", "--resume"]):
            result = invoke(*command, "--zoo", str(tmp_path), "--name", "r", "-q")
            assert result.exit_code == 1 and f"being written by process {holder.pid}" in result.output, result.output
        result = invoke("zoo", "rm", str(tmp_path / "r"), "--yes")
        assert result.exit_code == 1 and "being written" in result.output and (tmp_path / "r" / "config.yaml").is_file()
    finally:
        holder.kill()
        holder.wait()
    Run.open(tmp_path, "r").close()  # the dead writer's lock is gone
