"""The frozen-opponent training view: API checks, frame skip, rewards, resets, opponent actions."""

from __future__ import annotations

import math

import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env as gymnasium_check_env
from stable_baselines3.common.env_checker import check_env as sb3_check_env

from pecli.game import Game
from pecli.policies import resolve_policy
from pecli.scenario import Scenario
from wrappers.frozen_opponent import FrozenOpponentCore, FrozenOpponentEnv, FrozenOpponentVecEnv


@pytest.mark.parametrize("role", ["pursuer", "evader"])
def test_single_game_view_passes_gymnasium_and_sb3_checks(paper: Scenario, role: str) -> None:
    other = "greedy" if role == "pursuer" else "pure-pursuit"
    env = FrozenOpponentEnv(paper, role, resolve_policy(other, "evader" if role == "pursuer" else "pursuer", paper))
    gymnasium_check_env(env, skip_render_check=True)
    sb3_check_env(env, warn=False)


def test_observation_layout(paper: Scenario) -> None:
    env = FrozenOpponentVecEnv(paper, "pursuer", resolve_policy("greedy", "evader", paper), n=5, seed=0)
    obs = env.reset()
    assert obs["obs"].shape == (5, 22)  # 2 stacked frames of 11
    assert obs["history"].shape == (5, 20 * 11)
    assert obs["state"].shape == (5, 10)  # 9 state numbers and t/T
    assert obs["opp_action"].shape == (5, 2)
    for key, space in env.observation_space.spaces.items():
        assert all(space.contains(row) for row in obs[key]), key


def test_frame_skip_sums_scaled_rewards_and_matches_the_game(quick: Scenario) -> None:
    n, seed = 6, 4
    core = FrozenOpponentCore(quick, "pursuer", resolve_policy("greedy", "evader", quick), n=n, seed=seed)
    core.reset(seed=seed)
    game = Game(quick, n=n, seed=seed)
    opponent = resolve_policy("greedy", "evader", quick)
    opponent.reset(n)
    game_obs = game.reset(seed=seed)
    rng = np.random.default_rng(0)
    for _ in range(20):
        action = rng.uniform(-1, 1, (n, 2))
        obs, reward, done, _ = core.step(action)
        expected = np.zeros(n)
        for _ in range(2):
            result = game.step(action, opponent.act(game_obs["evader"]))
            expected += result.rewards["pursuer"]
            game_obs = result.obs
        if done.any():
            break
        np.testing.assert_allclose(reward, expected * quick.training.reward_scale, rtol=1e-6)
        np.testing.assert_array_equal(core.game.state(), game.state())
        np.testing.assert_array_equal(obs["obs"][:, 11:], game_obs["pursuer"])
    assert core.game.t.max() == game.t.max()


def test_opp_action_is_what_the_opponent_plays(paper: Scenario) -> None:
    core = FrozenOpponentCore(paper, "pursuer", resolve_policy("greedy", "evader", paper), n=8, seed=1)
    obs = core.reset()
    greedy = resolve_policy("greedy", "evader", paper)
    greedy.reset(8)
    np.testing.assert_allclose(obs["opp_action"], greedy.act(core.game.observe()["evader"]), atol=1e-6)


def test_finished_games_restart_with_terminal_observation_and_episode_info(paper: Scenario) -> None:
    env = FrozenOpponentVecEnv(paper, "pursuer", resolve_policy("greedy", "evader", paper), n=2, seed=0)
    env.reset()
    state = env.core.game.state()
    state[0, :5] = [0.0, 0.0, 0.0, 0.0, 0.0]
    state[0, 5:9] = [0.3, 0.0, 0.0, 0.0]  # game 0 is one step from capture
    env.core.game.set_state(state)
    obs, reward, done, infos = env.step(np.zeros((2, 2), dtype=np.float32))
    assert done.tolist() == [True, False]
    assert infos[0]["captured"] is True and infos[0]["episode"]["l"] == 1
    assert reward[0] == pytest.approx(paper.reward.capture * paper.training.reward_scale)
    terminal = infos[0]["terminal_observation"]
    assert set(terminal) == {"obs", "history", "state", "opp_action"} and terminal["obs"].shape == (22,)
    assert env.core.game.t[0] == 0  # restarted
    assert "terminal_observation" not in infos[1]


def test_curriculum_knobs_reach_the_game(paper: Scenario) -> None:
    env = FrozenOpponentVecEnv(paper, "evader", resolve_policy("pure-pursuit", "pursuer", paper), n=2, seed=0)
    env.env_method("set_curriculum", 2 * math.pi, 0.25)
    assert env.core.game.fov["pursuer"] == 2 * math.pi and env.core.game.speed_scale["evader"] == 0.25


def test_an_opponent_of_the_wrong_role_is_refused(paper: Scenario) -> None:
    with pytest.raises(ValueError, match="must play evader"):
        FrozenOpponentCore(paper, "pursuer", resolve_policy("pure-pursuit", "pursuer", paper), n=1)
