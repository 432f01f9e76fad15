"""Beliefs: what they cost in training and how well they locate an unseen opponent.

    python benchmarks/bench_belief.py speed      # (a) training transitions/s per belief kind, as a ratio to none
    python benchmarks/bench_belief.py quality    # (b) unseen-position error on held-out games
    python benchmarks/bench_belief.py capture    # (c) capture vs greedy and rash of the curve runs' checkpoints
    python benchmarks/bench_belief.py selfplay   # (d) self-play runs with and without a belief, against each other

(a) trains the pursuer on the paper scenario with each ``--belief`` for the same number of
transitions, with learning and belief fitting both active (warm-ups shortened), in one process
on one torch thread, median of ``--repeats``.

(b) collects history windows of a pure-pursuit pursuer against the random-walk, greedy and rash
evaders (``--games`` per evader), fits the BiMDN and the image belief on them by NLL (paper
settings: batch 256, Adam 0.002), keeping the state with the best NLL on validation games, then
measures, on held-out games with other seeds, the mean distance (m) between each belief's mean
and the evader's true position at the moments the pursuer does not see it: BiMDN, UKF, image,
"last seen" (the last sighting in the window; the arena's centre if none) and the centre itself,
over all unseen moments and split by whether the window holds a sighting.

(c) reads the curve runs of ``bench_train.py curves --belief KIND`` and, for each, takes the
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
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from pathlib import Path
from typing import Any

os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np  # noqa: E402
import torch as th  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
KINDS = ("none", "bimdn", "bimdn-mixed", "ukf", "image")
TEST_EPISODES = 500


def speed(args: argparse.Namespace) -> None:
    from pecli.policies import resolve_policy
    from pecli.rl.train import TrainJob, make_learner, with_overrides
    from pecli.scenario import load_scenario

    base = load_scenario(args.config)
    rates: dict[str, list[float]] = {kind: [] for kind in args.kinds}
    for _ in range(args.repeats):
        for kind in args.kinds:
            scenario = with_overrides(base, {"belief": kind, "learning_starts": 1000, "belief_settings.warmup": 1000})
            job = TrainJob(role="pursuer", scenario=scenario, opponent="greedy", zoo=Path("unused"), name="bench")
            _, model, fit = make_learner(job, resolve_policy("greedy", "evader", scenario), seed=0)
            callbacks = [] if fit is None else [fit]
            model.learn(1000, callback=callbacks)  # warm-ups over: learning and fitting both run below
            start = time.perf_counter()
            model.learn(args.steps, callback=callbacks, reset_num_timesteps=False)
            rates[kind].append(args.steps / (time.perf_counter() - start))
    reference = statistics.median(rates["none"]) if "none" in rates else None
    print(
        f"{base.name}: {args.steps} transitions after warm-up, 8 envs, batch 512, 1 torch thread, "
        f"median of {args.repeats}"
    )
    print("| belief | transitions/s | vs none |")
    print("| --- | ---: | ---: |")
    for kind, values in rates.items():
        rate = statistics.median(values)
        print(f"| {kind} | {rate:,.0f} | {rate / reference:.2f} |" if reference else f"| {kind} | {rate:,.0f} | - |")


def _windows(scenario, evaders: list[str], games: int, seed: int):
    """Windows of a pure-pursuit pursuer vs each evader: (history, true position, unseen) at every 10th step."""
    from pecli.game import Game
    from pecli.game.memory import HistoryWindow
    from pecli.policies import resolve_policy

    histories, targets, unseen = [], [], []
    for k, name in enumerate(evaders):
        game = Game(scenario, n=games, seed=seed + k)
        obs = game.reset(seed=seed + k)
        pursuer = resolve_policy("pure-pursuit", "pursuer", scenario, seed=seed + k)
        evader = resolve_policy(name, "evader", scenario, seed=seed + 100 + k)
        pursuer.reset(games)
        evader.reset(games)
        t = scenario.training
        window = HistoryWindow(games, game.obs_dim["pursuer"], t.history_length, t.history_stride)
        window.reset(obs["pursuer"])
        seen_index = game.codecs["pursuer"].seen_index
        for step in range(1, scenario.horizon + 1):
            obs = game.step(pursuer.act(obs["pursuer"]), evader.act(obs["evader"])).obs
            window.push(obs["pursuer"])
            if step % 10 == 0:
                live = ~game.finished
                histories.append(window.get()[live])
                targets.append(game.normalised_state()[live, 5:7])
                unseen.append(obs["pursuer"][live, seen_index] < 0)
    return np.concatenate(histories), np.concatenate(targets), np.concatenate(unseen)


def _last_seen(decoder, history: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The last sighting in each window (the arena's centre if none), and whether there was one."""
    window = decoder(history)
    out = np.zeros((history.shape[0], 2))
    for t in range(window.seen.shape[1]):  # later sightings overwrite earlier ones
        seen = window.seen[:, t] & window.valid[:, t]
        out[seen] = window.opp_pos[seen, t]
    return out, (window.seen & window.valid).any(axis=1)


