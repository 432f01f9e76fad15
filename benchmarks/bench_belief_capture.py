"""Beliefs in play: what a belief adds to capture, in the curve runs and in self-play.

    python benchmarks/bench_belief_capture.py capture   # (c) the curve runs' checkpoints vs greedy and rash
    python benchmarks/bench_belief_capture.py selfplay  # (d) self-play runs with and without a belief, cross-played

(c) reads the curve runs of ``bench_train_curves.py curves --belief KIND`` and, for each, takes the
newest checkpoint the run had written within ``--minutes`` of CPU time (the run's evaluation log
maps CPU time to steps), then plays it against the greedy and rash evaders (500 episodes, seed 0).
With ``--shuffled`` it plays each belief checkpoint once more with its belief features permuted
across the batch's games at every step: same distribution, but no longer about the actor's own
game. The capture lost is what the actor takes from its belief. With ``--keep K`` it selects the
paper's way instead (§V-B): every checkpoint within the budget is ranked by its capture rate
against greedy on ``--rank-episodes`` (200) episodes (seed 1, not the test episodes), and the best K are tested
and pooled per seed.

(d) reads the self-play runs of ``pecli selfplay --belief KIND`` (named
``<config>-<opponents>-<kind>-s<seed>``, no ``<kind>`` for ``none``) and plays the round-``--round``
pursuer of each run against the same round's evader of every run and against the greedy and
random-walk evaders (500 episodes, seed 0): medians over seeds, and each kind's pooled captures
against those of ``none`` with a two-proportion z-test. Results are cached in the zoo's
``belief-cross`` (a ``pecli tournament``'s pairing cache).

What a belief costs in training, and how well it locates an unseen opponent: ``bench_belief.py``.
"""

from __future__ import annotations

import argparse
import itertools
import os
import statistics
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np  # noqa: E402
import torch as th  # noqa: E402

from pecli.match import play_match  # noqa: E402
from pecli.policies import resolve_policy  # noqa: E402
from pecli.rl.evaluations import evaluation_log, read_evaluations  # noqa: E402
from pecli.scenario import Scenario, load_scenario  # noqa: E402
from pecli.stats import two_proportion_z_test  # noqa: E402
from pecli.tournament import PairingResult, pairing_results, player_spec  # noqa: E402
from pecli.zoo import read_metadata  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
TEST_EPISODES = 500


def _report() -> Callable[[PairingResult, bool], None]:
    """Prints each pairing played (not those read from the cache), numbered."""
    played = itertools.count(1)

    def report(result: PairingResult, cached: bool) -> None:
        if not cached:
            print(f"  {next(played)}: {result.pursuer} vs {result.evader}", file=sys.stderr, flush=True)

    return report


def _checkpoints_within(run: Path, minutes: float) -> list[tuple[Path, float]]:
    """Every checkpoint of ``run`` written within ``minutes`` of CPU time with that CPU time, oldest first.

    The run's evaluation log maps steps to CPU time; a checkpoint's CPU time is interpolated between
    its rows. Checkpoints with the same step count hold the same policy: one of them is listed.
    """
    rows = read_evaluations(evaluation_log(run, "pursuer"))
    steps = [0] + [r.steps for r in rows]
    used = [0.0] + [r.cpu_seconds / 60 for r in rows]
    within = max((s for s, m in zip(steps, used) if m <= minutes), default=0)
    found: dict[int, Path] = {}
    for path in sorted((run / "pursuer").glob("*.zip")):  # ep*.zip sort before best/final/last
        taken = read_metadata(path).steps
        if 0 < taken <= within:
            found.setdefault(taken, path)
    return [(found[taken], float(np.interp(taken, steps, used))) for taken in sorted(found)]


def _best_ranked(
    run: Path,
    found: list[tuple[Path, float]],
    scenario: Scenario,
    keep: int,
    episodes: int,
    workers: int,
) -> list[tuple[Path, float]]:
    """The ``keep`` checkpoints of ``found`` that capture most against greedy on ranking episodes (seed 1).

    The paper's selection (§V-B), against the run's own opponent. The ranking episodes are not
    the test episodes (seed 0) nor training's evaluations (seed 10 000 + run seed). The pairings are
    cached in ``run/ranking``, so a second call only plays new checkpoints.
    """
    print(f"ranking {len(found)} checkpoints of {run.name}", file=sys.stderr, flush=True)
    rates = pairing_results(
        scenario, [str(path) for path, _ in found], ["greedy"], episodes, [1], run / "ranking", workers, _report()
    )
    ranked = sorted(
        found, key=lambda c: (-rates[(player_spec(c[0]), "greedy")].capture_rate, -c[1])
    )  # ties: the later checkpoint
    return sorted(ranked[:keep], key=lambda c: c[1])


