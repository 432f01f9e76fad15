"""Every algorithm of the registry: trains, saves, rebuilds from its recorded policy kwargs, plays its
deterministic action, exports with parity, and meets others in a tournament; --algo and --device on the CLI."""

from __future__ import annotations

import io
import zipfile
from pathlib import Path

import numpy as np
import pytest
import torch as th
from stable_baselines3.common.buffers import DictReplayBuffer
from typer.testing import CliRunner

from pecli.cli import app
from pecli.export import export_checkpoint
from pecli.models.algorithms import ALGORITHMS, deterministic_actor, get_algorithm, torch_device
from pecli.models.buffers import ConcatDictReplayBuffer, TensorDict
from pecli.policies import resolve_policy
from pecli.policies.learned import LearnedPolicy
from pecli.rl.train import TrainJob, checkpoint_meta, make_env, make_model, with_overrides
from pecli.runtime import ExportedModel
from pecli.scenario import ALGOS, Scenario
from pecli.tournament import find_players, run_tournament, schedule
from pecli.zoo import Run, read_metadata

runner = CliRunner()
pytestmark = pytest.mark.usefixtures("keep_torch_threads")
TINY = {"buffer_size": 500, "batch_size": 16, "learning_starts": 50, "net_arch": [16, 16], "n_envs": 4}


def test_the_scenario_names_every_registered_algorithm() -> None:
    assert tuple(ALGORITHMS) == ALGOS


@pytest.fixture(scope="module")
def checkpoints(tmp_path_factory, quick: Scenario) -> dict[str, tuple[Path, object, object]]:
    """(checkpoint, live model, its env) per algorithm, each trained for a few gradient steps."""
    zoo = tmp_path_factory.mktemp("zoo")
    made = {}
    for algo in ALGORITHMS:
        scenario = with_overrides(quick, {**TINY, "algo": algo})
        job = TrainJob(role="pursuer", scenario=scenario, opponent="greedy", zoo=zoo, name=algo)
        env = make_env(job, resolve_policy("greedy", "evader", scenario), seed=0)
        model = make_model(job, env, tensorboard=None)
        model.learn(120)  # 50 transitions of warm-up, then updates (CrossQ's batch statistics move)
        path = Run.create(zoo, algo, scenario, {"command": "test"}).save(
            model, "pursuer", "final", checkpoint_meta(job, model, 0)
        )
        made[algo] = (path, model, env)
    return made


@pytest.mark.parametrize("algo", ALGOS)
def test_a_policy_rebuilds_from_its_recorded_kwargs_and_state_dict(checkpoints, algo: str) -> None:
    """The contract of the checkpoint loader: the policy class, the spaces and ``meta.policy_kwargs`` alone
    rebuild networks that take the saved ``policy.pth`` and play the same actions."""
    path, model, env = checkpoints[algo]
    meta = read_metadata(path)
    spec = get_algorithm(meta.algo)
    with zipfile.ZipFile(path) as archive:
        state = th.load(io.BytesIO(archive.read("policy.pth")), map_location="cpu", weights_only=True)
    rebuilt = spec.policy(env.observation_space, env.action_space, lambda _: 1e-3, **meta.policy_kwargs)
    rebuilt.load_state_dict(state)  # strict: every network has the shape it was saved with
    rebuilt.set_training_mode(False)
    obs = env.reset()
    with th.no_grad():
        batch = {key: th.as_tensor(value) for key, value in obs.items()}
        actor = rebuilt.actor
        played = deterministic_actor(actor)(actor.features_extractor(batch)).numpy()
    np.testing.assert_allclose(played, model.predict(obs, deterministic=True)[0], atol=1e-6)


@pytest.mark.parametrize("algo", ALGOS)
def test_a_checkpoint_plays_its_deterministic_action_and_exports_with_parity(
    checkpoints, quick: Scenario, algo: str
) -> None:
    path, model, env = checkpoints[algo]
    scenario = with_overrides(quick, {**TINY, "algo": algo})
    learned = LearnedPolicy.load(path, "pursuer", scenario)
    obs = env.reset()
    with th.no_grad():
        features = learned.actor.features_extractor({"obs": th.as_tensor(obs["obs"])})
        np.testing.assert_allclose(learned._act(features).numpy(), model.predict(obs, deterministic=True)[0], atol=1e-6)
    result = export_checkpoint(path, episodes=2)  # refuses to write an export that fails parity
    assert result.parity.passed
    exported = ExportedModel.load(result.model)
    assert exported.role == "pursuer"


