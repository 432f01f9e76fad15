"""Whom a self-play learner meets: the frozen players of the pools, and one rule per ``selfplay.opponents``.

Every rule gives the weights of the other side's pool entries for one learner's turn (:meth:`OpponentRule.weigher`):

``latest``, ``uniform``   the pool's own draw (:meth:`~pecli.rl.pool.OpponentPool.weights`);
``pfsp``, ``league``      prioritised by how often each entry beats the learner, its prior from the newest
                          tournament under the zoo that rated both (:class:`Prioritised`);
``nash``                  PSRO's meta-solver: the Nash mixture of the meta-game between the two pools, after
                          playing the pairings it lacks (:class:`NashMixture`).

The league's floor of scripted players and its exploiters' share apply around each of them.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np

from pecli.errors import PecliError
from pecli.match import play_match
from pecli.metagame import solve
from pecli.policies import resolve_policy
from pecli.policies.base import Policy
from pecli.policies.mixed import MixedPolicy
from pecli.policies.registry import recorded_policy
from pecli.rl.handover import STATE_FILE
from pecli.rl.pool import OpponentPool, predicted_win_rate
from pecli.rl.state import SelfPlayState
from pecli.roles import Role, opponent_of
from pecli.scenario import Scenario, SelfPlay
from pecli.tournament import tournament_ratings


class PoolPlayers:
    """The frozen players of a run's pools, each loaded once per process; a run from elsewhere is data (each
    entry's policy string is checked by :func:`~pecli.policies.registry.recorded_policy`)."""

    def __init__(self, run: Path, scenario: Scenario, seed: int) -> None:
        self.run, self.scenario, self.seed = run, scenario, seed
        self._loaded: dict[tuple[Role, str], Policy] = {}

    def spec(self, entry_spec: str) -> str:
        """The policy string of a pool entry: a checkpoint inside the run (run-relative) or a built-in."""
        target = str(self.run / entry_spec) if entry_spec.endswith(".zip") else entry_spec
        return recorded_policy(target, self.run, f"{self.run / STATE_FILE}")

    def load(self, role: Role, entry_spec: str) -> Policy:
        """A new player of the entry (its own memory, sized for the games it is given)."""
        return resolve_policy(self.spec(entry_spec), role, self.scenario, seed=self.seed)

    def player(self, role: Role, entry_spec: str) -> Policy:
        """The entry's player, loaded once."""
        if (role, entry_spec) not in self._loaded:
            self._loaded[role, entry_spec] = self.load(role, entry_spec)
        return self._loaded[role, entry_spec]

    def mixture(self, pool: OpponentPool) -> MixedPolicy:
        """The whole pool as one player whose games each draw a member (the weights come per turn)."""
        if not pool.entries:
            raise PecliError(f"the {pool.role} pool of run '{self.run.name}' is empty (damaged {STATE_FILE}?)")
        return MixedPolicy(
            pool.role, [self.player(pool.role, e.spec) for e in pool.entries], [e.name for e in pool.entries]
        )


class OpponentRule:
    """The pool's own draw (``latest``, ``uniform``): no prior, no meta-game."""

    def __init__(self, settings: SelfPlay) -> None:
        self.settings = settings

    def priors(self, learner: Role, state: SelfPlayState) -> dict[str, float]:
        """Each opponent's prior win rate against ``learner``'s latest checkpoint, by name (none known: {})."""
        return {}

    def mixture(self, side: Role, state: SelfPlayState) -> dict[str, float] | None:
        """A mixture over ``side``'s pool that replaces the records' weights (None: the records decide)."""
        return None

    def weigher(self, learner: Role, state: SelfPlayState) -> Callable[[OpponentPool], np.ndarray]:
        """The weights of the opponents' pool for ``learner``'s turn."""
        sp, priors, mixture = self.settings, self.priors(learner, state), self.mixture(opponent_of(learner), state)
        return lambda pool: pool.weights(
            sp.opponents,
            sp.pfsp_power,
            priors,
            sp.pfsp_prior_episodes,
            sp.league_floor,
            sp.league_floor_split,
            sp.league_exploiter_share,
            mixture,
        )


class Prioritised(OpponentRule):
    """``pfsp`` and ``league``: priors from the newest tournament under ``zoo`` that rated the learner's latest
    checkpoint and the entries."""

    def __init__(self, settings: SelfPlay, run: Path, zoo: Path) -> None:
        super().__init__(settings)
        self.run, self.zoo = run, zoo

    def priors(self, learner: Role, state: SelfPlayState) -> dict[str, float]:
        mine = [t for t in state.turns if t.role == learner and t.learner == "main"]
        if not mine:
            return {}
        ratings = tournament_ratings(self.zoo)
        rated = ratings.get(str((self.run / mine[-1].checkpoint).resolve()))
        if rated is None or rated.get("role") != learner:
            return {}
        other = opponent_of(learner)
        priors = {}
        for e in state.pools[other].entries:
            key = str((self.run / e.spec).resolve()) if e.spec.endswith(".zip") else f"{other}:{e.spec}"
            if key in ratings and ratings[key].get("role") == other:
                priors[e.name] = predicted_win_rate(ratings[key]["elo"], rated["elo"])
        return priors


class NashMixture(OpponentRule):
    """``nash``: the other side's Nash mixture of the meta-game between the two pools (:mod:`pecli.metagame`).
    Each pairing the record lacks plays ``nash_games`` games from the same start states first; the record is
    kept in ``state.payoffs`` and saved with the turn."""

    def __init__(self, settings: SelfPlay, players: PoolPlayers) -> None:
        super().__init__(settings)
        self.players = players

    def mixture(self, side: Role, state: SelfPlayState) -> dict[str, float]:
        pursuers, evaders = state.pools["pursuer"].entries, state.pools["evader"].entries
        missing = [(p, e) for p in pursuers for e in evaders if f"{p.name}|{e.name}" not in state.payoffs]
        loaded: dict[tuple[Role, str], Policy] = {}  # fresh players: the pools' own are sized for the learner's games

        def player(role: Role, spec: str) -> Policy:
            if (role, spec) not in loaded:
                loaded[role, spec] = self.players.load(role, spec)
            return loaded[role, spec]

        for p, e in missing:
            match, _ = play_match(
                self.players.scenario,
                player("pursuer", p.spec),
                player("evader", e.spec),
                self.settings.nash_games,
                seed=state.seed,
            )
            state.payoffs[f"{p.name}|{e.name}"] = [int(match.captured.sum()), match.episodes]
        rates = np.array(
            [
                [state.payoffs[f"{p.name}|{e.name}"][0] / state.payoffs[f"{p.name}|{e.name}"][1] for e in evaders]
                for p in pursuers
            ]
        )
        return solve([p.name for p in pursuers], [e.name for e in evaders], rates).support(side)


def opponent_rule(settings: SelfPlay, players: PoolPlayers, zoo: Path) -> OpponentRule:
    """The rule ``settings.opponents`` names."""
    if settings.opponents == "nash":
        return NashMixture(settings, players)
    if settings.opponents in ("pfsp", "league"):
        return Prioritised(settings, players.run, zoo)
    return OpponentRule(settings)
