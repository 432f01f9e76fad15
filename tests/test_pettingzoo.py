"""The PettingZoo adapter: the official API test, determinism, spaces."""

from __future__ import annotations

import numpy as np
import pytest
from pettingzoo.test import parallel_api_test

from pecli.game.pettingzoo_env import parallel_env


@pytest.mark.parametrize("name", ["paper", "car_vs_car", "point_mass"])
def test_parallel_api(name: str) -> None:
    parallel_api_test(parallel_env(name), num_cycles=300)


def rollout(seed: int, steps: int = 600) -> list:
    env = parallel_env("quick")
    rng = np.random.default_rng(0)
    obs, _ = env.reset(seed=seed)
    trace = []
    for _ in range(steps):
        if not env.agents:
            obs, _ = env.reset()
        actions = {agent: rng.uniform(-1, 1, 2).astype(np.float32) for agent in env.agents}
        obs, rewards, terminations, truncations, infos = env.step(actions)
        trace.append((obs["pursuer"].copy(), obs["evader"].copy(), rewards["pursuer"], terminations["pursuer"]))
    return trace


def test_multi_step_determinism() -> None:
    a, b = rollout(5), rollout(5)
    for x, y in zip(a, b):
        np.testing.assert_array_equal(x[0], y[0])
        np.testing.assert_array_equal(x[1], y[1])
        assert x[2:] == y[2:]
    assert any(x[3] for x in a), "expected at least one episode to end in 600 steps of quick.yaml"
    c = rollout(6)
    assert not all(np.array_equal(x[0], y[0]) for x, y in zip(a, c))


@pytest.mark.parametrize("name", ["paper", "car_vs_car", "point_mass", "robots"])
def test_every_observation_and_state_lies_in_its_space(name: str) -> None:
    env = parallel_env(name)
    rng = np.random.default_rng(1)
    obs, _ = env.reset(seed=0)
    for _ in range(500):
        if not env.agents:
            obs, _ = env.reset()
        for agent, value in obs.items():
            assert env.observation_space(agent).contains(value), (agent, value)
        assert env.state_space.contains(env.state())
        actions = {agent: env.action_space(agent).sample() for agent in env.agents}
        actions["pursuer"] = rng.choice([-1.0, 1.0], 2).astype(np.float32)
        obs, rewards, *_ = env.step(actions)
        assert rewards["pursuer"] == -rewards["evader"]


def test_step_after_the_end_is_refused() -> None:
    env = parallel_env("quick")
    env.reset(seed=0)
    env.agents = []
    with pytest.raises(RuntimeError, match="reset"):
        env.step({"pursuer": np.zeros(2), "evader": np.zeros(2)})


def test_reset_infos_have_the_keys_and_types_of_step_infos() -> None:
    env = parallel_env("paper")
    _, reset_infos = env.reset(seed=0)
    _, _, _, _, step_infos = env.step({agent: env.action_space(agent).sample() for agent in env.agents})
    for agent in env.possible_agents:
        assert {k: type(v) for k, v in reset_infos[agent].items()} == {k: type(v) for k, v in step_infos[agent].items()}
    assert reset_infos["pursuer"]["captured"] is False
    assert reset_infos["pursuer"]["distance"] == reset_infos["evader"]["distance"] > 0.0


def test_render_accepts_a_mode() -> None:
    env = parallel_env("quick")
    env.reset(seed=0)
    assert env.render() is None and env.render("human") is None
