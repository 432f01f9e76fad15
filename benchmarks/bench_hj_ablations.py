"""Hamilton–Jacobi ablations: what made the old players weak, and how the hj evader rates its inputs.

    python benchmarks/bench_hj_ablations.py causes      # the old players' weakness, one suspected cause at a time
    python benchmarks/bench_hj_ablations.py ratings [--full-pursuer P.zip ...]   # how the hj evader rates its inputs

``causes``: under full observation (both sensor ranges 30 m), 500 games per pairing (seed 0),
each row changes one thing of the players found weak before (rel4d, the default grid, the
gradient rule): the grid, the horizon, the model (rel6d keeps each player's speed limit, abs8d the
walls), the rule that turns the value into inputs. "chase" is the rule those players fell back
on (full acceleration along the sign of ∂V/∂r of the default rel4d value, per axis: a lead
pursuit towards the closest approach, or a flight from it). Then, under ``point_mass.yaml``
(3.75 m), the two rules for an unseen opponent, one at a time.

``ratings``: under full observation, 500 games per cell (seed 0), the ``hj`` evader with each way of
rating an input over the pursuer's nine (the worst, the average, blends, the best outcome it leaves)
against the pursuers that do not catch it every time: chase, the interceptor, ``hj:model=rel4d``,
pure pursuit and the learned ``--full-pursuer`` checkpoints.
"""

from __future__ import annotations

import argparse
import os
import sys
from collections.abc import Callable
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("XLA_FLAGS", "--xla_cpu_multi_thread_eigen=false intra_op_parallelism_threads=1")

import numpy as np  # noqa: E402
from hj_players import Chase, GradientRule, make_player, rate, solution_for  # noqa: E402

from pecli.hj import Solution  # noqa: E402
from pecli.policies import resolve_policy  # noqa: E402
from pecli.policies.hj import INPUTS, HJPolicy, choose  # noqa: E402
from pecli.scenario import Scenario, load_scenario  # noqa: E402

EPISODES = 500


class RatesEstimates(HJPolicy):
    """The outcome rule also where the opponent is unseen: the estimate rated as if it were the state."""

    name = "hj-rates-estimates"

    def _act(self, view):
        opp_pos, opp_vel = self._estimate(view)
        own = np.concatenate([view.own_pos, view.own_vel], axis=1).T
        opp = np.concatenate([opp_pos, opp_vel], axis=1).T
        scores, distances = self.outcomes(*((own, opp) if self.role == "pursuer" else (opp, own)))
        if self.role == "pursuer":
            return INPUTS[choose(scores.mean(axis=2), distances.mean(axis=2))]
        return INPUTS[self._evader_choice(scores, distances)]


class KeepsEstimates(HJPolicy):
    """An estimate within the player's own sensing range stays where it is."""

    name = "hj-keeps-estimates"

    def _out_of_sight(self, view, estimate):
        return estimate