def _mean(model, history: np.ndarray) -> np.ndarray:
    with th.no_grad():
        return np.concatenate(
            [model.mixture(th.as_tensor(history[i : i + 2048])).mean().numpy() for i in range(0, len(history), 2048)]
        )


def _nll(model, history: np.ndarray, target: np.ndarray) -> float:
    with th.no_grad():
        total = sum(
            -model.mixture(th.as_tensor(history[i : i + 2048]))
            .log_prob(th.as_tensor(target[i : i + 2048]))
            .sum()
            .item()
            for i in range(0, len(history), 2048)
        )
    return total / len(history)


def _fit(model, data, validation, settings, updates: int, check_every: int) -> tuple[int, float]:
    """Fits ``model`` by NLL (the paper's batch and learning rate); keeps the state with the best
    validation NLL, checked every ``check_every`` updates. Returns that update and the seconds spent."""
    import copy

    optimiser = th.optim.Adam(model.parameters(), lr=settings.learning_rate)
    rng = np.random.default_rng(0)
    best = (_nll(model, *validation), 0, copy.deepcopy(model.state_dict()))
    start = time.perf_counter()
    for update in range(1, updates + 1):
        index = rng.integers(0, len(data[0]), settings.batch_size)
        loss = model.mixture(th.as_tensor(data[0][index])).nll(th.as_tensor(data[1][index]))
        optimiser.zero_grad()
        loss.backward()
        th.nn.utils.clip_grad_norm_(model.parameters(), settings.max_grad_norm)
        optimiser.step()
        if update % check_every == 0:
            score = _nll(model, *validation)
            if score < best[0]:
                best = (score, update, copy.deepcopy(model.state_dict()))
    model.load_state_dict(best[2])
    return best[1], time.perf_counter() - start


