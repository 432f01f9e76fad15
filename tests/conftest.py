"""Shared fixtures: scenarios are loaded once per session."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest
import torch as th

from pecli.scenario import Scenario, builtin_names, load_scenario

BUILTINS = ["paper", "car_vs_car", "point_mass", "robots", "quick", "tuned", "league"]


@pytest.fixture(scope="session")
def paper() -> Scenario:
    return load_scenario("paper")


@pytest.fixture(scope="session")
def quick() -> Scenario:
    return load_scenario("quick")


TINY_LEARNER = {
    "buffer_size": 2000,
    "batch_size": 32,
    "learning_starts": 100,
    "net_arch": [16, 16],
    "n_envs": 4,
    "checkpoint_every": 5,
    "eval_episodes": 20,
}


@pytest.fixture
def tiny(tmp_path: Path, quick: Scenario) -> Path:
    """The quick game with a tiny learner (best responses in seconds): a config file of its own."""
    import yaml

    data = quick.model_dump(mode="json")
    data["training"].update(TINY_LEARNER)
    data["name"] = "quick"
    path = tmp_path / "tiny.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def all_scenarios() -> list[Scenario]:
    """Every built-in game in both observation frames (a config that only trains differently, such as
    tuned, is the game of another)."""
    assert sorted(builtin_names()) == sorted(BUILTINS)
    out, games = [], set()
    for name in BUILTINS:
        s = load_scenario(name)
        if s.fingerprint() in games:
            continue
        games.add(s.fingerprint())
        out += [s, s.model_copy(update={"observation_frame": "world" if s.observation_frame == "own" else "own"})]
    return out


@pytest.fixture
def keep_torch_threads():
    """Training sets torch's thread count for the whole process; a test using this restores it after."""
    threads = th.get_num_threads()
    yield
    th.set_num_threads(threads)


def hold(folder: Path, code: str = "from pecli.locks import acquire; acquire({folder!r}, 'x')") -> subprocess.Popen:
    """A process that takes ``folder``'s lock (exit code 3 if refused), says so, and sleeps."""
    script = (
        "import sys, time\nfrom pecli.locks import FolderLocked\ntry:\n    "
        + code.format(folder=str(folder))
        + "\nexcept FolderLocked:\n    sys.exit(3)\n"
        "print('locked', flush=True)\ntime.sleep(120)\n"
    )
    process = subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.PIPE, text=True)
    line = process.stdout.readline().strip()
    if line != "locked":
        process.wait()
    return process
