"""The one interface for everything that acts: heuristics, learned checkpoints, ONNX models, HJ policies.

A policy plays one role in ``n`` games at once. It keeps whatever memory it needs (the last
sighting, a search timer, a history window) inside, one entry per game, and restarts that
memory for the games its caller resets.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from typing import Protocol, runtime_checkable

import numpy as np

from pecli.game.observation import Decoded, ObservationCodec
from pecli.roles import Role
from pecli.scenario import Scenario


@runtime_checkable
class Policy(Protocol):
    """Acts for one role in a batch of games.

    Attributes:
        role: ``"pursuer"`` or ``"evader"``.
    """

    role: Role

    def reset(self, n: int, mask: np.ndarray | None = None, seed: int | None = None) -> None:
        """Start ``n`` games, or restart only the games where ``mask`` (``(n,)`` bool) is true."""
        ...

    def act(self, obs: np.ndarray) -> np.ndarray:
        """Actions ``(n, 2)`` in [-1, 1] for observations ``(n, obs_dim)``."""
        ...

    # Optional: ``end(mask)``, told by a match which games have ended (their actions no longer
    # matter until a reset), so that an expensive policy can skip them. Learned players have it.


class HeuristicPolicy(ABC):
    """Shared plumbing of the hand-written baselines: a decoder for observations, per-game memory, an RNG.

    Subclasses set ``roles`` (the roles they can play) and implement :meth:`_act`, and may
    override :meth:`_restart` to clear their memory for some games.
    """

    roles: tuple[Role, ...] = ("pursuer", "evader")
    name: str = "heuristic"

    def __init__(self, scenario: Scenario, role: Role, seed: int | None = None) -> None:
        if role not in self.roles:
            raise ValueError(f"{self.name} cannot play {role}")
        self.scenario = scenario
        self.role = role
        self.params = scenario.agent(role)
        self.codec = ObservationCodec(scenario, role)
        self.rng = np.random.default_rng(seed)
        self.n = 0

    def reset(self, n: int, mask: np.ndarray | None = None, seed: int | None = None) -> None:
        if seed is not None:
            self.rng = np.random.default_rng(seed)
        if mask is None or n != self.n:
            self.n = n
            self._allocate(n)
            mask = np.ones(n, dtype=bool)
        self._restart(np.asarray(mask, dtype=bool))

    def act(self, obs: np.ndarray) -> np.ndarray:
        obs = np.asarray(obs)
        if obs.ndim != 2 or obs.shape[1] != self.codec.dim:
            raise ValueError(f"{self.name} expects observations of shape (n, {self.codec.dim}), got {obs.shape}")
        if obs.shape[0] != self.n:
            self.reset(obs.shape[0])
        return np.clip(self._act(self.codec.decode(obs)), -1.0, 1.0)

    def _allocate(self, n: int) -> None:  # noqa: B027 (a hook: memoryless policies have nothing to allocate)
        """Create the per-game memory for ``n`` games."""

    def _restart(self, mask: np.ndarray) -> None:  # noqa: B027 (a hook)
        """Clear the memory of the games where ``mask`` is true."""

    @abstractmethod
    def _act(self, view: Decoded) -> np.ndarray:
        """Actions ``(n, 2)`` from the decoded observations."""

    def __repr__(self) -> str:
        return f"{type(self).__name__}(role={self.role!r})"
