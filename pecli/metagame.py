"""The meta-game of a zoo: its pursuers against its evaders as a zero-sum matrix game, its Nash equilibrium and
each player's exploitability within the zoo.

The payoff of pursuer ``i`` against evader ``j`` is their capture rate ``M[i, j]``: the pursuer maximises it, the
evader minimises it. A mixture ``x`` of pursuers guarantees ``min_j (x M)_j``; a mixture ``y`` of evaders concedes
at most ``max_i (M y)_i``. The Nash equilibrium (the maximin and minimax mixtures, one linear program each) meets at
the value ``v`` of the game. As in PSRO (Lanctot et al. 2017), the same quantities measure players:

* a pursuer's exploitability within the zoo is ``v - min_j M[i, j]``: how far below the value its worst evader of
  the zoo holds it; an evader's is ``max_i M[i, j] - v``;
* the NashConv of a pair of mixtures is ``max_i (M y)_i - min_j (x M)_j``: 0 exactly for an equilibrium.

A meta-solver (PSRO's term; OpenSpiel's PSRO has ``nash`` and ``uniform`` too) picks the mixture of a population
that the other side's next best response trains against: ``nash`` the equilibrium's, ``maxent`` the most spread
mixture that guarantees the value less a slack, ``uniform`` every member alike (fictitious play), ``last`` the
newest member alone (iterated best response, i.e. self-play of whole players).

Why ``maxent``: a zero-sum game has many equilibria and the LP returns a vertex, a mixture of few members. Against
a response trained on the real game, outside the zoo, spreading the weight over every member that is nearly as
good is safer: the response has to escape more searches at once. The maximum-entropy mixture among those that
guarantee ``v - slack`` against every column (Balduzzi et al. 2018, "Re-evaluating evaluation", use the
maximum-entropy Nash equilibrium for the same reason) is found from its dual, a smooth convex problem with
non-negative multipliers ``l``: the mixture is ``softmax(M l)``. A slack of a few hundredths is of the order of
the payoffs' sampling error (200 games: a standard error of 0.035 at a capture rate of 0.5).

Everything here is NumPy and SciPy (HiGHS through :func:`scipy.optimize.linprog`), no torch.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import Literal, get_args

import numpy as np

WEIGHT_FLOOR = 1e-9  # mixture weights below this are LP round-off, not play
MAXENT_SLACK = 0.05  # the capture rate the maximum-entropy mixture may give up against the game's value
MetaSolver = Literal["nash", "maxent", "uniform", "last"]
META_SOLVERS: tuple[str, ...] = get_args(MetaSolver)


@dataclass(frozen=True)
class MetaGame:
    """A zoo's pursuers (rows) against its evaders (columns), ``matrix[i, j]`` the capture rate of pursuer ``i``
    against evader ``j``, with the game's Nash equilibrium."""

    pursuers: tuple[str, ...]
    evaders: tuple[str, ...]
    matrix: np.ndarray  # (pursuers, evaders), capture rates in [0, 1]
    pursuer_mixture: np.ndarray  # (pursuers,): the maximin mixture (or a meta-solver's: with_meta_solvers)
    evader_mixture: np.ndarray  # (evaders,): the minimax mixture (or a meta-solver's)
    value: float  # the capture rate the equilibrium guarantees both ways
    pursuer_solver: MetaSolver = "nash"  # the meta-solver of pursuer_mixture (with_meta_solvers)
    evader_solver: MetaSolver = "nash"
    slack: float | None = None  # what a maxent mixture gives up against the value (None: no maxent mixture)

    @property
    def mixtures_rate(self) -> float:
        """The capture rate of the two mixtures against each other (the value, for the equilibrium's)."""
        return min(1.0, max(0.0, float(self.pursuer_mixture @ self.matrix @ self.evader_mixture)))

    @property
    def pursuer_held_to(self) -> float:
        """The capture rate the pursuer mixture keeps against the zoo's strongest evader against it,
        ``min_j (x M)_j``: the value for an equilibrium mixture, at most the value for any other. The zoo's evaders
        are replies too, so no best response can credit the mixture with more."""
        return min(1.0, max(0.0, float((self.pursuer_mixture @ self.matrix).min())))  # round-off kept in [0, 1]

    @property
    def evader_caught_at_most(self) -> float:
        """The capture rate the zoo's strongest pursuer against the evader mixture reaches, ``max_i (M y)_i``."""
        return min(1.0, max(0.0, float((self.matrix @ self.evader_mixture).max())))

    def exploitability(self) -> dict[str, float]:
        """Each player's exploitability within the zoo (0 for a player that is itself an equilibrium strategy),
        pursuers first; a capture-rate difference in [0, 1]."""
        worst_for_pursuer = self.matrix.min(axis=1)
        worst_for_evader = self.matrix.max(axis=0)
        found = {name: max(0.0, self.value - float(rate)) for name, rate in zip(self.pursuers, worst_for_pursuer)}
        found.update({name: max(0.0, float(rate) - self.value) for name, rate in zip(self.evaders, worst_for_evader)})
        return found

    def support(self, role: str) -> dict[str, float]:
        """The members of ``role``'s equilibrium mixture with their weights, heaviest first."""
        names, weights = (
            (self.pursuers, self.pursuer_mixture) if role == "pursuer" else (self.evaders, self.evader_mixture)
        )
        kept = {name: float(w) for name, w in zip(names, weights) if w > WEIGHT_FLOOR}
        return dict(sorted(kept.items(), key=lambda item: -item[1]))