def _shuffle_belief(policy: Any, seed: int = 0) -> None:
    """Make a learned player's belief features those of another game of the batch, at every step."""
    belief = policy.actor.features_extractor.belief
    own, generator = belief.features, th.Generator().manual_seed(seed)

    def shuffled(history: th.Tensor, draws: tuple[th.Tensor, th.Tensor] | None = None) -> th.Tensor:
        features = own(history, draws)
        return features[th.randperm(features.shape[0], generator=generator)]

    belief.features = shuffled


def _captures(checkpoint: Path, scenario: Scenario, shuffled_too: bool) -> list[int]:
    """Captures in 500 test episodes (seed 0) vs greedy and rash, then the same with shuffled beliefs."""

    counts = []
    for shuffled in (False, True) if shuffled_too else (False,):
        for evader in ("greedy", "rash"):
            pursuer = resolve_policy(str(checkpoint), "pursuer", scenario)
            if shuffled:
                _shuffle_belief(pursuer)
            result, _ = play_match(
                scenario, pursuer, resolve_policy(evader, "evader", scenario), episodes=TEST_EPISODES, seed=0
            )
            counts.append(int(result.captured.sum()))
    return counts


def capture(args: argparse.Namespace) -> None:

    scenario = load_scenario(args.config)
    curves = ROOT / "runs" / "bench_train"
    chosen_by = (
        f"the best {args.keep} by capture vs greedy ({args.rank_episodes} ranking episodes, seed 1), pooled"
        if args.keep
        else "the newest"
    )
    print(
        f"checkpoints within {args.minutes:g} CPU-minutes of training: {chosen_by}; "
        f"{TEST_EPISODES} test episodes each, seed 0"
    )
    columns = " vs greedy, shuffled | vs rash, shuffled |" if args.shuffled else ""
    print("| belief | seed | checkpoint (~CPU min) | vs greedy | vs rash |" + columns)
    print("| --- | ---: | --- | ---: | ---: |" + " ---: | ---: |" * bool(args.shuffled))
    summary: dict[str, list[tuple[np.ndarray, int]]] = {}
    for kind in args.kinds:
        for seed in args.seeds:
            run = curves / f"{args.config}-{kind}-s{seed}"
            found = _checkpoints_within(run, args.minutes) if evaluation_log(run, "pursuer").is_file() else []
            if not found:
                continue
            chosen = (
                _best_ranked(run, found, scenario, args.keep, args.rank_episodes, args.workers)
                if args.keep
                else found[-1:]
            )
            shuffled_too = args.shuffled and kind != "none"
            counts = np.sum([_captures(path, scenario, shuffled_too) for path, _ in chosen], axis=0)
            episodes = TEST_EPISODES * len(chosen)
            summary.setdefault(kind, []).append((counts, episodes))
            names = ", ".join(f"{path.stem} ({minutes:.1f})" for path, minutes in chosen)
            print(f"| {kind} | {seed} | {names} | " + " | ".join(f"{c / episodes:.3f}" for c in counts) + " |")
    pooled = {kind: (sum(c[0] for c, _ in values), sum(n for _, n in values)) for kind, values in summary.items()}
    for kind, values in summary.items():
        medians = [statistics.median(c[i] / n for c, n in values) for i in range(len(values[0][0]))]
        line = f"median {kind}: greedy {medians[0]:.3f}, rash {medians[1]:.3f}"
        if len(medians) == 4:
            line += f"; shuffled belief: greedy {medians[2]:.3f}, rash {medians[3]:.3f}"
        captured, episodes = pooled[kind]
        line += f" ({len(values)} seeds); pooled vs greedy {captured / episodes:.3f} of {episodes}"
        if kind != "none" and "none" in pooled:
            line += f", p = {two_proportion_z_test(captured, episodes, *pooled['none']):.2g} against none"
        print(line)


