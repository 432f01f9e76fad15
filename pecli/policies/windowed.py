"""What every learned player does between decisions: memory, the decision clock and its random numbers.

A learned player (an SB3 checkpoint, or its ONNX export) is called at every game step. Like the
training view it keeps a history window updated at every step and a frame stack updated at
decision steps, and it decides every ``frame_skip`` steps, holding its action in between.
A ``bimdn-mixed`` belief needs random numbers at each decision; they come from the policy's own
NumPy generator (seeded by :meth:`~WindowedPolicy.reset`), so a checkpoint and its export draw the
same numbers under the same seed.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from typing import NamedTuple

import numpy as np

from pecli.game.memory import FrameStack, HistoryWindow
from pecli.roles import Role
from pecli.scenario import Scenario

Draws = tuple[np.ndarray, np.ndarray]  # uniform (n, samples) and normal (n, samples, 2), float32


class Decision(NamedTuple):
    """What a decision step hands to the network: the deciding games (``(n,)`` bool) and their inputs."""

    due: np.ndarray
    stack: np.ndarray  # (d, k * dim) frame stacks
    history: np.ndarray | None  # (d, samples * dim) windows, or None without a belief
    draws: Draws | None


class WindowedPolicy(ABC):
    """Frame stack, history window and frame skip around a decision function :meth:`_decide`.

    Args:
        role: the role it plays.
        scenario: the game; observations have its layout.
        frame_skip, frame_stack: as in training.
        history_length, history_stride: the belief's window; ``None`` for a player without a belief.
        draws: random numbers a mixed belief reads per decision (its ``samples``), 0 for none.
        seed: seed of those random numbers (:meth:`reset` with a seed restarts them).
    """

    def __init__(
        self,
        role: Role,
        scenario: Scenario,
        frame_skip: int,
        frame_stack: int,
        history_length: int | None,
        history_stride: int,
        draws: int = 0,
        seed: int | None = None,
    ) -> None:
        self.role = role
        self.scenario = scenario
        self.frame_skip, self.frame_stack = frame_skip, frame_stack
        self.history_length, self.history_stride = history_length, history_stride
        self.draws = draws
        self.rng = np.random.default_rng(seed)
        self.n = 0
        self._fresh = np.zeros(0, dtype=bool)
        self._stack: FrameStack | None = None
        self._history: HistoryWindow | None = None

    def reset(self, n: int, mask: np.ndarray | None = None, seed: int | None = None) -> None:
        if seed is not None:
            self.rng = np.random.default_rng(seed)
        if mask is None or n != self.n:
            self.n = n
            self._fresh = np.ones(n, dtype=bool)
            self._clock = np.zeros(n, dtype=np.int64)
            self._action = np.zeros((n, 2), dtype=np.float32)
            self._ended = np.zeros(n, dtype=bool)
            self._stack = None
            self._history = None
        else:
            self._fresh |= np.asarray(mask, dtype=bool)
            self._ended &= ~np.asarray(mask, dtype=bool)

    def end(self, mask: np.ndarray) -> None:
        """The games in ``mask`` (``(n,)`` bool) have ended: skip their decisions until they restart.

        A hint from a caller that keeps stepping finished (frozen) games, such as a match: the
        networks then run only for games still in play. Their memory keeps being updated.
        """
        self._ended |= np.asarray(mask, dtype=bool)

    def act(self, obs: np.ndarray) -> np.ndarray:
        decision = self.observe(obs)
        if decision is not None:
            self.settle(decision.due, self.decide(decision))
        return self._action.copy()

    def observe(self, obs: np.ndarray) -> Decision | None:
        """The first half of :meth:`act`: update the memory with ``obs`` and, if any game decides now, return
        what :meth:`_decide` takes for them; :meth:`settle` then takes their actions. (A caller that decides
        for many players at once, :class:`~pecli.policies.mixed.MixedPolicy`, calls the two halves itself.)"""
        obs = np.asarray(obs, dtype=np.float32)
        if obs.shape[0] != self.n:
            self.reset(obs.shape[0])
        if self._stack is None:
            dim = obs.shape[1]
            self._stack = FrameStack(self.n, dim, self.frame_stack)
            if self.history_length is not None:
                self._history = HistoryWindow(self.n, dim, self.history_length, self.history_stride)
        fresh = self._fresh
        if self._history is not None:
            self._history.push(obs)
        if fresh.any():
            self._clock[fresh] = 0
            self._stack.reset(obs, mask=fresh)
            if self._history is not None:
                self._history.reset(obs, mask=fresh)
            self._fresh = np.zeros(self.n, dtype=bool)
        due = (self._clock % self.frame_skip == 0) & ~self._ended
        self._clock += 1
        if not due.any():
            return None
        stack = self._stack.push(obs, mask=due)[due]
        history = self._history.get()[due] if self._history is not None else None
        return Decision(due, stack, history, self._draw(int(due.sum())))

    def decide(self, decision: Decision) -> np.ndarray:
        """The actions ``(d, 2)`` of the games of ``decision`` (from :meth:`observe`)."""
        return self._decide(decision.stack, decision.history, decision.draws, decision.due)

    def settle(self, due: np.ndarray, actions: np.ndarray) -> None:
        """The second half of :meth:`act`: the games ``due`` hold ``actions`` until they decide again."""
        self._action[due] = actions

    def held(self) -> np.ndarray:
        """The action each game holds, ``(n, 2)``: what :meth:`act` returned last (not a copy)."""
        return self._action

    def _draw(self, rows: int) -> Draws | None:
        """The random numbers of one decision for ``rows`` games, or ``None`` without a mixed belief."""
        if not self.draws:
            return None
        uniform = self.rng.random((rows, self.draws), dtype=np.float32)
        normal = self.rng.standard_normal((rows, self.draws, 2), dtype=np.float32)
        return uniform, normal

    def memory(self, games: int | None = None) -> tuple[np.ndarray, np.ndarray | None] | None:
        """The frame stacks ``(g, k * dim)`` and history windows ``(g, samples * dim)`` (``None`` without a
        belief) of the first ``games`` games as of the last :meth:`act`; ``None`` before it."""
        if self._stack is None:
            return None
        return self._stack.get()[:games], None if self._history is None else self._history.get()[:games]

    @abstractmethod
    def _decide(
        self, stack: np.ndarray, history: np.ndarray | None, draws: Draws | None, due: np.ndarray
    ) -> np.ndarray:
        """Actions ``(d, 2)`` in [-1, 1] for the ``d`` games deciding now (``due``, ``(n,)`` bool):
        their frame stacks ``(d, k * dim)``, history windows ``(d, samples * dim)`` and draws."""
