"""The centralised critic, SB3 save/load, and a checkpoint playing exactly as it trained."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch as th
from stable_baselines3 import DDPG, TD3

from pecli.game import Game
from pecli.models.policies import CentralCriticPolicy
from pecli.policies import resolve_policy
from pecli.policies.learned import LearnedPolicy
from pecli.rl.train import TrainJob, make_model, with_overrides
from pecli.scenario import Scenario
from wrappers.frozen_opponent import FrozenOpponentVecEnv


def tiny(scenario: Scenario) -> Scenario:
    return with_overrides(scenario, {"buffer_size": 500, "batch_size": 16, "learning_starts": 50, "net_arch": [32, 32]})


def model_for(scenario: Scenario, algo: str = "td3", n: int = 4, belief: str = "none"):
    scenario = with_overrides(tiny(scenario), {"algo": algo, "belief": belief, "belief_settings.hidden": 16})
    job = TrainJob(role="pursuer", scenario=scenario, opponent="greedy", zoo=Path("unused"), name="t")
    if belief == "none":
        env = FrozenOpponentVecEnv(scenario, "pursuer", resolve_policy("greedy", "evader", scenario), n=n, seed=0)
        return make_model(job, env, tensorboard=None), env
    from pecli.rl.train import make_env

    env = make_env(job, resolve_policy("greedy", "evader", scenario), seed=0)
    model = make_model(job, env, tensorboard=None)
    env.set_belief(model.policy.actor.features_extractor.belief)
    return model, env


def tensors(obs: dict[str, np.ndarray]) -> dict[str, th.Tensor]:
    return {key: th.as_tensor(value) for key, value in obs.items()}


@pytest.mark.parametrize("belief", ["none", "bimdn"])
def test_actor_ignores_privileged_keys_and_critic_reads_them(quick: Scenario, belief: str) -> None:
    model, env = model_for(quick, belief=belief)
    obs = env.reset()
    policy = model.policy
    assert isinstance(policy, CentralCriticPolicy)
    changed = {**obs, "state": -obs["state"] + 0.5, "opp_action": -obs["opp_action"] + 0.3}
    with th.no_grad():
        np.testing.assert_array_equal(policy.actor(tensors(obs)).numpy(), policy.actor(tensors(changed)).numpy())
        action = th.zeros((obs["obs"].shape[0], 2))
        q_before = policy.critic(tensors(obs), action)[0].numpy()
        q_after = policy.critic(tensors(changed), action)[0].numpy()
    assert not np.allclose(q_before, q_after)
    assert policy.critic.features_extractor.keys == ("obs", "state", "opp_action")
    if belief == "none":
        assert policy.actor.features_extractor.keys == ("obs",)
    else:  # the actor reads the stored belief: changing it changes the action
        moved = {**obs, "belief": obs["belief"] + 0.5}
        with th.no_grad():
            assert not np.allclose(policy.actor(tensors(obs)).numpy(), policy.actor(tensors(moved)).numpy())


@pytest.mark.parametrize(("algo", "belief"), [("td3", "none"), ("ddpg", "none"), ("td3", "bimdn")])
def test_save_and_load_round_trip(quick: Scenario, tmp_path: Path, algo: str, belief: str) -> None:
    model, env = model_for(quick, algo, belief=belief)
    model.learn(200)
    path = tmp_path / "model.zip"
    model.save(path)
    loaded = {"td3": TD3, "ddpg": DDPG}[algo].load(path, device="cpu")
    assert isinstance(loaded.policy, CentralCriticPolicy) and loaded.policy.critic_keys == model.policy.critic_keys
    obs = env.reset()
    np.testing.assert_array_equal(model.predict(obs, deterministic=True)[0], loaded.predict(obs, deterministic=True)[0])
    with th.no_grad():
        action = th.zeros((obs["obs"].shape[0], 2))
        np.testing.assert_array_equal(
            model.policy.critic(tensors(obs), action)[0].numpy(), loaded.policy.critic(tensors(obs), action)[0].numpy()
        )
    if belief != "none":  # the belief network travels in the zip
        for a, b in zip(
            model.policy.actor.features_extractor.belief.parameters(),
            loaded.policy.actor.features_extractor.belief.parameters(),
        ):
            assert th.equal(a, b)


def test_a_learned_policy_plays_exactly_as_in_its_training_view(quick: Scenario) -> None:
    """Same actor, same games: the view (frame skip, stack, window) and play time must agree step by step."""
    n, seed = 4, 2
    model, _ = model_for(quick, n=n)
    scenario = tiny(quick)
    view = FrozenOpponentVecEnv(scenario, "pursuer", resolve_policy("greedy", "evader", scenario), n=n, seed=seed)
    obs = view.reset()
    from pecli.rl.train import checkpoint_meta

    job = TrainJob(role="pursuer", scenario=scenario, opponent="greedy", zoo=Path("unused"), name="t")
    learner = LearnedPolicy(model.policy.actor, "pursuer", scenario, checkpoint_meta(job, model, 0))
    greedy = resolve_policy("greedy", "evader", scenario)
    game = Game(scenario, n=n, seed=seed)
    game_obs = game.reset(seed=seed)
    learner.reset(n)
    greedy.reset(n)
    for _ in range(60):
        with th.no_grad():
            action = model.policy.actor(tensors(obs)).numpy()
        obs, _, done, _ = view.step(action)
        if done.any():
            break
        for _ in range(scenario.training.frame_skip):
            played = learner.act(game_obs["pursuer"])
            np.testing.assert_allclose(played, action, atol=1e-6)
            game_obs = game.step(played, greedy.act(game_obs["evader"])).obs
        np.testing.assert_allclose(game.state(), view.core.game.state(), atol=1e-5)


def test_unknown_algorithm_is_refused() -> None:
    from pecli.errors import PolicyError
    from pecli.models.algorithms import get_algorithm

    with pytest.raises(PolicyError, match="unknown algorithm 'ppo'"):
        get_algorithm("ppo")