def test_checkpoints_of_every_algorithm_meet_in_a_tournament(checkpoints, quick: Scenario, tmp_path: Path) -> None:
    scenario = with_overrides(quick, TINY)
    found = find_players([str(path) for path, _, _ in checkpoints.values()] + ["greedy"], scenario)
    assert len(found.players["pursuer"]) == len(ALGOS)
    results = run_tournament(scenario, found.players, schedule(found.players), episodes=2, seeds=[0], out=tmp_path)
    assert len(results.grid()) == len(ALGOS)


def test_crossq_concatenates_dict_observations() -> None:
    a = TensorDict(obs=th.zeros(2, 3), state=th.ones(2, 1))
    b = TensorDict(obs=th.ones(4, 3), state=th.zeros(4, 1))
    both = th.cat([a, b], dim=0)
    assert isinstance(both, TensorDict) and both["obs"].shape == (6, 3) and both["state"].shape == (6, 1)
    assert th.equal(both["obs"][2:], th.ones(4, 3))
    assert get_algorithm("crossq").cls is not None and issubclass(ConcatDictReplayBuffer, DictReplayBuffer)


def test_train_with_algo_then_play_on_the_cli(tmp_path: Path) -> None:
    sets = sum((["--set", f"{key}={value}"] for key, value in TINY.items() if key != "net_arch"), [])
    result = runner.invoke(
        app,
        [
            "train",
            "pursuer",
            "-c",
            "quick",
            "--algo",
            "sac",
            "--steps",
            "200",
            "--zoo",
            str(tmp_path),
            "--name",
            "sac",
            "-q",
            "--device",
            "auto",
            *sets,
            "--set",
            "net_arch=[16, 16]",
        ],
    )
    assert result.exit_code == 0, result.output
    checkpoint = tmp_path / "sac" / "pursuer" / "final.zip"
    assert read_metadata(checkpoint).algo == "sac"
    result = runner.invoke(app, ["play", "--pursuer", str(checkpoint), "--evader", "greedy", "-c", "quick", "-n", "2"])
    assert result.exit_code == 0, result.output


def test_an_unknown_algorithm_is_refused_in_one_line(tmp_path: Path) -> None:
    result = runner.invoke(app, ["train", "pursuer", "-c", "quick", "--set", "algo=ppo", "--zoo", str(tmp_path)])
    assert result.exit_code == 1
    assert len(result.output.strip().splitlines()) == 1 and "algo" in result.output


@pytest.mark.skipif(th.cuda.is_available(), reason="this machine has CUDA")
@pytest.mark.parametrize("command", [["train", "pursuer"], ["selfplay"], ["tune", "pursuer"]])
def test_device_cuda_without_cuda_is_one_clear_line(tmp_path: Path, command: list[str]) -> None:
    result = runner.invoke(
        app, [*command, "-c", "quick", "--device", "cuda", "--zoo" if command[0] != "tune" else "--dir", str(tmp_path)]
    )
    assert result.exit_code == 1
    assert result.output.strip().count("\n") == 0 and "no CUDA device" in result.output
    assert not any(tmp_path.iterdir())  # refused before anything was written


def test_torch_device_names() -> None:
    assert torch_device("cpu") == th.device("cpu")
    assert torch_device("auto") == th.device("cuda" if th.cuda.is_available() else "cpu")
    from pecli.errors import PecliError

    with pytest.raises(PecliError, match="unknown device"):
        torch_device("gpu")


@pytest.mark.parametrize("algo", ALGOS)
def test_actor_and_critic_use_fused_adam_and_crossq_keeps_its_betas(checkpoints, algo: str) -> None:
    _, model, _ = checkpoints[algo]
    for optimizer in (model.actor.optimizer, model.critic.optimizer):
        assert optimizer.defaults["fused"] is True
        assert optimizer.defaults["betas"] == ((0.5, 0.999) if algo == "crossq" else (0.9, 0.999))
