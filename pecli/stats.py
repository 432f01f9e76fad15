"""Statistics for comparing policies: the paper's two-proportion z-test, its stratified form (Mantel–Haenszel),
intervals of capture rates and of their differences, Bradley–Terry ratings, and the interquartile mean over runs
with its stratified-bootstrap interval."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.optimize import minimize
from scipy.special import expit, log_expit
from scipy.stats import binomtest, trim_mean


def two_proportion_z_test(successes_a: int, n_a: int, successes_b: int, n_b: int) -> float:
    """Two-sided p-value that two capture rates are equal (pooled two-proportion z-test).

    With a pooled rate of 0 or 1 the two samples cannot differ: the p-value is 1.
    """
    if n_a < 1 or n_b < 1:
        raise ValueError("both samples need at least one episode")
    pooled = (successes_a + successes_b) / (n_a + n_b)
    variance = pooled * (1.0 - pooled) * (1.0 / n_a + 1.0 / n_b)
    if variance <= 0.0:
        return 1.0
    z = (successes_a / n_a - successes_b / n_b) / math.sqrt(variance)
    return math.erfc(abs(z) / math.sqrt(2.0))


def mantel_haenszel_test(strata: Sequence[tuple[int, int, int, int]]) -> tuple[float, float]:
    """Whether side a captures more than side b within strata (Cochran–Mantel–Haenszel, no continuity correction).

    Each stratum is ``(successes_a, n_a, successes_b, n_b)`` against one opponent, so sides that met their
    opponents in different proportions compare like with like. Returns a's successes above what equal rates within
    each stratum would give, and the two-sided p-value; strata of one side only or of one outcome add nothing (a
    p-value of 1 when none is left). With one stratum it is the pooled z-test scaled by (n - 1) / n in chi-square.
    """
    excess = variance = 0.0
    for successes_a, n_a, successes_b, n_b in strata:
        if not (0 <= successes_a <= n_a and 0 <= successes_b <= n_b):
            raise ValueError(
                f"a stratum needs 0 <= successes <= episodes on both sides, not {successes_a}/{n_a} "
                f"and {successes_b}/{n_b}"
            )
        n, successes = n_a + n_b, successes_a + successes_b
        if n_a < 1 or n_b < 1 or successes in (0, n):
            continue
        excess += successes_a - n_a * successes / n
        variance += n_a * n_b * successes * (n - successes) / (n * n * (n - 1))
    if variance <= 0.0:
        return excess, 1.0
    return excess, math.erfc(abs(excess) / math.sqrt(variance) / math.sqrt(2.0))


def ties_with_best(
    successes: Sequence[int], trials: Sequence[int], higher_is_better: bool = True, alpha: float = 0.05
) -> list[bool]:
    """For one row of the paper's table: which entries are the best or statistically tie with it (p > alpha)."""
    rates = [s / n for s, n in zip(successes, trials)]
    best = int(np.argmax(rates) if higher_is_better else np.argmin(rates))
    return [
        i == best or two_proportion_z_test(successes[i], trials[i], successes[best], trials[best]) > alpha
        for i in range(len(rates))
    ]


ELO_SCALE = 400.0 / math.log(10.0)  # one logit = 173.7 Elo points
ELO_BASE = 1500.0


@dataclass(frozen=True)
class Rating:
    """A player's Bradley–Terry strength on the Elo scale, with its standard error."""

    name: str
    elo: float
    stderr: float
    games: int


