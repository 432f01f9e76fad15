"""Checkpoints are data: a pickled payload in a checkpoint never runs, unless the user says --trust."""

from __future__ import annotations

import base64
import json
import pickle
import shutil
import zipfile
from pathlib import Path

import pytest
from typer.testing import CliRunner

from pecli.cli import app
from pecli.policies import resolve_policy
from pecli.rl.train import DEFAULT_OPPONENT, TrainJob, checkpoint_meta, make_env, make_model, with_overrides
from pecli.scenario import Scenario
from pecli.zoo import Run

runner = CliRunner()


class Payload:
    """What an attacker pickles: unpickling it creates ``marker`` (any code could run there)."""

    def __init__(self, marker: Path) -> None:
        self.marker = marker

    def __reduce__(self):
        return (Path.touch, (self.marker,))


def rewrite_zip(path: Path, replace: dict[str, bytes]) -> None:
    """Replace entries of the zip at ``path``."""
    with zipfile.ZipFile(path) as archive:
        entries = {name: archive.read(name) for name in archive.namelist()}
    entries.update(replace)
    with zipfile.ZipFile(path, "w") as archive:
        for name, data in entries.items():
            archive.writestr(name, data)


@pytest.fixture(scope="module")
def zoo(tmp_path_factory, quick: Scenario) -> Path:
    """A zoo with one tiny pursuer run: ``zoo/run/pursuer/final.zip``."""
    zoo = tmp_path_factory.mktemp("zoo")
    scenario = with_overrides(quick, {"buffer_size": 500, "batch_size": 16, "learning_starts": 50, "net_arch": [16, 16],
                                      "n_envs": 2})
    job = TrainJob(role="pursuer", scenario=scenario, opponent=DEFAULT_OPPONENT["pursuer"], zoo=zoo, name="run")
    model = make_model(job, make_env(job, resolve_policy("greedy", "evader", scenario), seed=0), tensorboard=None)
    model.learn(60)
    Run.create(zoo, "run", scenario, {"command": "test"}).save(model, "pursuer", "final", checkpoint_meta(job, model, 0))
    return zoo


def poisoned_copy(zoo: Path, tmp_path: Path, marker: Path, entry: str) -> Path:
    """A copy of the zoo whose checkpoint carries a payload in ``entry``: in ``data`` as SB3 stores pickled
    objects (base64 under ':serialized:'), or as the whole ``policy.pth``."""
    copy = tmp_path / "zoo"
    shutil.copytree(zoo, copy)
    path = copy / "run" / "pursuer" / "final.zip"
    with zipfile.ZipFile(path) as archive:
        data = json.loads(archive.read("data"))
    if entry == "data":
        data["policy_class"] = {":type:": "<class 'type'>",
                                ":serialized:": base64.b64encode(pickle.dumps(Payload(marker))).decode()}
        rewrite_zip(path, {"data": json.dumps(data).encode()})
    else:
        rewrite_zip(path, {"policy.pth": pickle.dumps(Payload(marker))})
    return path


def test_the_payload_is_real(zoo: Path, tmp_path: Path) -> None:
    """SB3's own loader runs the payload: what pecli must never do."""
    from stable_baselines3 import TD3

    marker = tmp_path / "ran"
    path = poisoned_copy(zoo, tmp_path, marker, "data")
    with pytest.raises(Exception):
        TD3.load(path)
    assert marker.exists()


def test_a_payload_in_data_never_runs(zoo: Path, tmp_path: Path) -> None:
    marker = tmp_path / "ran"
    path = poisoned_copy(zoo, tmp_path, marker, "data")
    for command in (
        ["play", "-p", str(path), "-e", "greedy", "-n", "4"],
        ["tournament", str(path.parents[2]), "--baselines", "--episodes", "4", "--seeds", "1", "--out", str(tmp_path / "t")],
        ["export", "onnx", str(path), "--out", str(tmp_path / "exported.onnx")],
        ["zoo", "show", str(path)],
    ):
        result = runner.invoke(app, command)
        assert result.exit_code == 0, (command, result.output)  # the weights are fine; the payload is ignored
        assert not marker.exists(), command


