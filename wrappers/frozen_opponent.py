"""The learner's view of the two-player game: one role learns, the other is a frozen :class:`Policy`.

:class:`FrozenOpponentVecEnv` is an SB3 ``VecEnv`` over ``n`` games of one batched
:class:`~pecli.game.Game` in one process (the fast path); :class:`FrozenOpponentEnv` is a plain
``gymnasium.Env`` over one game. Both share :class:`FrozenOpponentCore`.

Each learner step holds the action for ``frame_skip`` game steps (the opponent acts at every
game step) and sums the rewards, scaled by ``reward_scale``. The observation is a flat ``Dict``:

``obs``         the last ``frame_stack`` observations of the learner, ``(k * dim,)``
``history``     the belief window: every ``history_stride``-th of the last ``history_length``
                game-step observations, ``(samples * dim,)``; left out with ``history=False``
                (a learner without a belief never reads it, and it would fill most of the replay buffer)
``state``       the privileged full state scaled to [-1, 1] plus ``t/T``, ``(state_dim + 1,)``
``opp_action``  the action the opponent takes at this step, ``(2,)``

The actor reads ``obs`` (and, with a belief, ``history``); a centralised critic also reads
``state`` and ``opp_action``. Finished games restart inside ``step``; the last observation of an
episode is in ``info["terminal_observation"]``, and ``info["episode"]`` holds its unscaled
return ``r`` and length ``l`` (game steps) as SB3's ``Monitor`` would, ``info["captured"]`` the
outcome, and, when the opponent names who played each game (a :class:`~pecli.policies.mixed.MixedPolicy`'s
``game_labels``), ``info["opponent"]`` that name.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
from stable_baselines3.common.vec_env.base_vec_env import VecEnv, VecEnvIndices, VecEnvStepReturn

from pecli.game import Game
from pecli.game.memory import FrameStack, HistoryWindow
from pecli.game.spaces import ACTION_SPACE, observation_space
from pecli.policies.base import Policy
from pecli.roles import Role, opponent_of
from pecli.scenario import Scenario, Training


class FrozenOpponentCore:
    """``n`` games seen by the ``role`` learner, with ``opponent`` playing the other side."""

    def __init__(
        self,
        scenario: Scenario,
        role: Role,
        opponent: Policy,
        n: int,
        seed: int = 0,
        training: Training | None = None,
        history: bool = True,
    ) -> None:
        if opponent.role != opponent_of(role):
            raise ValueError(f"the opponent of a {role} must play {opponent_of(role)}, not {opponent.role}")
        self.scenario = scenario
        self.training = training or scenario.training
        self.role, self.opponent_role = role, opponent_of(role)
        self.opponent = opponent
        self.n = n
        self.game = Game(scenario, n=n, seed=seed)
        dim = self.game.obs_dim[role]
        t = self.training
        self.stack = FrameStack(n, dim, t.frame_stack)
        self.history = HistoryWindow(n, dim, t.history_length, t.history_stride) if history else None
        self.observation_space = observation_space(self.game, role, t, history)
        self.action_space = ACTION_SPACE
        self.render_mode = None
        self._opponent_obs = np.zeros((n, self.game.obs_dim[self.opponent_role]), np.float32)
        self._opponent_action = np.zeros((n, 2))
        self._return = np.zeros(n)
        self._opponent_seed = int(np.random.SeedSequence([seed, 1]).generate_state(1)[0])

    def set_curriculum(self, pursuer_fov: float, evader_speed_scale: float) -> None:
        """Turn the game's curriculum knobs (paper §V-A)."""
        self.game.fov["pursuer"] = pursuer_fov
        self.game.speed_scale["evader"] = evader_speed_scale

    def set_opponent(self, opponent: Policy) -> None:
        """Play against ``opponent`` from the next :meth:`reset` on (self-play swaps pools between rounds)."""
        if opponent.role != self.opponent_role:
            raise ValueError(f"the opponent of a {self.role} must play {self.opponent_role}, not {opponent.role}")
        self.opponent = opponent

    def reset(self, seed: int | None = None) -> dict[str, np.ndarray]:
        """Start every game; a ``seed`` restarts the start-state sequence."""
        obs = self.game.reset(seed=seed)
        if seed is not None:
            self._opponent_seed = int(np.random.SeedSequence([seed, 1]).generate_state(1)[0])
        self.opponent.reset(self.n, seed=self._opponent_seed)
        own = obs[self.role]
        self.stack.reset(own)
        if self.history is not None:
            self.history.reset(own)
        self._return[:] = 0.0
        self._opponent_obs = obs[self.opponent_role]
        self._opponent_action = self._act_opponent()
        return self._observation()

    def _act_opponent(self) -> np.ndarray:
        return np.asarray(self.opponent.act(self._opponent_obs), dtype=np.float64)

    def _observation(self, rows: np.ndarray | slice = slice(None)) -> dict[str, np.ndarray]:
        obs = {"obs": self.stack.get()[rows]}
        if self.history is not None:
            obs["history"] = self.history.get()[rows]
        obs["state"] = self.game.normalised_state()[rows]
        obs["opp_action"] = self._opponent_action[rows].astype(np.float32)
        return obs

    def step(self, action: np.ndarray) -> tuple[dict[str, np.ndarray], np.ndarray, np.ndarray, list[dict[str, Any]]]:
        """Hold ``action`` ``(n, 2)`` for ``frame_skip`` game steps; restart games that end."""
        action = np.asarray(action, dtype=np.float64).reshape(self.n, 2)
        reward = np.zeros(self.n)
        done = np.zeros(self.n, dtype=bool)
        captured = np.zeros(self.n, dtype=bool)
        for i in range(self.training.frame_skip):
            opponent_action = self._opponent_action if i == 0 else self._act_opponent()
            if self.role == "pursuer":
                result = self.game.step(action, opponent_action)
            else:
                result = self.game.step(opponent_action, action)
            reward += result.rewards[self.role]  # finished (frozen) games add 0
            done |= result.done
            captured |= result.captured
            if self.history is not None:
                self.history.push(result.obs[self.role])
            self._opponent_obs = result.obs[self.opponent_role]
            if self.game.finished.all():
                break
        self.stack.push(result.obs[self.role])
        self._return += reward
        infos: list[dict[str, Any]] = [{"TimeLimit.truncated": False} for _ in range(self.n)]
        if done.any():
            ended = np.flatnonzero(done)
            self._opponent_action[ended] = 0.0  # no action follows the end of a game
            terminal = self._observation(ended)
            labels = getattr(self.opponent, "game_labels", None)
            for j, i in enumerate(ended):
                infos[i].update(
                    terminal_observation={key: value[j].copy() for key, value in terminal.items()},
                    episode={"r": float(self._return[i]), "l": int(self.game.t[i])},
                    captured=bool(captured[i]),
                )
                if labels is not None:
                    infos[i]["opponent"] = labels[i]
            self._return[ended] = 0.0
            fresh = self.game.reset(mask=done)
            self.opponent.reset(self.n, mask=done)
            self.stack.reset(fresh[self.role], mask=done)
            if self.history is not None:
                self.history.reset(fresh[self.role], mask=done)
            self._opponent_obs = fresh[self.opponent_role]
        self._opponent_action = self._act_opponent()
        scaled = (reward * self.training.reward_scale).astype(np.float32)
        return self._observation(), scaled, done, infos


