"""Training with a belief: features computed when transitions are collected, and the belief's own fitting.

A BiLSTM inside every TD3 gradient step would make training 40-50x slower (211 ms against 5 ms a step at batch
256 on one core). So, as the paper puts it, each observation is *extended* with the belief:
:class:`BeliefVecEnv` runs the belief once per vector step, batched over all games, replaces the ``history``
window by the belief features in what the replay buffer stores, and keeps the (window, true opponent position)
pairs in a :class:`BeliefBuffer` of its own. :class:`FitBelief` fits the belief network on those by negative
log-likelihood with its own optimiser (paper: buffer 25 000, warm-up 10 000, an update every 10 steps, batch
256, Adam 0.002). The features stored with older transitions were computed by an older belief; the actor reads
them as they were when the transition happened.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch as th
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.vec_env import VecEnvWrapper

from pecli.belief.model import BeliefModel
from pecli.models.extractors import belief_observation_space
from pecli.roles import Role
from pecli.scenario import BeliefSettings
from wrappers.frozen_opponent import FrozenOpponentVecEnv


class BeliefBuffer:
    """A ring buffer of belief training pairs: flattened windows, true positions, and whether unseen."""

    def __init__(self, capacity: int, window_size: int, seed: int = 0) -> None:
        self.history = np.zeros((capacity, window_size), dtype=np.float32)
        self.target = np.zeros((capacity, 2), dtype=np.float32)
        self.unseen = np.zeros(capacity, dtype=bool)
        self.capacity, self.size, self.cursor = capacity, 0, 0
        self.added = 0  # pairs ever added
        self.rng = np.random.default_rng(seed)

    def add(self, history: np.ndarray, target: np.ndarray, unseen: np.ndarray) -> None:
        """Append ``n`` pairs (rows of each array), overwriting the oldest when full."""
        rows = (self.cursor + np.arange(history.shape[0])) % self.capacity
        self.history[rows], self.target[rows], self.unseen[rows] = history, target, unseen
        self.set_count(self.added + history.shape[0])

    def set_count(self, added: int) -> None:
        """Make the buffer hold the newest of ``added`` pairs (a restored buffer's arrays already hold them)."""
        self.added = added
        self.cursor, self.size = added % self.capacity, min(added, self.capacity)

    def arrays(self) -> dict[str, np.ndarray]:
        """The ring's arrays, ``(capacity, ...)`` each, by name (for saving and restoring)."""
        return {"history": self.history, "target": self.target, "unseen": self.unseen}

    def sample(self, batch: int) -> tuple[th.Tensor, th.Tensor, np.ndarray]:
        index = self.rng.integers(0, self.size, size=batch)
        return th.as_tensor(self.history[index]), th.as_tensor(self.target[index]), self.unseen[index]


class BeliefVecEnv(VecEnvWrapper):
    """Swaps the view's ``history`` for ``belief`` features and records belief training pairs.

    Args:
        venv: the frozen-opponent view, built with ``history=True``.
        features_dim: size of the belief features.
        buffer: where (window, position) pairs go; ``None`` for a belief that does not learn.
        belief: the belief whose features the actor reads (the actor's extractor's :class:`BeliefModel`);
            usually set later with :meth:`set_belief`, once the model exists, before the first reset.
    """

    def __init__(
        self,
        venv: FrozenOpponentVecEnv,
        features_dim: int,
        buffer: BeliefBuffer | None,
        belief: BeliefModel | None = None,
    ) -> None:
        core = venv.core
        if core.history is None:
            raise ValueError("the view must be built with history=True to feed a belief")
        role: Role = core.role
        self.belief, self.buffer = belief, buffer
        self._features_dim = features_dim
        super().__init__(venv, observation_space=belief_observation_space(venv.observation_space, features_dim))
        # where the truth is: the opponent's (x, y) in the normalised state, and the newest seen flag
        self._target = (
            slice(0, 2)
            if role == "evader"
            else slice(core.game.dynamics["pursuer"].state_dim, core.game.dynamics["pursuer"].state_dim + 2)
        )
        dim = core.game.obs_dim[role]
        self._seen_index = (core.training.frame_stack - 1) * dim + core.game.codecs[role].seen_index

    def set_belief(self, belief: BeliefModel) -> None:
        if belief.features_dim != self._features_dim:
            raise ValueError(f"the belief has {belief.features_dim} features, the space {self._features_dim}")
        self.belief = belief

    def _convert(self, obs: dict[str, np.ndarray], record: bool) -> dict[str, np.ndarray]:
        if self.belief is None:
            raise RuntimeError("set_belief() before using the environment")
        history = obs.pop("history")
        obs["belief"] = self.belief.features_numpy(history)
        if record and self.buffer is not None:
            self.buffer.add(history, obs["state"][:, self._target], obs["obs"][:, self._seen_index] < 0)
        return obs

    def reset(self) -> dict[str, np.ndarray]:
        return self._convert(self.venv.reset(), record=True)

    def step_wait(self) -> Any:
        obs, rewards, dones, infos = self.venv.step_wait()
        ended = [info for info in infos if "terminal_observation" in info]
        if ended:  # one batched belief pass for every game that ended this step
            batch = {
                key: np.stack([info["terminal_observation"][key] for info in ended])
                for key in ended[0]["terminal_observation"]
            }
            converted = self._convert(batch, record=False)
            for j, info in enumerate(ended):
                info["terminal_observation"] = {key: value[j] for key, value in converted.items()}
        return self._convert(obs, record=True), rewards, dones, infos


class FitBelief(BaseCallback):
    """Fits a learned belief on its own buffer, loss and optimiser; logs its NLL and unseen-position error.

    ``belief/nll`` is the batch's negative log-likelihood; ``belief/unseen_error_m`` the mean distance
    (metres) between the mixture's mean and the opponent's true position over the batch's samples
    in which the opponent was not seen.
    """

    def __init__(
        self, belief: BeliefModel, buffer: BeliefBuffer, settings: BeliefSettings, half: tuple[float, float]
    ) -> None:
        super().__init__()
        self.belief, self.buffer, self.settings = belief, buffer, settings
        self.optimizer = th.optim.Adam(belief.parameters(), lr=settings.learning_rate)
        self.half = th.tensor(half, dtype=th.float32)

    def _on_step(self) -> bool:
        s = self.settings
        vector_steps = self.num_timesteps // self.training_env.num_envs  # restored on resume, unlike n_calls
        if vector_steps % s.update_every == 0 and self.buffer.size >= max(s.warmup, 1):
            self.update()
        return True

    def update(self) -> float:
        history, target, unseen = self.buffer.sample(self.settings.batch_size)
        device = self.belief.device  # the fitter runs where the actor's networks are (--device)
        history, target = history.to(device), target.to(device)
        self.belief.train()
        mixture = self.belief.mixture(history)
        loss = mixture.nll(target)
        self.optimizer.zero_grad()
        loss.backward()
        th.nn.utils.clip_grad_norm_(self.belief.parameters(), self.settings.max_grad_norm)
        self.optimizer.step()
        self.logger.record("belief/nll", loss.item())
        if unseen.any():
            with th.no_grad():
                error = (
                    ((mixture.mean() - target) * self.half.to(device))
                    .norm(dim=1)[th.as_tensor(unseen, device=device)]
                    .mean()
                )
            self.logger.record("belief/unseen_error_m", float(error))
        return loss.item()