def test_a_payload_in_the_weights_is_refused(zoo: Path, tmp_path: Path) -> None:
    marker = tmp_path / "ran"
    path = poisoned_copy(zoo, tmp_path, marker, "policy.pth")
    result = runner.invoke(app, ["play", "-p", str(path), "-e", "greedy", "-n", "4"])
    assert result.exit_code == 1 and "holds pickled objects" in result.output and "--trust" in result.output
    assert len(result.output.strip().splitlines()) == 1
    tournament = runner.invoke(app, ["tournament", str(path.parents[2]), "--baselines", "--episodes", "2", "--seeds",
                                     "1", "--workers", "2", "--out", str(tmp_path / "t")])
    assert tournament.exit_code == 1 and "holds pickled objects" in tournament.output  # from a worker process
    assert not marker.exists()


def test_a_checkpoint_of_an_older_pecli_needs_trust(zoo: Path, tmp_path: Path, monkeypatch) -> None:
    """Metadata without a network description: only unpickling can rebuild it."""
    monkeypatch.setenv("PECLI_TRUST", "0")  # and restored after the test, which sets it through --trust
    copy = tmp_path / "zoo"
    shutil.copytree(zoo, copy)
    meta_path = copy / "run" / "pursuer" / "final.json"
    meta = json.loads(meta_path.read_text())
    del meta["policy_kwargs"]
    meta_path.write_text(json.dumps(meta))
    command = ["play", "-p", str(meta_path.with_suffix(".zip")), "-e", "greedy", "-n", "4"]
    refused = runner.invoke(app, command)
    assert refused.exit_code == 1 and "written before pecli described networks" in refused.output
    assert "--trust" in refused.output
    trusted = runner.invoke(app, ["--trust", *command])
    assert trusted.exit_code == 0, trusted.output


def test_edited_metadata_is_one_clear_line(zoo: Path, tmp_path: Path) -> None:
    copy = tmp_path / "zoo"
    shutil.copytree(zoo, copy)
    meta_path = copy / "run" / "pursuer" / "final.json"
    original = json.loads(meta_path.read_text())
    for change, message in (
        ({"frame_stack": 5}, "does not describe its network: actor.mu.0.weight has shape [16, 22] in the weights but "
                             "[16, 55] by the metadata"),
        ({"frame_stack": "two"}, "damaged metadata (frame_stack must be a whole number >= 1, not 'two')"),
        ({"belief": "bimdn"}, "without its belief_kwargs"),
        ({"algo": "ppo"}, "unknown algorithm 'ppo'"),
        ({"policy_kwargs": {"net_arch": [64, 64]}}, "has shape [16, 22] in the weights but [64, 22] by the metadata"),
    ):
        meta_path.write_text(json.dumps({**original, **change}))
        for command in (["play", "-p", str(meta_path.with_suffix(".zip")), "-e", "greedy", "-n", "2"],
                        ["export", "onnx", str(meta_path.with_suffix(".zip")), "--out", str(tmp_path / "x.onnx")]):
            result = runner.invoke(app, command)
            assert result.exit_code == 1 and message in result.output, (change, command, result.output)
            assert "Traceback" not in result.output and "internal error" not in result.output


def test_a_payload_in_the_durable_state_is_refused(tmp_path: Path) -> None:
    import io

    import numpy as np

    tiny = ["--set", "buffer_size=400", "--set", "batch_size=16", "--set", "learning_starts=50", "--set",
            "net_arch=[16,16]", "--set", "n_envs=2", "--set", "checkpoint_every=2"]
    start = ["train", "pursuer", "-c", "quick", "--steps", "300", "--name", "r", "--zoo", str(tmp_path), "-q", *tiny]
    assert runner.invoke(app, start).exit_code == 0
    marker = tmp_path / "ran"
    chunk = sorted((tmp_path / "r" / "pursuer" / "resume").glob("replay-*.npz"))[-1]
    with np.load(chunk) as data:
        arrays = {key: data[key] for key in data.files}
    arrays["actions"] = np.array([Payload(marker)] * len(arrays["actions"]), dtype=object)
    buffer = io.BytesIO()
    np.savez(buffer, **arrays)
    chunk.write_bytes(buffer.getvalue())
    result = runner.invoke(app, ["train", "pursuer", "--name", "r", "--zoo", str(tmp_path), "--resume", "-q",
                                 "--steps", "400"])
    assert result.exit_code == 1 and "buffer files hold pickled objects" in result.output
    assert not marker.exists()
