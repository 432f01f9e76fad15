"""The opponent pool of self-play: who is in it, how each has fared, and how opponents are drawn.

Four ways to draw (``training.selfplay.opponents``):

``latest``   the newest generation only (the baselines, until a learner has finished a round);
``uniform``  every entry alike: fictitious self-play;
``pfsp``     prioritised fictitious self-play: an entry's weight is ``p ** power``, where ``p``
             estimates how often it beats the current learner, so the learner practises most
             against what still beats it. ``p`` pools the learner's own episodes against the entry
             with a prior worth ``prior_episodes`` episodes: the prediction of a tournament's
             ratings when one rated both, else 0.5.
``nash``     the league's structure (floor, exploiters' share) around the Nash mixture of the pools' meta-game
             (:mod:`pecli.metagame`, PSRO's meta-solver, Lanctot et al. 2017) instead of pfsp: the learner
             practises against the mixture of the other side that no player of its own side's pool beats.
``league``   pfsp, with the scripted players (generation 0) keeping ``floor`` of the draws
             between them whatever their records, so that a learner never forgets them; the floor
             is split among them alike (``split="uniform"``) or by their pfsp weights (``"pfsp"``:
             most to the scripted players that still beat the learner). The exploiters that joined
             the pool may keep ``exploiter_share`` of the draws in the same way, split by their pfsp
             weights (AlphaStar's main agents spend a share of their games on the league's
             exploiters, evaders of other lineages than their own).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

from pecli.roles import Role
from pecli.stats import ELO_SCALE

MAIN, EXPLOITER = "main", "exploiter"  # the league's learners: one main and one exploiter per side
STRATEGIES = ("latest", "uniform", "pfsp", "league", "nash")
LEAGUES = ("league", "nash")  # the rules with a league's structure: scripted floor, exploiters
FLOOR_SPLITS = ("uniform", "pfsp")
MIN_SHARE = 0.02  # (ours) pfsp never starves an entry: each keeps >= 2 % of a uniform draw's share


@dataclass
class PoolEntry:
    """One opponent: a policy string (built-in name or checkpoint path) and its record against the learner."""

    name: str
    spec: str
    generation: int  # 0 for the baselines, r for the learner's checkpoint after round r
    episodes: float = 0.0  # episodes the current learner (decayed over rounds) played against it
    wins: float = 0.0  # of those, how many the entry won

    @property
    def kind(self) -> str:
        """Whose checkpoint it is: a league exploiter's (named ``exploiter-<role>-rNNN`` when it joined), else
        ``main`` (a main learner's, or a scripted player)."""
        return EXPLOITER if self.name.startswith(f"{EXPLOITER}-") else MAIN

    def win_rate(self, prior: float = 0.5, prior_episodes: float = 10.0) -> float:
        """Estimated probability that this entry beats the learner."""
        return (self.wins + prior * prior_episodes) / (self.episodes + prior_episodes)


@dataclass
class OpponentPool:
    """The pool of one ``role``: entries in the order they joined."""

    role: Role
    entries: list[PoolEntry] = field(default_factory=list)

    def add(self, name: str, spec: str, generation: int) -> PoolEntry:
        if any(e.name == name for e in self.entries):
            raise ValueError(f"the {self.role} pool already holds '{name}'")
        entry = PoolEntry(name, spec, generation)
        self.entries.append(entry)
        return entry

    def entry(self, name: str) -> PoolEntry:
        for e in self.entries:
            if e.name == name:
                return e
        raise KeyError(name)

    def observe(self, name: str, entry_won: bool) -> None:
        """Count one finished episode of the learner against ``name``."""
        e = self.entry(name)
        e.episodes += 1
        e.wins += float(entry_won)

    def decay(self, keep: float) -> None:
        """The learner changed (a new round): keep only ``keep`` of every record."""
        for e in self.entries:
            e.episodes *= keep
            e.wins *= keep

    def weights(
        self,
        strategy: str,
        power: float = 2.0,
        priors: dict[str, float] | None = None,
        prior_episodes: float = 10.0,
        floor: float = 0.0,
        split: str = "uniform",
        exploiter_share: float = 0.0,
        nash: dict[str, float] | None = None,
    ) -> np.ndarray:
        """Draw probabilities of the entries under ``strategy``, ``(entries,)``; ``floor``, ``split`` and
        ``exploiter_share`` only for ``league`` and ``nash``, ``nash`` (the meta-game's mixture of this pool, by
        entry name) only for ``nash``."""
        if not self.entries:
            raise ValueError(f"the {self.role} pool is empty")
        k = len(self.entries)
        if strategy == "uniform":
            w = np.ones(k)
        elif strategy == "latest":
            newest = max(e.generation for e in self.entries)
            w = np.array([float(e.generation == newest) for e in self.entries])
        elif strategy in LEAGUES:
            if split not in FLOOR_SPLITS:
                raise ValueError(f"unknown league floor split '{split}' (known: {', '.join(FLOOR_SPLITS)})")
            pfsp = self.weights("pfsp", power, priors, prior_episodes)
            base = pfsp if strategy == "league" else self._mixture(nash or {})
            scripted = np.array([e.generation == 0 for e in self.entries], dtype=float)
            exploiters = np.array([e.kind == EXPLOITER for e in self.entries], dtype=float)
            kept, w = 0.0, np.zeros(k)
            for group, share, by in ((scripted, floor, split), (exploiters, exploiter_share, "pfsp")):
                if share > 0 and 0 < group.sum() < k:  # a group that is the whole pool keeps its pfsp weights
                    part = group * pfsp if by == "pfsp" else group
                    w += share * part / part.sum()
                    kept += share
            w += (1.0 - kept) * base
        elif strategy == "pfsp":
            priors = priors or {}
            p = np.array([e.win_rate(priors.get(e.name, 0.5), prior_episodes) for e in self.entries])
            w = p**power
            w = w / w.sum() if w.sum() > 0 else np.ones(k) / k
            w = np.maximum(w, MIN_SHARE / k)
        else:
            raise ValueError(f"unknown opponent sampling '{strategy}' (known: {', '.join(STRATEGIES)})")
        return w / w.sum()

    def _mixture(self, weights: dict[str, float]) -> np.ndarray:
        """The entries' weights in a mixture given by name (absent: 0), normalised; uniform if none has weight."""
        w = np.array([max(0.0, float(weights.get(e.name, 0.0))) for e in self.entries])
        return w / w.sum() if w.sum() > 0 else np.full(len(self.entries), 1.0 / len(self.entries))

    def to_dict(self) -> dict[str, Any]:
        return {"role": self.role, "entries": [asdict(e) for e in self.entries]}

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> OpponentPool:
        return cls(data["role"], [PoolEntry(**e) for e in data["entries"]])


def predicted_win_rate(entry_elo: float, learner_elo: float) -> float:
    """P(entry beats learner) from Bradley–Terry ratings in pecli's Elo points."""
    return 1.0 / (1.0 + math.exp(-(entry_elo - learner_elo) / ELO_SCALE))
