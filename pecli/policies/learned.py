"""A trained checkpoint as a :class:`Policy`: SB3's actor with the memory it was trained with.

At play time the policy is called at every game step. Like the training view it keeps a
history window updated at every step and a frame stack updated at decision steps, and it
decides every ``frame_skip`` steps, holding its action in between.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import torch as th

from pecli.errors import PolicyError
from pecli.game.memory import FrameStack, HistoryWindow
from pecli.roles import Role
from pecli.scenario import Scenario
from pecli.zoo import CheckpointMeta, ZooError, read_metadata


def algorithm_class(algo: str) -> Any:
    """The SB3 algorithm class of ``algo`` (``td3`` or ``ddpg``)."""
    from stable_baselines3 import DDPG, TD3

    classes = {"td3": TD3, "ddpg": DDPG}
    if algo not in classes:
        raise PolicyError(f"unknown algorithm '{algo}' (known: {', '.join(classes)})")
    return classes[algo]


class LearnedPolicy:
    """Plays with the actor of an SB3 model.

    Args:
        actor: the model's actor network (reads ``obs`` and, with a belief, ``history``).
        role: the role it plays.
        scenario: the game; observations have its layout.
        meta: the checkpoint's metadata (frame skip/stack and history window come from it).
    """

    def __init__(self, actor: th.nn.Module, role: Role, scenario: Scenario, meta: CheckpointMeta) -> None:
        self.actor = actor
        self.role = role
        self.scenario = scenario
        self.meta = meta
        self.n = 0
        self._fresh = np.zeros(0, dtype=bool)
        self._history: HistoryWindow | None = None
        self._generator: th.Generator | None = None
        self._belief = getattr(actor.features_extractor, "belief", None)

    @classmethod
    def load(cls, path: str | Path, role: Role, scenario: Scenario, seed: int | None = None) -> LearnedPolicy:
        """Load a zoo checkpoint; refuses one of another role or trained on another scenario."""
        path = Path(path)
        try:
            meta = read_metadata(path)
        except ZooError as exc:
            raise PolicyError(str(exc)) from None
        if meta.role != role:
            raise PolicyError(f"{path} is a {meta.role} checkpoint; it cannot play {role}")
        if meta.scenario_hash != scenario.fingerprint():
            raise PolicyError(
                f"{path} was trained on scenario '{meta.scenario}' ({meta.scenario_hash}), not on "
                f"'{scenario.name}' ({scenario.fingerprint()}): pass the config it was trained with"
            )
        try:
            model = algorithm_class(meta.algo).load(path, device="cpu")
        except Exception as exc:  # a truncated or foreign zip: SB3 raises many kinds
            raise PolicyError(f"cannot load {path}: {type(exc).__name__}: {exc}") from None
        return cls(model.policy.actor, role, scenario, meta)

    def reset(self, n: int, mask: np.ndarray | None = None, seed: int | None = None) -> None:
        if seed is not None:  # the draws of a mixed belief follow the seed
            self._generator = th.Generator().manual_seed(seed)
        if mask is None or n != self.n:
            self.n = n
            self._fresh = np.ones(n, dtype=bool)
            self._clock = np.zeros(n, dtype=np.int64)
            self._action = np.zeros((n, 2), dtype=np.float32)
            self._stack: FrameStack | None = None
            self._history = None
        else:
            self._fresh |= np.asarray(mask, dtype=bool)

    def act(self, obs: np.ndarray) -> np.ndarray:
        obs = np.asarray(obs, dtype=np.float32)
        if obs.shape[0] != self.n:
            self.reset(obs.shape[0])
        if self._stack is None:
            dim = obs.shape[1]
            self._stack = FrameStack(self.n, dim, self.meta.frame_stack)
            if self.meta.belief != "none":
                self._history = HistoryWindow(self.n, dim, self.meta.history_length, self.meta.history_stride)
        fresh = self._fresh
        if self._history is not None:
            self._history.push(obs)
        if fresh.any():
            self._clock[fresh] = 0
            self._stack.reset(obs, mask=fresh)
            if self._history is not None:
                self._history.reset(obs, mask=fresh)
            self._fresh = np.zeros(self.n, dtype=bool)
        due = self._clock % self.meta.frame_skip == 0
        self._clock += 1
        if due.any():
            batch = {"obs": self._stack.push(obs, mask=due)[due]}
            if self._history is not None:
                batch["history"] = self._history.get()[due]
            self._action[due] = self._forward(batch)
        return self._action.copy()

    def current_belief(self, games: int | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
        """The belief given the window of the last :meth:`act`, for drawing, for the first ``games`` games:
        ``(weights (g, K), means (g, K, 2), stds (g, K, 2))`` in normalised world coordinates;
        ``None`` for a policy without a belief."""
        if self._belief is None or self._history is None:
            return None
        with th.no_grad():
            mixture = self._belief.mixture(th.as_tensor(self._history.get()[:games]))
        return mixture.weights.numpy(), mixture.means.numpy(), mixture.stds.numpy()

    def _forward(self, batch: dict[str, np.ndarray]) -> np.ndarray:
        """SB3's ``Actor.forward`` without its preprocessing, which insists on the training-time keys
        (a belief's actor trained on stored ``belief`` features but plays from the ``history`` window)."""
        if self._belief is not None:  # this policy's draws; the model may be shared with a learner
            previous, self._belief.generator = self._belief.generator, self._generator
        try:
            with th.no_grad():
                features = self.actor.features_extractor({key: th.as_tensor(value) for key, value in batch.items()})
                return self.actor.mu(features).numpy()
        finally:
            if self._belief is not None:
                self._belief.generator = previous

    def __repr__(self) -> str:
        return f"LearnedPolicy(role={self.role!r}, algo={self.meta.algo!r}, steps={self.meta.steps})"
