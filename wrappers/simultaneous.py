"""Both players learn at once: one batched game seen from both sides, with an SB3 ``VecEnv`` face per side.

The paper trains with MADDPG: in every game both learners act, each holding its action for
``frame_skip`` game steps, and both learn from every step. :class:`SimultaneousGame` holds ``n``
games and both sides' memories (frame stack, belief window); ``faces[role]`` is that side's
``VecEnv``, with the observation of :class:`~wrappers.frozen_opponent.FrozenOpponentVecEnv`. The
game steps once both faces have an action: ``step_async`` on each face, then ``step_wait`` on each.

``opp_action``, the other side's action that a centralised critic reads, is the other learner's
decision, not the game's: the faces leave it zero and the training loop fills it in
(:mod:`pecli.rl.simultaneous`). A face's ``reset`` starts new games unless the other face has just
done so, in which case it returns those games' observations: SB3 resets each model's environment.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from stable_baselines3.common.vec_env.base_vec_env import VecEnvStepReturn

from pecli.game import Game
from pecli.game.memory import FrameStack, HistoryWindow
from pecli.game.spaces import ACTION_SPACE, observation_space
from pecli.roles import ROLES, Role
from pecli.scenario import Scenario
from wrappers.frozen_opponent import DelegatingVecEnv


class Side:
    """One side's view of the shared games: its frame stack and belief window (what a belief wrapper
    reads as its view's ``core``)."""

    def __init__(self, game: Game, scenario: Scenario, role: Role, history: bool) -> None:
        self.game, self.scenario, self.training, self.role = game, scenario, scenario.training, role
        t, dim = scenario.training, game.obs_dim[role]
        self.stack = FrameStack(game.n, dim, t.frame_stack)
        self.history = HistoryWindow(game.n, dim, t.history_length, t.history_stride) if history else None
        self.observation_space = observation_space(game, role, t, history)
        self.action_space = ACTION_SPACE

    def restart(self, obs: np.ndarray, mask: np.ndarray | None = None) -> None:
        """Begin the memories of the games in ``mask`` (all by default) at their first observations ``(n, dim)``."""
        self.stack.reset(obs, mask=mask)
        if self.history is not None:
            self.history.reset(obs, mask=mask)

    def observation(self, rows: np.ndarray | slice = slice(None)) -> dict[str, np.ndarray]:
        obs = {"obs": self.stack.get()[rows]}
        if self.history is not None:
            obs["history"] = self.history.get()[rows]
        obs["state"] = self.game.normalised_state()[rows]
        obs["opp_action"] = np.zeros((obs["obs"].shape[0], 2), np.float32)
        return obs


