"""Beliefs: what they cost in training and how well they locate an unseen opponent.

    python benchmarks/bench_belief.py speed      # (a) training transitions/s per belief kind, as a ratio to none
    python benchmarks/bench_belief.py league     # (a') CPU seconds of a self-play round per kind at the league recipe
    python benchmarks/bench_belief.py quality    # (b) unseen-position error on held-out games

(a) trains the pursuer on the paper scenario with each ``--belief`` for the same number of
transitions, with learning and belief fitting both active (warm-ups shortened), in one process
on one torch thread, median of ``--repeats``.

(a') runs ``pecli selfplay -c league --belief KIND --rounds R`` for each kind (BiMDN kinds with
``--hidden`` units, 64 as the league recipe runs them), the warm-ups shortened so that learning and belief fitting
both run, and reads each side's CPU seconds from the run's ``selfplay.json``: per round on average and in the last
round. From the second round on, each side also faces its opponent's earlier rounds, whose beliefs run at every
step, so a league's cost per round grows with its pool; ``--rounds 6`` shows it.

(b) collects history windows of a pure-pursuit pursuer against the random-walk, greedy and rash
evaders (``--games`` per evader), fits the BiMDN and the image belief on them by NLL (paper
settings: batch 256, Adam 0.002), keeping the state with the best NLL on validation games, then
measures (:mod:`pecli.rl.belief_quality`), on held-out games with other seeds, the mean distance (m) between each
belief's mean and the evader's true position at the moments the pursuer does not see it: BiMDN, UKF, image,
"last seen" (the last sighting in the window; the arena's centre if none) and the centre itself,
over all unseen moments and split by whether the window holds a sighting.

What a belief adds to capture, in the curve runs (c) and in self-play (d): ``bench_belief_capture.py``.
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np  # noqa: E402
import torch as th  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
KINDS = ("none", "bimdn", "bimdn-mixed", "ukf", "image")


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


def league(args: argparse.Namespace) -> None:
    from pecli.rl.handover import STATE_FILE
    from pecli.rl.state import read_state_file

    warmups = ["learning_starts=1000", "belief_settings.warmup=1000"]
    seconds: dict[str, list[float]] = {kind: [] for kind in args.kinds}
    last: dict[str, list[float]] = {kind: [] for kind in args.kinds}
    with tempfile.TemporaryDirectory(prefix="bench-belief-") as zoo:
        for repeat in range(args.repeats):
            for kind in args.kinds:
                name = f"{kind}-{repeat}"
                sets = [*warmups, *([f"belief_settings.hidden={args.hidden}"] if kind.startswith("bimdn") else [])]
                command = [sys.executable, "-m", "pecli", "selfplay", "-c", "league", "--belief", kind]
                command += ["--rounds", str(args.rounds)]
                command += ["--steps-per-round", str(args.steps), "--zoo", zoo, "--name", name, "--quiet"]
                command += [part for item in sets for part in ("--set", item)]
                env = {**os.environ, "PYTHONPATH": str(ROOT)}
                subprocess.run(command, check=True, cwd=ROOT, env=env, stdout=subprocess.DEVNULL)
                turns = read_state_file(Path(zoo) / name / STATE_FILE).turns
                seconds[kind].append(sum(turn.cpu_seconds for turn in turns) / args.rounds)
                last[kind].append(sum(turn.cpu_seconds for turn in turns[-2:]))  # one turn per side
                print(f"{kind}: {seconds[kind][-1]:.1f} CPU-s per round, last {last[kind][-1]:.1f}", file=sys.stderr)
    print(
        f"league: {args.rounds} self-play round(s), {args.steps} transitions per side each, warm-ups 1 000, "
        f"BiMDN {args.hidden} units, median of {args.repeats}"
    )
    print("| belief | CPU s per round | vs none | last round | vs none |")
    print("| --- | ---: | ---: | ---: | ---: |")
    for kind in args.kinds:
        cells = []
        for measured in (seconds, last):
            cpu = statistics.median(measured[kind])
            reference = statistics.median(measured["none"]) if "none" in measured else None
            cells += [f"{cpu:.1f}", f"{cpu / reference:.2f}" if reference else "-"]
        print(f"| {kind} | {' | '.join(cells)} |")


def quality(args: argparse.Namespace) -> None:
    from pecli.belief.model import LEARNED_KINDS, BeliefModel
    from pecli.rl.belief_quality import (
        belief_means,
        collect_windows,
        fit_belief,
        last_sighting,
        location_error,
    )
    from pecli.scenario import load_scenario

    th.manual_seed(0)
    scenario = load_scenario(args.config)
    evaders = ["random-walk", "greedy", "rash"]
    learned = [kind for kind in args.kinds if kind in LEARNED_KINDS]
    if learned:
        train = collect_windows(scenario, "pure-pursuit", evaders, args.games, seed=0)
        valid = collect_windows(scenario, "pure-pursuit", evaders, max(args.games // 10, 10), seed=500)
    test = collect_windows(scenario, "pure-pursuit", evaders, args.test_games, seed=1000)
    settings = scenario.training.belief_settings
    t = scenario.training
    samples = -(-t.history_length // t.history_stride)
    kwargs = {
        "window": (samples, test.history.shape[1] // samples),
        "scenario": scenario.model_dump(mode="json"),
        "role": "pursuer",
    }
    last, sighted = last_sighting(BeliefModel("ukf", **kwargs).decoder, test.history)
    means: dict[str, np.ndarray] = {"last seen": last, "centre": np.zeros_like(last)}
    for kind in args.kinds:
        model = BeliefModel(kind, **kwargs)
        if model.learned:
            fit = fit_belief(model, train, valid, settings, args.updates, args.check_every)
            print(
                f"{kind}: {args.updates} updates in {fit.seconds:.0f} s; kept update {fit.kept_update} "
                "(best validation NLL)"
            )
        means[kind] = belief_means(model, test.history)
    fitted = (
        f"{len(train)} training windows ({args.games} games per evader), up to {args.updates} updates "
        f"of batch {settings.batch_size}; "
        if learned
        else ""
    )
    print(
        f"\n{scenario.name}: pure pursuit vs {', '.join(evaders)}; {fitted}{int(test.unseen.sum())} held-out "
        f"unseen moments ({args.test_games} other games per evader)"
    )
    groups = {
        "all unseen": test.unseen,
        "a sighting in the window": test.unseen & sighted,
        "none in the window": test.unseen & ~sighted,
    }
    print("| belief | " + " | ".join(f"{name} ({int(mask.sum())})" for name, mask in groups.items()) + " |")
    print("| --- |" + " ---: |" * len(groups))
    errors = {kind: location_error(scenario, mean, test.target) for kind, mean in means.items()}
    for kind, error in sorted(errors.items(), key=lambda item: item[1][test.unseen].mean()):
        print(f"| {kind} | " + " | ".join(f"{error[mask].mean():.2f}" for mask in groups.values()) + " |")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="step", required=True)
    s = sub.add_parser("speed")
    s.add_argument("--config", default="paper")
    s.add_argument("--kinds", nargs="+", default=list(KINDS))
    s.add_argument("--steps", type=int, default=4000)
    s.add_argument("--repeats", type=int, default=3)
    g = sub.add_parser("league")
    g.add_argument("--kinds", nargs="+", default=list(KINDS))
    g.add_argument("--steps", type=int, default=10000, help="transitions per side")
    g.add_argument("--hidden", type=int, default=64, help="BiMDN units per direction")
    g.add_argument("--repeats", type=int, default=1)
    g.add_argument("--rounds", type=int, default=1, help="self-play rounds (from the second, learned opponents play)")
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
    args = parser.parse_args()
    th.set_num_threads(1)
    {"speed": speed, "league": league, "quality": quality}[args.step](args)


if __name__ == "__main__":
    main()