def selfplay(args: argparse.Namespace) -> None:

    scenario = load_scenario(args.config)
    checkpoint = f"round-{args.round:03d}.zip"
    runs: dict[str, dict[int, Path]] = {}
    for kind in args.kinds:
        infix = "" if kind == "none" else f"{kind}-"
        for seed in args.seeds:
            run = args.zoo / f"{args.config}-{args.opponents}-{infix}s{seed}"
            if all((run / role / checkpoint).is_file() for role in ("pursuer", "evader")):
                runs.setdefault(kind, {})[seed] = run
    if not runs:
        raise SystemExit(f"no self-play run in {args.zoo} has reached round {args.round}")
    evaders = {
        f"{kind}-sp": [str(run / "evader" / checkpoint) for run in found.values()] for kind, found in runs.items()
    }
    evaders |= {name: [name] for name in ("greedy", "random-walk")}
    print(
        f"round {args.round} pursuers of self-play ({args.opponents}) against the round-{args.round} evaders of "
        f"every run and two heuristics; {TEST_EPISODES} episodes per pairing, seed 0"
    )
    print("| pursuer | seed | " + " | ".join(f"vs {name}" for name in evaders) + " |")
    print("| --- | ---: |" + " ---: |" * len(evaders))
    pursuers = [str(run / "pursuer" / checkpoint) for found in runs.values() for run in found.values()]
    results = pairing_results(
        scenario,
        pursuers,
        sum(evaders.values(), []),
        TEST_EPISODES,
        [0],
        args.zoo / "belief-cross",
        args.workers,
        _report(),
    )
    captures: dict[str, list[list[tuple[int, int]]]] = {}  # kind → per seed, per evader group: (captures, episodes)
    for kind, found in runs.items():
        for seed, run in found.items():
            pursuer = player_spec(run / "pursuer" / checkpoint)
            row = [
                (
                    sum(results[(pursuer, player_spec(e))].captures for e in group),
                    sum(results[(pursuer, player_spec(e))].episodes for e in group),
                )
                for group in evaders.values()
            ]
            captures.setdefault(kind, []).append(row)
            print(f"| {kind}-sp | {seed} | " + " | ".join(f"{c / n:.3f}" for c, n in row) + " |")
    for kind, rows in captures.items():
        medians = [statistics.median(c / n for c, n in column) for column in zip(*rows)]
        print(
            f"median {kind}-sp ({len(rows)} seeds): "
            + ", ".join(f"vs {name} {m:.3f}" for name, m in zip(evaders, medians))
        )
    for kind in (k for k in captures if k != "none" and "none" in captures):
        for name, ours, theirs in zip(evaders, zip(*captures[kind]), zip(*captures["none"])):
            ours, theirs = (tuple(map(sum, zip(*column))) for column in (ours, theirs))  # pooled over seeds
            print(
                f"pooled vs {name}: {kind}-sp {_ratio(*ours)}, none-sp {_ratio(*theirs)}, "
                f"p = {two_proportion_z_test(*ours, *theirs):.2g}"
            )


def _ratio(successes: int, trials: int) -> str:
    return f"{successes / trials:.3f} of {trials}"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="step", required=True)
    c = sub.add_parser("capture")
    c.add_argument("--config", default="paper")
    c.add_argument("--kinds", nargs="+", default=["none", "bimdn", "bimdn-mixed"])
    c.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    c.add_argument("--minutes", type=float, default=10.0)
    c.add_argument(
        "--shuffled",
        action="store_true",
        help="also play each belief checkpoint with its features permuted across games",
    )
    c.add_argument(
        "--keep",
        type=int,
        default=0,
        help="the paper's selection: rank every checkpoint within the budget, test the best KEEP",
    )
    c.add_argument("--rank-episodes", type=int, default=200, help="episodes per checkpoint in the ranking")
    c.add_argument("--workers", type=int, default=1, help="processes for the ranking")
    d = sub.add_parser("selfplay")
    d.add_argument("--config", default="paper")
    d.add_argument("--zoo", type=Path, default=ROOT / "runs" / "bench_selfplay")
    d.add_argument("--opponents", default="pfsp")
    d.add_argument("--kinds", nargs="+", default=["none", "bimdn"])
    d.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    d.add_argument("--round", type=int, default=8, help="the generation of every run to play")
    d.add_argument("--workers", type=int, default=1)
    args = parser.parse_args()
    th.set_num_threads(1)
    {"capture": capture, "selfplay": selfplay}[args.step](args)


if __name__ == "__main__":
    main()