class SimultaneousGame:
    """``n`` games played by two learners at once.

    Args:
        scenario: the game; its ``training`` section sets frame skip/stack, window and reward scale.
        n: number of games (each face's ``num_envs``).
        seed: seed of the start states.
        history: per role, whether its observation has the belief window ``history``.
    """

    def __init__(self, scenario: Scenario, n: int, seed: int = 0, history: dict[Role, bool] | None = None) -> None:
        history = history or {}
        self.n, self.training = n, scenario.training
        self.render_mode = None
        self.game = Game(scenario, n=n, seed=seed)
        self.sides = {role: Side(self.game, scenario, role, history.get(role, False)) for role in ROLES}
        self.faces = {role: SideVecEnv(self, role) for role in ROLES}
        self.next_seed: int | None = seed
        self._actions: dict[Role, np.ndarray] = {}
        self._results: dict[Role, tuple] = {}
        self._reset_for: set[Role] = set()  # the faces that were handed the current fresh games
        self._return = np.zeros(n)

    def set_curriculum(self, pursuer_fov: float, evader_speed_scale: float) -> None:
        """Turn the game's curriculum knobs (paper §V-A)."""
        self.game.fov["pursuer"] = pursuer_fov
        self.game.speed_scale["evader"] = evader_speed_scale

    def reset_for(self, role: Role) -> dict[str, np.ndarray]:
        """The fresh games' observations for ``role``; new games unless the other face just started them."""
        if not self._reset_for or role in self._reset_for:
            seed, self.next_seed = self.next_seed, None
            obs = self.game.reset(seed=seed)
            for side in ROLES:
                self.sides[side].restart(obs[side])
            self._return[:] = 0.0
            self._reset_for = set()
            self._actions, self._results = {}, {}
        self._reset_for.add(role)
        return self.sides[role].observation()

    def act(self, role: Role, action: np.ndarray) -> None:
        """``role``'s actions ``(n, 2)`` for the next step; the games step once both sides have acted."""
        self._actions[role] = np.asarray(action, dtype=np.float64).reshape(self.n, 2)
        if len(self._actions) == len(ROLES):
            self._results = self._step(self._actions["pursuer"], self._actions["evader"])
            self._actions = {}

    def result(self, role: Role) -> VecEnvStepReturn:
        """What the last step gave ``role``: observations, scaled rewards, dones, infos."""
        if role not in self._results:
            raise RuntimeError("both faces must step_async before either can step_wait")
        return self._results.pop(role)

    def _step(self, pursuer_action: np.ndarray, evader_action: np.ndarray) -> dict[Role, tuple]:
        """Hold both actions for ``frame_skip`` game steps; restart the games that end."""
        self._reset_for = set()
        reward = np.zeros(self.n)  # the pursuer's; the evader's is its negative
        done = np.zeros(self.n, dtype=bool)
        captured = np.zeros(self.n, dtype=bool)
        for _ in range(self.training.frame_skip):
            result = self.game.step(pursuer_action, evader_action)
            reward += result.rewards["pursuer"]
            done |= result.done
            captured |= result.captured
            for role in ROLES:
                if self.sides[role].history is not None:
                    self.sides[role].history.push(result.obs[role])
            if self.game.finished.all():
                break
        for role in ROLES:
            self.sides[role].stack.push(result.obs[role])
        self._return += reward
        infos: dict[Role, list[dict[str, Any]]] = {
            role: [{"TimeLimit.truncated": False} for _ in range(self.n)] for role in ROLES
        }
        if done.any():
            ended = np.flatnonzero(done)
            for role in ROLES:
                terminal = self.sides[role].observation(ended)
                sign = 1.0 if role == "pursuer" else -1.0
                for j, i in enumerate(ended):
                    infos[role][i].update(
                        terminal_observation={key: value[j].copy() for key, value in terminal.items()},
                        episode={"r": float(sign * self._return[i]), "l": int(self.game.t[i])},
                        captured=bool(captured[i]),
                    )
            self._return[ended] = 0.0
            fresh = self.game.reset(mask=done)
            for role in ROLES:
                self.sides[role].restart(fresh[role], mask=done)
        scaled = (reward * self.training.reward_scale).astype(np.float32)
        return {
            role: (self.sides[role].observation(), scaled if role == "pursuer" else -scaled, done.copy(), infos[role])
            for role in ROLES
        }


class SideVecEnv(DelegatingVecEnv):
    """One side's SB3 ``VecEnv`` over a :class:`SimultaneousGame`."""

    def __init__(self, games: SimultaneousGame, role: Role) -> None:
        self.games = self.target = games
        self.role = role
        self.core = games.sides[role]
        super().__init__(games.n, self.core.observation_space, self.core.action_space)

    def reset(self) -> dict[str, np.ndarray]:
        return self.games.reset_for(self.role)

    def step_async(self, actions: np.ndarray) -> None:
        self.games.act(self.role, actions)

    def step_wait(self) -> VecEnvStepReturn:
        return self.games.result(self.role)

    def seed(self, seed: int | None = None) -> list[int | None]:
        self.games.next_seed = seed
        return [seed] * self.num_envs