def mixture_weights(weights: Sequence[float], members: int) -> np.ndarray:
    """``weights`` normalised into the draw probabilities of ``members`` players; :class:`ValueError` unless they
    are ``members`` finite, non-negative numbers with a positive sum."""
    w = np.asarray(weights, dtype=np.float64)
    if w.shape != (members,) or not np.all(np.isfinite(w)) or np.any(w < 0) or w.sum() <= 0:
        raise ValueError(f"weights must be {members} non-negative numbers with a positive sum, got {w.tolist()}")
    return w / w.sum()


def check_matrix(matrix: np.ndarray) -> np.ndarray:
    """``matrix`` as a 2-D float array of finite capture rates in [0, 1]; :class:`ValueError` otherwise."""
    m = np.asarray(matrix, dtype=np.float64)
    if m.ndim != 2 or m.shape[0] < 1 or m.shape[1] < 1:
        raise ValueError(f"a meta-game needs a non-empty pursuers x evaders matrix, got shape {m.shape}")
    if not np.all(np.isfinite(m)) or m.min() < 0.0 or m.max() > 1.0:
        raise ValueError("a meta-game's payoffs are capture rates: finite numbers in [0, 1]")
    return m


def maximin(matrix: np.ndarray) -> tuple[np.ndarray, float]:
    """The row player's (the maximiser's) equilibrium mixture of a zero-sum game and the game's value.

    maximise v subject to ``sum_i x_i M[i, j] >= v`` for every column ``j``, ``sum x = 1``, ``x >= 0``.
    """
    from scipy.optimize import linprog  # imported here: reading a mixture's file needs no SciPy

    m = check_matrix(matrix)
    rows, columns = m.shape
    cost = np.zeros(rows + 1)
    cost[-1] = -1.0  # linprog minimises: -v
    upper = np.hstack([-m.T, np.ones((columns, 1))])  # v - (x M)_j <= 0
    equal = np.hstack([np.ones((1, rows)), np.zeros((1, 1))])
    bounds = [(0.0, None)] * rows + [(None, None)]
    solution = linprog(cost, A_ub=upper, b_ub=np.zeros(columns), A_eq=equal, b_eq=[1.0], bounds=bounds, method="highs")
    if not solution.success:  # a bounded, feasible LP: only a solver fault lands here
        raise RuntimeError(f"the meta-game's linear program failed: {solution.message}")
    x = np.clip(solution.x[:rows], 0.0, None)
    x[x < WEIGHT_FLOOR] = 0.0
    return x / x.sum(), float(solution.x[-1])