def bradley_terry(
    names: Sequence[str],
    results: Sequence[tuple[int, int, int, int]],
    prior_sd: float = 5.0,
) -> list[Rating]:
    """Fit Bradley–Terry strengths from pairings ``(winner_side_index, loser_side_index, wins, games)``.

    Each result ``(i, j, w, n)`` says player ``i`` beat player ``j`` in ``w`` of ``n`` games
    (for a pursuer ``i`` against an evader ``j``: ``w`` captures). The model is
    ``P(i beats j) = sigmoid(theta_i - theta_j)``; a weak Gaussian prior (sd ``prior_sd`` logits)
    keeps strengths finite when a player wins or loses everything. Strengths are centred on their
    mean and reported as ``1500 + 173.7 * theta`` (Elo points) with standard errors from the inverse
    Hessian of the penalised likelihood.
    """
    k = len(names)
    if k == 0:
        return []
    i_idx = np.array([r[0] for r in results], dtype=np.int64)
    j_idx = np.array([r[1] for r in results], dtype=np.int64)
    wins = np.array([r[2] for r in results], dtype=np.float64)
    games = np.array([r[3] for r in results], dtype=np.float64)
    losses = games - wins

    def objective(theta: np.ndarray) -> tuple[float, np.ndarray]:
        diff = theta[i_idx] - theta[j_idx]
        nll = -(wins * log_expit(diff) + losses * log_expit(-diff)).sum() + 0.5 * (theta @ theta) / prior_sd**2
        residual = games * expit(diff) - wins  # d nll / d diff
        grad = np.zeros(k)
        np.add.at(grad, i_idx, residual)
        np.add.at(grad, j_idx, -residual)
        return float(nll), grad + theta / prior_sd**2

    solution = minimize(objective, np.zeros(k), jac=True, method="L-BFGS-B")
    theta = solution.x
    diff = theta[i_idx] - theta[j_idx]
    weight = games * expit(diff) * expit(-diff)
    hessian = np.eye(k) / prior_sd**2
    np.add.at(hessian, (i_idx, i_idx), weight)
    np.add.at(hessian, (j_idx, j_idx), weight)
    np.add.at(hessian, (i_idx, j_idx), -weight)
    np.add.at(hessian, (j_idx, i_idx), -weight)
    covariance = np.linalg.inv(hessian)
    # centre on the mean: theta - mean(theta) = C theta, its covariance C Sigma C^T
    centre = np.eye(k) - 1.0 / k
    centred = centre @ theta
    stderr = np.sqrt(np.clip(np.diag(centre @ covariance @ centre.T), 0.0, None))
    played = np.zeros(k)
    np.add.at(played, i_idx, games)
    np.add.at(played, j_idx, games)
    return [
        Rating(name=names[p], elo=ELO_BASE + ELO_SCALE * centred[p], stderr=ELO_SCALE * stderr[p], games=int(played[p]))
        for p in range(k)
    ]


def wilson_interval(successes: int, n: int, confidence: float = 0.95) -> tuple[float, float]:
    """The Wilson score interval of a capture rate ``successes / n`` (SciPy's ``binomtest``)."""
    if n < 1 or not 0 <= successes <= n:
        raise ValueError(f"an interval needs 0 <= successes <= n and n >= 1, not {successes}/{n}")
    interval = binomtest(successes, n).proportion_ci(confidence_level=confidence, method="wilson")
    return float(interval.low), float(interval.high)


def difference_interval(
    successes_a: int, n_a: int, successes_b: int, n_b: int, confidence: float = 0.95
) -> tuple[float, float]:
    """An interval for the difference of two independent capture rates ``a - b`` (Newcombe's hybrid score
    interval, built from each rate's Wilson interval; it stays within [-1, 1] and behaves near 0 and 1)."""
    p_a, p_b = successes_a / n_a, successes_b / n_b
    low_a, high_a = wilson_interval(successes_a, n_a, confidence)
    low_b, high_b = wilson_interval(successes_b, n_b, confidence)
    d = p_a - p_b
    return (
        d - math.sqrt((p_a - low_a) ** 2 + (high_b - p_b) ** 2),
        d + math.sqrt((high_a - p_a) ** 2 + (p_b - low_b) ** 2),
    )


def interquartile_mean(scores: np.ndarray) -> float:
    """The mean of the middle half of all ``scores`` (25 % cut from each end), as rliable's aggregate IQM."""
    return float(trim_mean(np.asarray(scores, dtype=float), 0.25, axis=None))


def stratified_bootstrap_interval(
    scores: np.ndarray, reps: int = 2000, confidence: float = 0.95, seed: int = 0
) -> tuple[float, float]:
    """A percentile bootstrap interval of :func:`interquartile_mean` over ``scores`` ``(runs, tasks)``: each
    resample draws the runs with replacement within every task (column), as rliable's stratified bootstrap.

    (rliable itself needs ``arch``, which does not import beside pandas 3; this is its method in NumPy.)"""
    scores = np.asarray(scores, dtype=float)
    if scores.ndim != 2 or min(scores.shape) < 1:
        raise ValueError(f"scores must be (runs, tasks) with at least one of each, not {scores.shape}")
    runs, tasks = scores.shape
    picks = np.random.default_rng(seed).integers(0, runs, size=(reps, runs, tasks))
    resampled = scores[picks, np.arange(tasks)]  # (reps, runs, tasks): run picks[r, i, j] of task j
    means = trim_mean(resampled.reshape(reps, -1), 0.25, axis=1)
    tail = 100 * (1 - confidence) / 2
    low, high = np.percentile(means, [tail, 100 - tail])
    return float(low), float(high)