def quality(args: argparse.Namespace) -> None:
    from pecli.belief.model import LEARNED_KINDS, BeliefModel
    from pecli.scenario import load_scenario

    th.manual_seed(0)
    scenario = load_scenario(args.config)
    evaders = ["random-walk", "greedy", "rash"]
    learned = [kind for kind in args.kinds if kind in LEARNED_KINDS]
    if learned:
        train_x, train_y, _ = _windows(scenario, evaders, args.games, seed=0)
        valid_x, valid_y, _ = _windows(scenario, evaders, max(args.games // 10, 10), seed=500)
    test_x, test_y, test_unseen = _windows(scenario, evaders, args.test_games, seed=1000)
    half = np.array(scenario.arena.half)
    settings = scenario.training.belief_settings
    t = scenario.training
    samples = -(-t.history_length // t.history_stride)
    kwargs = {
        "window": (samples, test_x.shape[1] // samples),
        "scenario": scenario.model_dump(mode="json"),
        "role": "pursuer",
    }
    decoder = BeliefModel("ukf", **kwargs).decoder
    last, sighted = _last_seen(decoder, test_x)
    means: dict[str, np.ndarray] = {"last seen": last, "centre": np.zeros_like(last)}
    for kind in args.kinds:
        model = BeliefModel(kind, **kwargs)
        if model.learned:
            best, seconds = _fit(
                model, (train_x, train_y), (valid_x, valid_y), settings, args.updates, args.check_every
            )
            print(f"{kind}: {args.updates} updates in {seconds:.0f} s; kept update {best} (best validation NLL)")
        means[kind] = _mean(model, test_x)
    fitted = (
        f"{len(train_x)} training windows ({args.games} games per evader), up to {args.updates} updates "
        f"of batch {settings.batch_size}; "
        if learned
        else ""
    )
    print(
        f"\n{scenario.name}: pure pursuit vs {', '.join(evaders)}; {fitted}{int(test_unseen.sum())} held-out "
        f"unseen moments ({args.test_games} other games per evader)"
    )
    groups = {
        "all unseen": test_unseen,
        "a sighting in the window": test_unseen & sighted,
        "none in the window": test_unseen & ~sighted,
    }
    print("| belief | " + " | ".join(f"{name} ({int(mask.sum())})" for name, mask in groups.items()) + " |")
    print("| --- |" + " ---: |" * len(groups))
    errors = {kind: np.linalg.norm((mean - test_y) * half, axis=1) for kind, mean in means.items()}
    for kind, error in sorted(errors.items(), key=lambda item: item[1][test_unseen].mean()):
        print(f"| {kind} | " + " | ".join(f"{error[mask].mean():.2f}" for mask in groups.values()) + " |")


def _checkpoints_within(run: Path, minutes: float) -> list[tuple[Path, float]]:
    """Every checkpoint of ``run`` written within ``minutes`` of CPU time with that CPU time, oldest first.

    The run's evaluation log maps steps to CPU time; a checkpoint's CPU time is interpolated between
    its rows. Checkpoints with the same step count hold the same policy: one of them is listed.
    """
    import csv

    from pecli.zoo import read_metadata

    rows = list(csv.DictReader((run / "eval_pursuer.csv").open()))
    steps = [0] + [int(r["steps"]) for r in rows]
    used = [0.0] + [float(r["cpu_seconds"]) / 60 for r in rows]
    within = max((s for s, m in zip(steps, used) if m <= minutes), default=0)
    found: dict[int, Path] = {}
    for path in sorted((run / "pursuer").glob("*.zip")):  # ep*.zip sort before best/final/last
        taken = read_metadata(path).steps
        if 0 < taken <= within:
            found.setdefault(taken, path)
    return [(found[taken], float(np.interp(taken, steps, used))) for taken in sorted(found)]


def _capture_rates(
    scenario: Any, pursuers: list[str], evaders: list[str], episodes: int, seed: int, out: Path, workers: int = 1
) -> dict[tuple[str, str], Any]:
    """Every pursuer against every evader (checkpoint paths or policy names): ``PairingResult`` keyed by
    ``(_spec(pursuer), _spec(evader))``, from a ``pecli tournament`` whose pairings are cached in ``out``."""
    from pecli.tournament import find_players, run_tournament

    found = find_players([*pursuers, *evaders], scenario, baselines=True).players  # baselines: the heuristics' roles
    wanted = {"pursuer": {_spec(p) for p in pursuers}, "evader": {_spec(e) for e in evaders}}
    players = {role: [p for p in found[role] if p.spec in wanted[role]] for role in found}
    pairings = [(p, e) for p in players["pursuer"] for e in players["evader"]]
    played = iter(range(1, len(pairings) + 1))

    def report(result: Any, cached: bool) -> None:
        if not cached:
            print(f"  {next(played)}: {result.pursuer} vs {result.evader}", file=sys.stderr, flush=True)

    grid = run_tournament(scenario, players, pairings, episodes, [seed], out, workers, report).grid()
    return {(p.spec, e.spec): grid[(p.name, e.name)] for p, e in pairings}


def _spec(policy: str | Path) -> str:
    """How the tournament names a policy: a checkpoint by its resolved path, anything else as given."""
    return str(Path(policy).resolve()) if str(policy).endswith(".zip") else str(policy)


def _best_ranked(
    run: Path,
    found: list[tuple[Path, float]],
    scenario: Any,
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
    rates = _capture_rates(
        scenario, [str(path) for path, _ in found], ["greedy"], episodes, 1, run / "ranking", workers
    )
    ranked = sorted(
        found, key=lambda c: (-rates[(_spec(c[0]), "greedy")].capture_rate, -c[1])
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


def _captures(checkpoint: Path, scenario: Any, shuffled_too: bool) -> list[int]:
    """Captures in 500 test episodes (seed 0) vs greedy and rash, then the same with shuffled beliefs."""
    from pecli.match import play_match
    from pecli.policies import resolve_policy

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
    from pecli.scenario import load_scenario
    from pecli.stats import two_proportion_z_test

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
            found = _checkpoints_within(run, args.minutes) if (run / "eval_pursuer.csv").is_file() else []
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
    from pecli.scenario import load_scenario
    from pecli.stats import two_proportion_z_test

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
    results = _capture_rates(
        scenario, pursuers, sum(evaders.values(), []), TEST_EPISODES, 0, args.zoo / "belief-cross", args.workers
    )
    captures: dict[str, list[list[tuple[int, int]]]] = {}  # kind → per seed, per evader group: (captures, episodes)
    for kind, found in runs.items():
        for seed, run in found.items():
            pursuer = _spec(run / "pursuer" / checkpoint)
            row = [
                (
                    sum(results[(pursuer, _spec(e))].captures for e in group),
                    sum(results[(pursuer, _spec(e))].episodes for e in group),
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
    s = sub.add_parser("speed")
    s.add_argument("--config", default="paper")
    s.add_argument("--kinds", nargs="+", default=list(KINDS))
    s.add_argument("--steps", type=int, default=4000)
    s.add_argument("--repeats", type=int, default=3)
    q = sub.add_parser("quality")
    q.add_argument("--config", default="paper")
    q.add_argument("--games", type=int, default=2000, help="training games per evader")
    q.add_argument("--test-games", type=int, default=300, help="held-out games per evader")
    q.add_argument("--updates", type=int, default=6000)
    q.add_argument("--check-every", type=int, default=250, help="updates between validation checks")
    q.add_argument(
        "--kinds",
        nargs="+",
        default=["bimdn", "image", "ukf"],
        choices=["bimdn", "image", "ukf"],
        help="the beliefs to fit and score ('last seen' and the centre are always scored)",
    )
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
    {"speed": speed, "quality": quality, "capture": capture, "selfplay": selfplay}[args.step](args)


if __name__ == "__main__":
    main()