class DelegatingVecEnv(VecEnv):
    """The ``VecEnv`` plumbing shared by pecli's views: attributes and methods go to ``self.target``,
    the object that holds the games (one object for all ``num_envs`` games)."""

    target: Any

    def set_curriculum(self, pursuer_fov: float, evader_speed_scale: float) -> None:
        self.target.set_curriculum(pursuer_fov, evader_speed_scale)

    def close(self) -> None:
        return None

    def get_attr(self, attr_name: str, indices: VecEnvIndices = None) -> list[Any]:
        return [getattr(self.target, attr_name)] * len(self._get_indices(indices))

    def set_attr(self, attr_name: str, value: Any, indices: VecEnvIndices = None) -> None:
        setattr(self.target, attr_name, value)

    def env_method(self, method_name: str, *args: Any, indices: VecEnvIndices = None, **kwargs: Any) -> list[Any]:
        result = getattr(self.target, method_name)(*args, **kwargs)
        return [result] * len(self._get_indices(indices))

    def env_is_wrapped(self, wrapper_class: type[gym.Wrapper], indices: VecEnvIndices = None) -> list[bool]:
        return [False] * len(self._get_indices(indices))


class FrozenOpponentVecEnv(DelegatingVecEnv):
    """SB3 ``VecEnv`` over ``n`` games of one batched game, in one process.

    Args:
        scenario: the game; its ``training`` section sets frame skip/stack, window and reward scale.
        role: the learner's role.
        opponent: the frozen opponent, any :class:`Policy` of the other role.
        n: number of games (SB3's ``n_envs``).
        seed: seed of the start states and of the opponent's randomness.
        history: include the belief window ``history`` in the observation.
    """

    def __init__(
        self, scenario: Scenario, role: Role, opponent: Policy, n: int, seed: int = 0, history: bool = True
    ) -> None:
        self.core = self.target = FrozenOpponentCore(scenario, role, opponent, n, seed, history=history)
        super().__init__(n, self.core.observation_space, self.core.action_space)
        self._actions: np.ndarray | None = None
        self._next_seed: int | None = seed

    def reset(self) -> dict[str, np.ndarray]:
        seed, self._next_seed = self._next_seed, None
        return self.core.reset(seed=seed)

    def step_async(self, actions: np.ndarray) -> None:
        self._actions = actions

    def step_wait(self) -> VecEnvStepReturn:
        if self._actions is None:
            raise RuntimeError("step_async() must come before step_wait()")
        obs, rewards, dones, infos = self.core.step(self._actions)
        self._actions = None
        return obs, rewards, dones, infos

    def seed(self, seed: int | None = None) -> list[int | None]:
        self._next_seed = seed
        return [seed] * self.num_envs


class FrozenOpponentEnv(gym.Env):
    """The same view as a ``gymnasium.Env`` over one game (for tools that want a plain env).

    An episode ends with ``terminated=True`` on capture or timeout (the timeout is part of the game).
    """

    metadata = {"render_modes": []}

    def __init__(self, scenario: Scenario, role: Role, opponent: Policy, seed: int = 0) -> None:
        self.core = FrozenOpponentCore(scenario, role, opponent, n=1, seed=seed)
        self.observation_space = self.core.observation_space
        self.action_space = self.core.action_space

    def reset(self, *, seed: int | None = None, options: dict | None = None) -> tuple[dict[str, np.ndarray], dict]:
        super().reset(seed=seed)
        obs = self.core.reset(seed=seed)
        return {key: value[0] for key, value in obs.items()}, {}

    def step(self, action: np.ndarray) -> tuple[dict[str, np.ndarray], float, bool, bool, dict[str, Any]]:
        obs, reward, done, infos = self.core.step(np.asarray(action).reshape(1, 2))
        info = infos[0]
        if done[0]:
            return info.pop("terminal_observation"), float(reward[0]), True, False, info
        return {key: value[0] for key, value in obs.items()}, float(reward[0]), False, False, info
