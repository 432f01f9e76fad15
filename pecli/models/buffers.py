"""Replay buffers for pecli's ``Dict`` observations: n-step returns, and the concatenating samples CrossQ needs.

SB3 computes n-step returns (its ``NStepReplayBuffer``) only for flat observations; pecli's learners
always see a ``Dict`` (the actor's observation beside the critic's privileged state), so
:class:`NStepDictReplayBuffer` does the same for them. With ``n_step = 1`` it samples exactly as SB3's
``DictReplayBuffer``.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch as th
from stable_baselines3.common.buffers import DictReplayBuffer, ReplayBuffer
from stable_baselines3.common.type_aliases import DictReplayBufferSamples


def end_episodes(buffer: ReplayBuffer) -> None:
    """Mark the newest row of every env as the end of its episode, a truncation where it was not one already.

    Call it where a learner abandons its games in flight (a self-play turn that starts new games, a
    resumed run): otherwise an n-step return that starts just before would run on into the next,
    unrelated game. A truncation bootstraps from the row's own next observation, so one-step samples
    do not change.
    """
    if buffer.pos == 0 and not buffer.full:
        return
    row = (buffer.pos - 1) % buffer.buffer_size
    buffer.timeouts[row] = np.where(buffer.dones[row] > 0, buffer.timeouts[row], 1.0)
    buffer.dones[row] = 1.0


class NStepDictReplayBuffer(DictReplayBuffer):
    """SB3's ``DictReplayBuffer`` whose samples carry ``n_step``-step returns.

    A sample starting at row ``t`` of one env sums ``gamma**k * r[t+k]`` up to the first episode end
    (termination or truncation) within ``n_step`` rows, bootstraps from the next observation of the
    last row it used, and reports the discount ``gamma**(rows used)`` in ``discounts``, which every
    SB3 / sb3-contrib off-policy algorithm multiplies the target value with. The newest row is treated as
    an episode end while sampling, so that no return runs into rows not yet written (or, once the ring
    is full, into the oldest ones), as SB3's ``NStepReplayBuffer`` does.

    Args:
        n_step: rewards summed before bootstrapping (1: the ordinary one-step target).
        gamma: the algorithm's discount factor.
    """

    def __init__(self, *args: Any, n_step: int = 1, gamma: float = 0.99, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        if n_step < 1:
            raise ValueError(f"n_step must be at least 1, not {n_step}")
        self.n_step = int(n_step)
        self.gamma = float(gamma)

    def _get_samples(self, batch_inds: np.ndarray, env: Any = None) -> DictReplayBufferSamples:  # type: ignore[override]
        if self.n_step == 1:
            return super()._get_samples(batch_inds, env)
        envs = np.random.randint(0, high=self.n_envs, size=(len(batch_inds),))
        rows = (batch_inds[:, None] + np.arange(self.n_step)) % self.buffer_size  # (B, n)
        ends = np.logical_or(self.dones[rows, envs[:, None]], self.timeouts[rows, envs[:, None]])
        ends[rows == (self.pos - 1) % self.buffer_size] = True  # the newest row ends every return
        used = np.where(ends.any(axis=1), ends.argmax(axis=1), self.n_step - 1) + 1  # rows in each return
        mask = np.arange(self.n_step) < used[:, None]
        rewards = self._normalize_reward(self.rewards[rows, envs[:, None]], env)
        returns = (rewards * self.gamma ** np.arange(self.n_step) * mask).sum(axis=1, keepdims=True)
        last = rows[np.arange(len(batch_inds)), used - 1]
        dones = self.dones[last, envs] * (1 - self.timeouts[last, envs])
        obs = self._normalize_obs({key: o[batch_inds, envs, :] for key, o in self.observations.items()}, env)
        next_obs = self._normalize_obs({key: o[last, envs, :] for key, o in self.next_observations.items()}, env)
        return DictReplayBufferSamples(
            observations={key: self.to_torch(o) for key, o in obs.items()},
            actions=self.to_torch(self.actions[batch_inds, envs]),
            next_observations={key: self.to_torch(o) for key, o in next_obs.items()},
            dones=self.to_torch(dones.reshape(-1, 1)),
            rewards=self.to_torch(returns.astype(np.float32)),
            discounts=self.to_torch((self.gamma**used).astype(np.float32).reshape(-1, 1)),
        )


class TensorDict(dict):
    """A ``dict`` of tensors that ``torch.cat`` concatenates key by key.

    CrossQ passes observations and next observations through its critics in one batch,
    ``th.cat([obs, next_obs])``, which torch cannot do for ``Dict`` observations; this type answers
    ``torch.cat`` through torch's ``__torch_function__`` protocol.
    """

    @classmethod
    def __torch_function__(cls, func: Any, types: Any, args: tuple = (), kwargs: dict | None = None) -> Any:
        if func is not th.cat:
            return NotImplemented
        parts, *rest = args
        return cls({key: th.cat([part[key] for part in parts], *rest, **(kwargs or {})) for key in parts[0]})


class ConcatDictReplayBuffer(NStepDictReplayBuffer):
    """:class:`NStepDictReplayBuffer` whose samples' observations are :class:`TensorDict` (for CrossQ)."""

    def _get_samples(self, batch_inds: np.ndarray, env: Any = None) -> DictReplayBufferSamples:  # type: ignore[override]
        samples = super()._get_samples(batch_inds, env)
        return samples._replace(
            observations=TensorDict(samples.observations), next_observations=TensorDict(samples.next_observations)
        )
