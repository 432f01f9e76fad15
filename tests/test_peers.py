"""pecli's PettingZoo env inside other multi-agent libraries (the ``peers`` extra): RLlib, TorchRL, BenchMARL.

Each test wraps the env as the library's documentation shows and runs a few steps of the library's own
sampling loop; each is skipped where its library is not installed.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from pecli.game.pettingzoo_env import parallel_env

INFO_KEYS = {"captured", "distance", "sees_opponent"}


def test_rllib_env_runner_samples_one_module_per_agent() -> None:
    pytest.importorskip("ray.rllib")
    from ray.rllib.algorithms.ppo import PPOConfig
    from ray.rllib.env.multi_agent_env_runner import MultiAgentEnvRunner
    from ray.rllib.env.wrappers.pettingzoo_env import ParallelPettingZooEnv
    from ray.rllib.utils.pre_checks.env import check_multiagent_environments
    from ray.tune.registry import register_env

    check_multiagent_environments(ParallelPettingZooEnv(parallel_env("paper")))
    register_env("pecli", lambda config: ParallelPettingZooEnv(parallel_env(config["scenario"])))
    config = (
        PPOConfig()
        .environment("pecli", env_config={"scenario": "quick"})
        .env_runners(num_env_runners=0)
        .multi_agent(policies={"pursuer", "evader"}, policy_mapping_fn=lambda agent_id, episode, **kwargs: agent_id)
        .debugging(seed=0)
    )
    runner = MultiAgentEnvRunner(config=config)
    try:
        episodes = runner.sample(num_timesteps=200)  # the untrained modules act; quick's horizon is 150 steps
    finally:
        runner.stop()
    assert sum(episode.env_steps() for episode in episodes) == 200
    assert any(episode.is_terminated for episode in episodes)
    env = parallel_env("quick")
    for episode in episodes:
        assert set(episode.agent_ids) == {"pursuer", "evader"}
        observations = episode.get_observations(-1)
        assert all(env.observation_space(agent).contains(observations[agent]) for agent in env.possible_agents)
        assert set(episode.get_infos(0)["pursuer"]) == INFO_KEYS


def test_torchrl_wrapper_passes_its_spec_check_and_collects() -> None:
    pytest.importorskip("torchrl")
    from torchrl.collectors import Collector
    from torchrl.envs import PettingZooWrapper
    from torchrl.envs.utils import check_env_specs

    env = PettingZooWrapper(env=parallel_env("paper"), return_state=True)
    check_env_specs(env, seed=0)
    assert env.group_map == {"pursuer": ["pursuer"], "evader": ["evader"]}
    rollout = env.rollout(450, break_when_any_done=False)  # paper's horizon is 400 steps
    assert rollout["next", "done"].any()
    assert set(rollout["next", "pursuer", "info"].keys()) == INFO_KEYS
    assert rollout["next", "state"].shape == (450, *env.observation_spec["state"].shape)

    collector = Collector(
        lambda: PettingZooWrapper(env=parallel_env("quick")), policy=None, frames_per_batch=100, total_frames=200
    )
    try:
        frames = [batch.numel() for batch in collector]
    finally:
        collector.shutdown()
    assert frames == [100, 100]


def test_benchmarl_runs_a_custom_task(tmp_path: Path) -> None:
    pytest.importorskip("benchmarl")
    from benchmarl.algorithms import MasacConfig
    from benchmarl.experiment import Experiment, ExperimentConfig
    from benchmarl.models.mlp import MlpConfig

    from pecli.peers.benchmarl import PecliTask

    config = ExperimentConfig.get_from_yaml()
    config.loggers, config.evaluation, config.render, config.create_json = [], False, False, False
    config.share_policy_params = False  # one policy per agent
    config.max_n_iters = 2
    config.off_policy_collected_frames_per_batch = 100
    config.off_policy_n_envs_per_worker = 2
    config.off_policy_n_optimizer_steps = 2
    config.off_policy_train_batch_size = 32
    config.off_policy_memory_size = 1_000
    config.save_folder = str(tmp_path)
    experiment = Experiment(
        task=PecliTask("quick", {"scenario": "quick"}),
        algorithm_config=MasacConfig.get_from_yaml(),
        model_config=MlpConfig.get_from_yaml(),
        critic_model_config=MlpConfig.get_from_yaml(),
        seed=0,
        config=config,
    )
    experiment.run()
    assert experiment.n_iters_performed == 2 and experiment.total_frames == 200
    assert set(experiment.group_map) == {"pursuer", "evader"}
    assert np.isfinite(experiment.replay_buffers["pursuer"].sample()["next", "pursuer", "reward"].numpy()).all()
