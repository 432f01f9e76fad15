"""The game as a PettingZoo ``ParallelEnv``, for multi-agent libraries that speak PettingZoo.

    >>> env = parallel_env("paper")
    >>> observations, infos = env.reset(seed=0)
    >>> while env.agents:
    ...     actions = {agent: env.action_space(agent).sample() for agent in env.agents}
    ...     observations, rewards, terminations, truncations, infos = env.step(actions)

Agents are ``"pursuer"`` and ``"evader"``; both act every step. ``state()`` is the privileged
full state scaled to [-1, 1] plus ``t/T``, for centralised critics. A capture and the timeout
both *terminate* the episode: the timeout is part of the game (it is observed through the time
index and carries the -lambda_capture reward), not an external truncation.

``infos`` have the same keys after ``reset`` as after ``step``: ``captured``, ``distance`` (m) and
``sees_opponent``. TorchRL's ``PettingZooWrapper`` builds its info spec from the first reset, so
these reach its tensordicts (and BenchMARL's logs).

The env runs :class:`~pecli.game.single.SingleGame`, the scalar mirror of the batched game,
which steps one game about 20 times faster than ``Game(n=1)``.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from gymnasium import spaces
from pettingzoo import ParallelEnv

from pecli.game.single import SingleGame
from pecli.roles import ROLES, Role
from pecli.scenario import Scenario, load_scenario


class PursuitEvasionEnv(ParallelEnv):
    """One pursuit-evasion game with the PettingZoo parallel API."""

    metadata = {"name": "pecli_pursuit_evasion_v0", "render_modes": [], "is_parallelizable": True}

    def __init__(self, scenario: Scenario | str = "paper") -> None:
        self.scenario = load_scenario(scenario) if isinstance(scenario, str) else scenario
        self.possible_agents: list[Role] = list(ROLES)
        self.agents: list[Role] = []
        self.render_mode = None
        self._game = SingleGame(self.scenario)  # reset(seed=...) makes it reproducible
        self.observation_spaces = {
            role: spaces.Box(-1.0, 1.0, shape=(self._game.obs_dim[role],), dtype=np.float32) for role in ROLES
        }
        self.action_spaces = {role: spaces.Box(-1.0, 1.0, shape=(2,), dtype=np.float32) for role in ROLES}
        self.state_space = spaces.Box(-1.0, 1.0, shape=(self._game.state_dim + 1,), dtype=np.float32)

    def observation_space(self, agent: Role) -> spaces.Box:
        return self.observation_spaces[agent]

    def action_space(self, agent: Role) -> spaces.Box:
        return self.action_spaces[agent]

    def reset(
        self, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[dict[Role, np.ndarray], dict[Role, dict]]:
        obs = self._game.reset(seed=seed)
        self.agents = list(self.possible_agents)
        return obs, self._reset_infos(obs)

    def _reset_infos(self, obs: dict[Role, np.ndarray]) -> dict[Role, dict[str, Any]]:
        """The infos of a step, for the start state: no capture, the distance (m) and the seen flags."""
        state = self._game.state().tolist()
        k = 5 if self.scenario.pursuer.kind == "car" else 4  # the pursuer's state comes first
        dx, dy = state[k] - state[0], state[k + 1] - state[1]
        distance = math.sqrt(dx * dx + dy * dy)
        return {
            role: {"captured": False, "distance": distance, "sees_opponent": bool(obs[role][-2] > 0.0)}
            for role in ROLES
        }

    def step(self, actions: dict[Role, np.ndarray]) -> tuple[dict, dict, dict, dict, dict]:
        if not self.agents:
            raise RuntimeError("the episode is over: call reset() first")
        missing = [role for role in ROLES if role not in actions]
        if missing:
            raise KeyError(f"no action for {', '.join(missing)}")
        result = self._game.step(actions["pursuer"], actions["evader"])
        done = result.done
        terminations = {role: done for role in ROLES}
        truncations = {role: False for role in ROLES}
        infos = {
            role: {"captured": result.captured, "distance": result.distance, "sees_opponent": result.seen[role]}
            for role in ROLES
        }
        if done:
            self.agents = []
        return result.obs, result.rewards, terminations, truncations, infos

    def state(self) -> np.ndarray:
        return self._game.normalised_state()

    def render(self, mode: str | None = None) -> None:
        """Not supported step by step; use ``pecli play --render`` for pictures and GIFs.

        ``mode`` is ignored: RLlib's ``ParallelPettingZooEnv.render`` passes its render mode.
        """
        return None

    def close(self) -> None:
        return None


def parallel_env(scenario: Scenario | str = "paper") -> PursuitEvasionEnv:
    """PettingZoo-style constructor."""
    return PursuitEvasionEnv(scenario)
