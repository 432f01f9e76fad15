"""A mixture of policies: every game of a batch is played by one member, drawn when the game starts.

This is how self-play faces a whole pool of opponents inside one batched simulation: game ``i``
is played by member ``assignment[i]`` for a whole episode, and a new member is drawn (by
``weights``) each time the game restarts.
"""

from __future__ import annotations

import sys
from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np

from pecli.metagame import mixture_weights
from pecli.policies.base import Policy
from pecli.roles import Role

if TYPE_CHECKING:
    from pecli.policies.stacked import StackedActors
    from pecli.policies.windowed import Decision


class MixedPolicy:
    """Plays ``role`` in ``n`` games, each game by one of ``members`` drawn with probability ``weights``.

    Args:
        role: the role every member plays.
        members: the policies to draw from.
        names: one label per member, reported per game by :attr:`game_labels`.
        weights: draw probabilities (normalised here); default uniform. Can be changed while playing:
            new weights apply to the games that start afterwards.
        stack: let learned members of one network shape decide together in one batched pass
            (:mod:`pecli.policies.stacked`; the same actions up to float rounding, cheaper with many members).

    Each member keeps its own memory for all ``n`` games, but is only asked to act while it plays
    at least one game; a game handed to a member restarts that member's memory for it.
    """

    def __init__(
        self,
        role: Role,
        members: Sequence[Policy],
        names: Sequence[str],
        weights: Sequence[float] | None = None,
        stack: bool = True,
    ) -> None:
        if not members:
            raise ValueError("a mixed policy needs at least one member")
        if len(names) != len(members):
            raise ValueError(f"{len(members)} members but {len(names)} names")
        for member in members:
            if member.role != role:
                raise ValueError(f"every member must play {role}; {member!r} plays {member.role}")
        self.role = role
        self.identity: str | None = None  # what a tournament's cache knows the mixture by, when it has a fixed one
        self.members = list(members)
        self.names = list(names)
        self.weights = np.full(len(members), 1.0 / len(members)) if weights is None else weights
        self.n = 0
        self.assignment = np.zeros(0, dtype=np.int64)
        self._rng = np.random.default_rng()
        self._stacked: dict[int, tuple[StackedActors, int]] = {}  # learned members of one shape decide together
        learned = sys.modules.get("pecli.policies.learned")  # none is learned unless that module was loaded
        if stack and learned is not None and sum(isinstance(m, learned.LearnedPolicy) for m in self.members) > 1:
            from pecli.policies.stacked import StackedActors

            self._stacked = StackedActors.of(self.members)

    @property
    def weights(self) -> np.ndarray:
        """Draw probabilities of the members, ``(members,)``, summing to 1."""
        return self._weights

    @weights.setter
    def weights(self, value: Sequence[float]) -> None:
        self._weights = mixture_weights(value, len(self.members))

    @property
    def game_labels(self) -> list[str]:
        """The name of the member playing each game, ``n`` entries."""
        return [self.names[k] for k in self.assignment]

    def reset(self, n: int, mask: np.ndarray | None = None, seed: int | None = None) -> None:
        if seed is not None:
            self._rng = np.random.default_rng(seed)
        if mask is None or n != self.n:
            self.n = n
            member_seeds = self._rng.integers(0, 2**31, size=len(self.members)) if seed is not None else None
            for k, member in enumerate(self.members):
                member.reset(n, seed=None if member_seeds is None else int(member_seeds[k]))
            self.assignment = np.zeros(n, dtype=np.int64)
            mask = np.ones(n, dtype=bool)
        mask = np.asarray(mask, dtype=bool)
        drawn = self._rng.choice(len(self.members), size=int(mask.sum()), p=self._weights)
        self.assignment[mask] = drawn
        for k in np.unique(drawn):
            self.members[k].reset(n, mask=mask & (self.assignment == k))
        for k, member in enumerate(self.members):  # learned members decide only for their own games
            end = getattr(member, "end", None)
            if end is not None:
                end(self.assignment != k)

    def act(self, obs: np.ndarray) -> np.ndarray:
        obs = np.asarray(obs)
        if obs.shape[0] != self.n:
            self.reset(obs.shape[0])
        actions = np.zeros((self.n, 2))
        present = {k: self.assignment == k for k in np.unique(self.assignment).tolist()}  # member -> its games
        waiting: dict[StackedActors, list[tuple[int, Decision]]] = {}
        for k, rows in present.items():
            if k in self._stacked:  # its memory now; its decision below, with the others of its stack
                decision = self.members[k].observe(obs)
                if decision is not None:
                    waiting.setdefault(self._stacked[k][0], []).append((k, decision))
            else:
                actions[rows] = np.asarray(self.members[k].act(obs))[rows]
        for stack, decisions in waiting.items():
            if stack.worth_it(len(decisions), sum(len(d.stack) for _, d in decisions)):
                decided = stack.decide(
                    [self._stacked[k][1] for k, _ in decisions],
                    [d.stack for _, d in decisions],
                    [d.history for _, d in decisions],
                )
            else:  # too few to gain from deciding together
                decided = [self.members[k].decide(d) for k, d in decisions]
            for (k, decision), chosen in zip(decisions, decided):
                self.members[k].settle(decision.due, chosen)
        for k, rows in present.items():
            if k in self._stacked:
                actions[rows] = self.members[k].held()[rows]
        return actions

    def __repr__(self) -> str:
        return f"MixedPolicy(role={self.role!r}, members={self.names})"