def causes(args: argparse.Namespace) -> None:
    base = load_scenario("point_mass")
    full = base.with_sensor_range(30.0)
    default = solution_for(base, "rel4d")
    variants = [  # (label, model, sizes, steps, rule)
        ("before: rel4d 81,21, T = 100, gradient rule", "rel4d", None, None, GradientRule),
        ("finer grid: rel4d 161,41", "rel4d", (161, 41), None, GradientRule),
        ("shorter horizon: rel4d T = 30", "rel4d", None, 30, GradientRule),
        ("longer horizon: rel4d T = 300", "rel4d", None, 300, GradientRule),
        ("speed limits: rel6d 41,11", "rel6d", None, None, GradientRule),
        ("the input rule: rel4d, outcome rule", "rel4d", None, None, HJPolicy),
        ("speed limits and rule: rel6d, outcome rule", "rel6d", None, None, HJPolicy),
        ("walls: abs8d 15,5, outcome rule (now the default)", "abs8d", None, None, HJPolicy),
        ("walls, coarser: abs8d 11,5", "abs8d", (11, 5), None, HJPolicy),
        ("walls, coarsest: abs8d 9,3, T = 40 (the tests' grid)", "abs8d", (9, 3), 40, HJPolicy),
    ]
    columns = ["hj vs hj", "chase vs hj", "pure-pursuit vs hj", "hj vs chase", "hj vs greedy"]
    rows = []
    for label, model, sizes, steps, rule in variants:
        solution = solution_for(base, model, sizes, steps)

        def player(role, solution=solution, rule=rule):
            return rule(full, role, solution)

        pairings = [
            (player("pursuer"), player("evader")),
            (Chase(full, "pursuer", default), player("evader")),
            (resolve_policy("pure-pursuit", "pursuer", full), player("evader")),
            (player("pursuer"), Chase(full, "evader", default)),
            (player("pursuer"), resolve_policy("greedy", "evader", full)),
        ]
        rows.append((label, [rate(full, p, e, args.episodes) for p, e in pairings]))
        print(f"done: {label}", file=sys.stderr)
    print(f"full observation, capture rate (time-to-capture / T), {args.episodes} games per cell, seed 0\n")
    print("| players | " + " | ".join(columns) + " |")
    print("| --- |" + " ---: |" * len(columns))
    for label, cells in rows:
        print(f"| {label} | " + " | ".join(f"{r:.3f} ({t:.2f})" for r, t in cells) + " |")

    # partial observation (point_mass.yaml): the two rules for an unseen opponent, one at a time
    arena = solution_for(base, "abs8d")
    greedy = resolve_policy("greedy", "evader", base)
    pairings = [
        ("hj vs hj", HJPolicy(base, "pursuer", arena), HJPolicy(base, "evader", arena)),
        ("hj vs greedy", HJPolicy(base, "pursuer", arena), greedy),
        (
            "hj vs an hj evader that rates its estimate",
            HJPolicy(base, "pursuer", arena),
            RatesEstimates(base, "evader", arena),
        ),
        ("an hj pursuer that rates its estimate vs greedy", RatesEstimates(base, "pursuer", arena), greedy),
        (
            "an hj pursuer that keeps its estimate in sight vs hj",
            KeepsEstimates(base, "pursuer", arena),
            HJPolicy(base, "evader", arena),
        ),
        ("an hj pursuer that keeps its estimate in sight vs greedy", KeepsEstimates(base, "pursuer", arena), greedy),
    ]
    print(f"\npoint_mass.yaml (sensor ranges 3.75 m), abs8d 15,5, {args.episodes} games per cell, seed 0\n")
    print("| pursuer vs evader | capture (time-to-capture / T) |")
    print("| --- | ---: |")
    for label, pursuer, evader in pairings:
        capture, time_to_capture = rate(base, pursuer, evader, args.episodes)
        print(f"| {label} | {capture:.3f} ({time_to_capture:.2f}) |")


class Rating(HJPolicy):
    """The ``hj`` evader with another rating of its inputs over the pursuer's nine (``scores`` axis 1)."""

    name = "hj-rating"

    def __init__(self, scenario: Scenario, solution: Solution, rate: Callable[[np.ndarray], np.ndarray]) -> None:
        super().__init__(scenario, "evader", solution)
        self.rate = rate

    def _evader_choice(self, scores: np.ndarray, distances: np.ndarray) -> np.ndarray:
        return choose(-self.rate(scores), -distances.mean(axis=1))


def _softmax_mean(scores: np.ndarray, temperature: float) -> np.ndarray:
    weights = np.exp((scores - scores.max(axis=1, keepdims=True)) / temperature)
    return (weights * scores).sum(axis=1) / weights.sum(axis=1)


RATINGS = {
    "worst": lambda s: s.min(axis=1),
    "average (rules 2)": lambda s: s.mean(axis=1),
    "half average, half best": lambda s: 0.5 * s.mean(axis=1) + 0.5 * s.max(axis=1),
    "softmax-weighted, 5 steps": lambda s: _softmax_mean(s, 5.0),
    "best (now)": lambda s: s.max(axis=1),
}


def ratings(args: argparse.Namespace) -> None:
    base = load_scenario("point_mass")
    full = base.with_sensor_range(30.0)
    arena = solution_for(full, "abs8d")
    pursuers = [
        ("chase", "chase"),
        ("interceptor", "interceptor"),
        ("hj rel4d", "hj:model=rel4d"),
        ("pure-pursuit", "pure-pursuit"),
    ]
    pursuers += [(f"learned full ({Path(p).parent.parent.name})", p) for p in args.full_pursuer]
    print(f"full observation: capture rate of the hj evader, {args.episodes} games per cell, seed 0\n")
    print("| evader's rating | " + " | ".join(label for label, _ in pursuers) + " |")
    print("| --- |" + " ---: |" * len(pursuers))
    for name, rule in RATINGS.items():
        cells = [
            rate(full, make_player(spec, "pursuer", full, base, 0), Rating(full, arena, rule), args.episodes)[0]
            for _, spec in pursuers
        ]
        print(f"| {name} | " + " | ".join(f"{c:.3f}" for c in cells) + " |", flush=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="step", required=True)
    c = sub.add_parser("causes", help="the old players' weakness, one suspected cause at a time")
    c.add_argument("--episodes", type=int, default=EPISODES)
    r = sub.add_parser("ratings", help="the hj evader's rating of its inputs, one way at a time")
    r.add_argument("--full-pursuer", nargs="*", default=[], help="learned pursuers trained under full observation")
    r.add_argument("--episodes", type=int, default=EPISODES)
    args = parser.parse_args()
    {"causes": causes, "ratings": ratings}[args.step](args)


if __name__ == "__main__":
    main()