def max_entropy(matrix: np.ndarray, floor: float, anchor: np.ndarray) -> np.ndarray:
    """The row mixture of largest entropy with ``(x M)_j >= floor`` for every column ``j``.

    ``anchor`` is a mixture that meets every constraint (the equilibrium's, for a floor below the value). The dual,
    ``min_{l >= 0} logsumexp(M l) - floor * sum(l)``, is solved with L-BFGS-B; the mixture is ``softmax(M l)``. If
    the solver stops short of the floor, the result is moved towards ``anchor`` just far enough to meet it, so
    the floor always holds.
    """
    from scipy.optimize import minimize
    from scipy.special import logsumexp, softmax

    m = check_matrix(matrix)
    anchor = np.asarray(anchor, dtype=np.float64)
    if anchor.shape != (m.shape[0],):
        raise ValueError("the anchor needs one weight per row")
    if (anchor @ m).min() < floor - 1e-6:  # the LP's round-off is far smaller
        raise ValueError(f"the anchor misses the floor {floor:.3f}: pass a mixture that meets it")

    def dual(multipliers: np.ndarray) -> tuple[float, np.ndarray]:
        scores = m @ multipliers
        return float(logsumexp(scores) - floor * multipliers.sum()), m.T @ softmax(scores) - floor

    start = np.zeros(m.shape[1])
    solution = minimize(
        dual,
        start,
        jac=True,
        method="L-BFGS-B",
        bounds=[(0.0, None)] * m.shape[1],
        options={"maxiter": 10_000, "gtol": 1e-10, "ftol": 1e-15},
    )
    x = softmax(m @ solution.x)
    x[x < WEIGHT_FLOOR] = 0.0
    x /= x.sum()
    short = floor - x @ m  # > 0 where the solver's mixture misses the floor
    if short.max() > 0.0:
        margin = anchor @ m - x @ m  # the anchor meets the floor: moving towards it closes the gap
        needed = np.where(short > 0.0, short / np.maximum(margin, 1e-12), 0.0)
        t = min(1.0, float(needed.max()))
        x = (1.0 - t) * x + t * anchor
    return x


def solve(pursuers: Sequence[str], evaders: Sequence[str], matrix: np.ndarray) -> MetaGame:
    """The Nash equilibrium of the zero-sum game of capture rates ``matrix`` (pursuers x evaders)."""
    m = check_matrix(matrix)
    if m.shape != (len(pursuers), len(evaders)):
        raise ValueError(f"{len(pursuers)} pursuers and {len(evaders)} evaders, but a {m.shape} matrix")
    x, value = maximin(m)
    y, minus_value = maximin(1.0 - m.T)  # the evader maximises the escape rate 1 - M
    return MetaGame(tuple(pursuers), tuple(evaders), m, x, y, value=0.5 * (value + 1.0 - minus_value))


def with_meta_solvers(
    game: MetaGame, pursuers: MetaSolver, evaders: MetaSolver, slack: float = MAXENT_SLACK
) -> MetaGame:
    """``game`` whose pursuer and evader mixtures are those of the meta-solvers named (:data:`META_SOLVERS`), each
    population in the order its members joined (``last``: the final row or column); ``maxent`` gives up at most
    ``slack`` of the value. The value and every player's exploitability stay the equilibrium's."""
    if not 0.0 < slack <= 1.0:
        raise ValueError(f"the maximum-entropy mixture's slack is a capture rate in (0, 1], got {slack}")

    def mixture(solver: str, role: str) -> np.ndarray:
        nash = game.pursuer_mixture if role == "pursuer" else game.evader_mixture
        if solver == "nash":
            return nash
        if solver == "maxent":
            if role == "pursuer":
                return max_entropy(game.matrix, game.value - slack, nash)
            return max_entropy(1.0 - game.matrix.T, 1.0 - game.value - slack, nash)  # the evader's escape rates
        if solver == "uniform":
            return np.full(len(nash), 1.0 / len(nash))
        if solver == "last":
            return np.eye(len(nash))[-1]
        raise ValueError(f"no meta-solver '{solver}' (known: {', '.join(META_SOLVERS)})")

    if (pursuers, evaders) == ("nash", "nash"):
        return game
    return replace(
        game,
        pursuer_mixture=mixture(pursuers, "pursuer"),
        evader_mixture=mixture(evaders, "evader"),
        pursuer_solver=pursuers,
        evader_solver=evaders,
        slack=slack if "maxent" in (pursuers, evaders) else None,
    )


def nash_conv(matrix: np.ndarray, pursuer_mixture: np.ndarray, evader_mixture: np.ndarray) -> float:
    """``max_i (M y)_i - min_j (x M)_j``: what the best responses within the matrix gain on the pair of mixtures
    ``(x, y)``; 0 for an equilibrium, at most 1."""
    m = check_matrix(matrix)
    x, y = np.asarray(pursuer_mixture, dtype=np.float64), np.asarray(evader_mixture, dtype=np.float64)
    if x.shape != (m.shape[0],) or y.shape != (m.shape[1],):
        raise ValueError("each mixture needs one weight per player of its side")
    return float((m @ y).max() - (x @ m).min())
