"""The z-test, its stratified form, ties with the best, and Bradley–Terry ratings against hand-computed values."""

from __future__ import annotations

import math

import numpy as np
import pytest

from pecli.stats import (
    ELO_SCALE,
    bradley_terry,
    interquartile_mean,
    mantel_haenszel_test,
    stratified_bootstrap_interval,
    ties_with_best,
    two_proportion_z_test,
)


def test_z_test_by_hand() -> None:
    # 0.98 vs 0.94 with 1500 episodes each: pooled 0.96, se = sqrt(.96 * .04 * 2/1500) = 0.0071554
    z = (0.98 - 0.94) / math.sqrt(0.96 * 0.04 * (2 / 1500))
    assert z == pytest.approx(5.5902, abs=1e-3)
    assert two_proportion_z_test(1470, 1500, 1410, 1500) == pytest.approx(math.erfc(z / math.sqrt(2)), rel=1e-9)
    assert two_proportion_z_test(1470, 1500, 1410, 1500) < 1e-7


def test_z_test_edges() -> None:
    assert two_proportion_z_test(10, 10, 10, 10) == 1.0  # both perfect: cannot differ
    assert two_proportion_z_test(0, 10, 0, 20) == 1.0
    assert two_proportion_z_test(50, 100, 50, 100) == pytest.approx(1.0)
    assert two_proportion_z_test(48, 100, 52, 100) == pytest.approx(0.5716, abs=1e-3)  # z = 0.566
    with pytest.raises(ValueError):
        two_proportion_z_test(0, 0, 1, 1)


def test_mantel_haenszel_with_one_stratum_is_the_z_test() -> None:
    # chi-square of Mantel-Haenszel = (n - 1) / n of Pearson's, whose root is the pooled z: 1470/1500 vs 1410/1500
    z = (0.98 - 0.94) / math.sqrt(0.96 * 0.04 * (2 / 1500))
    excess, p = mantel_haenszel_test([(1470, 1500, 1410, 1500)])
    assert excess == pytest.approx(1470 - 1500 * 2880 / 3000)  # 30 captures above equal rates
    assert p == pytest.approx(math.erfc(z * math.sqrt(2999 / 3000) / math.sqrt(2)), rel=1e-9)


def test_mantel_haenszel_compares_within_strata() -> None:
    # Simpson: a met the hard opponent twice as often, so pooled it looks worse; within each opponent both are equal
    strata = [(95, 100, 190, 200), (80, 200, 40, 100)]
    assert two_proportion_z_test(175, 300, 230, 300) < 1e-5
    excess, p = mantel_haenszel_test(strata)
    assert excess == pytest.approx(0.0, abs=1e-9) and p == pytest.approx(1.0)
    better = [(99, 100, 180, 200), (100, 200, 40, 100)]  # a ahead against both: 0.99 vs 0.90, 0.50 vs 0.40
    excess, p = mantel_haenszel_test(better)
    assert excess > 0 and p < 0.01
    excess, p = mantel_haenszel_test([(10, 10, 20, 20), (5, 5, 0, 0)])  # one outcome only, one side only
    assert (excess, p) == (0.0, 1.0)
    with pytest.raises(ValueError, match="0 <= successes <= episodes"):
        mantel_haenszel_test([(11, 10, 5, 10)])


def test_ties_with_best() -> None:
    # 0.990 vs 0.985 with 1500 each: z = 1.26, p = 0.21, a tie; 0.99 vs 0.98: z = 2.25, p = 0.024, not
    assert ties_with_best([1485, 1478, 1410], [1500, 1500, 1500]) == [True, True, False]
    assert ties_with_best([1485, 1470], [1500, 1500]) == [True, False]
    assert ties_with_best([10, 90], [100, 100], higher_is_better=False) == [True, False]


def test_bradley_terry_recovers_a_known_gap() -> None:
    # player 0 beats player 1 in 75 % of 4000 games: theta0 - theta1 = logit(0.75) = ln 3
    ratings = bradley_terry(["a", "b"], [(0, 1, 3000, 4000)], prior_sd=100.0)
    gap = (ratings[0].elo - ratings[1].elo) / ELO_SCALE
    assert gap == pytest.approx(math.log(3), rel=1e-3)
    assert ratings[0].elo + ratings[1].elo == pytest.approx(3000.0)  # centred on 1500
    assert 0 < ratings[0].stderr < 0.1 * ELO_SCALE and ratings[0].games == 4000


def test_bradley_terry_orders_transitively_and_stays_finite() -> None:
    names = ["strong pursuer", "weak pursuer", "evader"]
    results = [(0, 2, 90, 100), (1, 2, 30, 100)]
    ratings = {r.name: r for r in bradley_terry(names, results)}
    assert ratings["strong pursuer"].elo > ratings["evader"].elo > ratings["weak pursuer"].elo
    perfect = bradley_terry(["p", "e"], [(0, 1, 100, 100)])
    assert all(math.isfinite(r.elo) and math.isfinite(r.stderr) for r in perfect)


def test_interquartile_mean_drops_the_outer_quarters() -> None:
    assert interquartile_mean(np.array([[0.0, 1.0, 2.0, 3.0], [4.0, 5.0, 6.0, 100.0]])) == 3.5  # mean of 2..5
    assert interquartile_mean(np.full((3, 2), 0.7)) == pytest.approx(0.7)


def test_the_stratified_bootstrap_resamples_runs_within_each_task() -> None:
    same_runs = np.array([[0.2, 0.9], [0.2, 0.9], [0.2, 0.9]])  # runs agree on each task: nothing to resample
    assert stratified_bootstrap_interval(same_runs) == pytest.approx((0.55, 0.55))
    rng = np.random.default_rng(1)
    spread = rng.uniform(0.4, 0.6, size=(3, 6))
    low, high = stratified_bootstrap_interval(spread, reps=500)
    assert 0.4 <= low < interquartile_mean(spread) < high <= 0.6
    wider = stratified_bootstrap_interval(0.5 + 4 * (spread - 0.5), reps=500)  # 4x the runs' spread
    assert wider[1] - wider[0] > 3 * (high - low)
    with pytest.raises(ValueError, match=r"scores must be \(runs, tasks\)"):
        stratified_bootstrap_interval(np.zeros(3))
