"""How strong are self-play's players? Schedules and belief kinds compared at equal CPU time, and their exploitability.

    python benchmarks/bench_strength.py train [--experiment strength|strength-small|schedules|exploitability|FILE] \\
        [--schedules league nash alternating simultaneous] [--beliefs none bimdn] [--seeds 0 1 2] [--cpu-hours 4] \\
        [--config tuned] [--rounds 150] [--steps-per-round 40000] [--zoo runs/bench_strength]
    python benchmarks/bench_strength.py report [--zoo runs/bench_strength] [--episodes 500] \\
        [--cpu-hours H | --round N] [--average K [--average-evaders]]
    python benchmarks/bench_strength.py exploit [--zoo runs/bench_strength] [--cpu-minutes 20] [--seeds 3] [--warm] \\
        [--handed-over | --cpu-hours H | --round N]
    python benchmarks/bench_strength.py behaviour --pursuer P.zip --evaders E.zip hider ... [--episodes 200]

``train`` trains the runs of an experiment (configs/experiments/), its grid and budget replaced by the options
given, one at a time in this process with the experiment's own code (:func:`pecli.experiment.runs.execute_run`):
each stops after the first round at which its recorded CPU time reaches its budget, so every schedule gets the
same CPU whatever a round costs it. Stopping it is safe; the same command continues every run from its durable
state. ``pecli experiment run strength --out runs/strength`` trains the same runs on Ray.

``report`` takes each run's main players at an equal budget (:func:`pecli.experiment.compare.main_players`) and
plays them as one arm of ``pecli experiment compare``: every pursuer against the scripted evaders and the other
runs' evaders (cross-play), every evader against pure pursuit. It prints the targets met or missed, and between
groups of runs (schedules with the same belief; ``bimdn`` against ``none`` pursuers of one schedule) the
two-proportion z-test over games, Welch's t-test over runs (the training seed as the unit), and, for the belief
kinds, the Mantel–Haenszel test stratified by evader (a run never meets its own evader, so each kind meets its own
kind's evaders less often).

``exploit`` measures each run's pursuer–evader pair against best responses (``pecli exploit --pair``, in
``<zoo>/exploit/<run>``, resumable) and prints the targets: a best evader held to >= 0.75, NashConv <= 0.25.

``behaviour`` is a diagnostic: how evaders play against one pursuer (``pecli play --behaviour`` for each).
An A/B of two zoos is ``pecli experiment compare``; a copy of a run to train on is ``pecli zoo fork``.
"""

from __future__ import annotations

import argparse
import copy
import os
import re
import sys
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")

from pecli.errors import ConfigError, PecliError
from pecli.experiment.compare import (
    compare_arms,
    contrast,
    handed_over,
    main_players,
    over_every_evader,
    pool,
    recipe,
    run_rates,
    welch_p,
)
from pecli.experiment.runs import check_unchanged, execute_run
from pecli.experiment.spec import RunSpec, experiment_from_dict, experiment_path, read_experiment
from pecli.match import Behaviour, play_match
from pecli.policies import resolve_policy
from pecli.process import one_torch_thread, sigterm_stops
from pecli.rl.fork import run_cpu_hours
from pecli.rl.selfplay import SelfPlayInterrupted
from pecli.scenario import load_scenario
from pecli.zoo import Run

RUN_NAME = re.compile(r"[a-z-]+-(alternating|simultaneous|league|nash)-s\d+")  # <belief>-<schedule>-s<seed>


def strength_runs(args: argparse.Namespace) -> list[RunSpec]:
    """The runs of ``--experiment``, its grid and budget replaced by the options given."""
    path = experiment_path(args.experiment)
    data = read_experiment(path)
    experiment_from_dict(copy.deepcopy(data), str(path), base=path.parent)  # the file as written is valid
    if args.config is not None:
        data["scenario"] = args.config
    given = {
        "kinds": args.beliefs,
        "seeds": args.seeds,
        "schedules": args.schedules,
        "cpu_hours": args.cpu_hours,
        "rounds": args.rounds,
        "steps_per_round": args.steps_per_round,
    }
    data["runs"].update({key: value for key, value in given.items() if value is not None})
    return experiment_from_dict(data, str(path), base=path.parent).runs()


def train(args: argparse.Namespace) -> None:
    args.zoo.mkdir(parents=True, exist_ok=True)
    runs = strength_runs(args)
    for run in runs:  # every run first: a resumed run keeps its settings
        check_unchanged(run, args.zoo)
    for run in runs:
        limit = f"of {run.cpu_hours:g} CPU-h" if run.cpu_hours is not None else "CPU-h (no CPU budget)"
        print(f"{run.name}: {run_cpu_hours(args.zoo / run.name):.2f} {limit}", flush=True)
        try:
            with sigterm_stops():  # `kill` (or a job's time limit) commits and stops like Ctrl-C
                outcome = execute_run(
                    run,
                    args.zoo,
                    progress=sys.stderr.isatty(),  # a log gets a line a round
                    report=lambda line, name=run.name: print(f"{name}: {line}", flush=True),
                )
        except SelfPlayInterrupted as stop:
            sys.exit(f"{run.name}: stopped in {stop}; its finished work is kept: run the same command to continue")
        except KeyboardInterrupt:  # before its first round started: nothing of it to keep yet
            sys.exit(f"{run.name}: stopped; run the same command to continue")
        did = "trained before" if outcome["did"] == "finished" else f"{outcome['did']} by this command"
        print(
            f"{run.name}: to round {outcome['progress']['round']}, {run_cpu_hours(args.zoo / run.name):.2f} CPU-h "
            f"({did})",
            flush=True,
        )


def picked(args: argparse.Namespace, average: int = 1, averaged: tuple[str, ...] = ("pursuer",)) -> dict:
    return main_players(
        args.zoo,
        args.cpu_hours,
        args.round,
        average,
        averaged,
        pattern=RUN_NAME,
        report=lambda line: print(line, file=sys.stderr),
    )


def per_run(faced: dict, sides: dict[str, list], evaders: set) -> str:
    rates = {label: run_rates(faced, names, evaders) for label, names in sides.items()}
    listed = "; ".join(f"{label} {', '.join(f'{r:.3f}' for r in values)}" for label, values in rates.items())
    p = welch_p(*rates.values())
    return f"{listed}" + (" (a test needs 2 runs of each)" if p is None else f"; Welch t-test p = {p:.2g}")


def report(args: argparse.Namespace) -> None:
    if args.average_evaders and args.average < 2:
        sys.exit("--average-evaders averages the evaders over --average K rounds: give K of 2 or more")
    runs = picked(args, args.average, ("pursuer", "evader") if args.average_evaders else ("pursuer",))
    result = compare_arms({"zoo": runs}, load_scenario(args.config), args.zoo / "report", args.episodes, args.workers)
    print("\n".join(result.lines()[2:]))  # the table: one arm, no A/B
    faced = {run: evaders for (_, run), evaders in result.faced.items()}
    faced = {
        run: {(e[1] if isinstance(e, tuple) else e): r for e, r in evaders.items()} for run, evaders in faced.items()
    }
    groups: dict[tuple[str, str], list[str]] = {}  # (schedule, belief) -> its runs
    for name in runs:
        groups.setdefault(recipe(Run(args.zoo / name).scenario()), []).append(name)
    budget = (
        f"at {args.cpu_hours} CPU-h"
        if args.cpu_hours is not None
        else f"after round {args.round}"
        if args.round is not None
        else "at each run's newest round (not an equal budget: give --cpu-hours)"
    )
    print(f"\npursuers pooled over every evader (scripted and cross-play) and seed, {budget}:")
    for schedule in sorted({s for s, _ in groups}):
        kinds = {b: (pool(faced, names), len(names)) for (s, b), names in sorted(groups.items()) if s == schedule}
        print(
            f"- {schedule}: "
            + ", ".join(f"{b} {c / n:.3f} ({k} run{'s' * (k > 1)})" for b, ((c, n), k) in kinds.items())
        )
    for (first, belief), (second, other) in ((a, b) for a in sorted(groups) for b in sorted(groups)):
        if belief == other and first < second:
            common, rate_a, rate_b, p = contrast(faced, groups[(first, belief)], groups[(second, belief)])
            pair = {first: groups[(first, belief)], second: groups[(second, belief)]}
            print(
                f"- {belief}: {first} {rate_a:.3f} vs {second} {rate_b:.3f} over the {len(common)} evaders all met:"
                f" z-test p = {p:.2g}; per run {per_run(faced, pair, common)}"
            )
    missed = result.missed()
    for schedule in sorted({s for s, b in groups if b == "bimdn" and (s, "none") in groups}):
        sides = {"bimdn": groups[(schedule, "bimdn")], "none": groups[(schedule, "none")]}
        every, rate_b, rate_n, p, excess, p_stratified = over_every_evader(faced, sides["bimdn"], sides["none"])
        met = rate_b > rate_n and p < 0.05 and excess > 0 and p_stratified < 0.05
        print(
            f"\n{schedule}: bimdn pursuers {rate_b:.3f} vs none {rate_n:.3f} over every evader a pursuer of each kind "
            f"met ({len(every)}): z-test p = {p:.2g}; stratified by evader (Mantel-Haenszel) {excess:+.1f} "
            f"captures, p = {p_stratified:.2g} ({'met' if met else 'NOT met'}: bimdn must capture more, p < 0.05 in "
            f"both); per run {per_run(faced, sides, every)}"
        )
        if not met:
            missed.append(f"{schedule}: bimdn pursuers capture more than none over every evader")
    print("\ntargets missed:" if missed else "\nevery target met", *missed, sep="\n- " if missed else "")


def exploit(args: argparse.Namespace) -> None:
    """Each run's pair against best responses trained on each alone (:func:`pecli.exploit.exploit_pair`)."""
    from pecli.exploit import exploit_pair

    if args.handed_over:
        runs = handed_over(args.zoo)
    else:
        runs = picked(args)
    runs = {name: players for name, players in runs.items() if not args.runs or name in args.runs}
    if not runs:
        sys.exit(f"no run to measure under {args.zoo}")
    print(
        f"best responses of {args.cpu_minutes:g} CPU-minutes, {args.seeds} seeds"
        f"{', fresh and warm-started' if args.warm else ''}, {args.episodes} held-out games; the strongest counts\n"
    )
    print(
        "| run | pair | best evader holds the pursuer to | best pursuer catches the evader | NashConv [95 %] | "
        "targets (>= 0.75, <= 0.25) |\n| --- | ---: | ---: | ---: | ---: | --- |"
    )
    for name, players in runs.items():
        try:
            with sigterm_stops():
                result = exploit_pair(
                    str(players.pursuer),
                    str(players.evader),
                    load_scenario(args.config),
                    args.zoo / "exploit" / name,
                    warm=args.warm,
                    cpu_minutes=args.cpu_minutes,
                    seeds=tuple(range(args.seeds)),
                    episodes=args.episodes,
                    report=lambda line: print(line, file=sys.stderr, flush=True),
                )
        except KeyboardInterrupt:
            sys.exit(f"{name}: stopped; every response keeps its state: run the same command to continue")
        held = [r.capture_rate for r in result.against_pursuer.responses]
        caught = [r.capture_rate for r in result.against_evader.responses]
        low, high = result.interval
        met = [min(held) >= 0.75, result.nash_conv <= 0.25]
        print(
            f"| {name} | {result.capture_rate:.2f} | {min(held):.2f} ({min(held):.2f}-{max(held):.2f}) | "
            f"{max(caught):.2f} ({min(caught):.2f}-{max(caught):.2f}) | {result.nash_conv:.2f} [{low:.2f}, "
            f"{high:.2f}] | {' / '.join('met' if m else 'missed' for m in met)} |",
            flush=True,
        )


def behaviour(args: argparse.Namespace) -> None:
    """How each evader plays against one pursuer (is it caught by a failed search or a lost chase?)."""
    scenario = load_scenario(args.config)
    pursuer = resolve_policy(args.pursuer, "pursuer", scenario, seed=1)
    evaders = {name: resolve_policy(name, "evader", scenario, seed=2) for name in args.evaders}
    one_torch_thread()
    print(f"against {args.pursuer} on {scenario.name}, {args.episodes} games each (means over the steps they lasted)\n")
    print(
        "| evader | caught | seen by the pursuer | sees the pursuer | speed unseen / seeing (m/step) | distance "
        "| to the nearest wall |\n| --- | ---: | ---: | ---: | --- | ---: | ---: |"
    )
    for name, evader in evaders.items():
        _, recording = play_match(scenario, pursuer, evader, args.episodes, seed=0, record=args.episodes)
        m = Behaviour.of(recording)
        print(
            f"| {name} | {m.caught:.2f} | {m.seen:.2f} | {m.sees:.2f} | {m.speed_unseen:.3f} / {m.speed_seeing:.3f} "
            f"| {m.distance:.1f} m | {m.wall:.2f} m |",
            flush=True,
        )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = parser.add_subparsers(dest="what", required=True)
    commands = {name: sub.add_parser(name) for name in ("train", "report", "exploit", "behaviour")}
    for name in ("train", "report", "exploit"):
        commands[name].add_argument("--zoo", type=Path, default=Path("runs/bench_strength"))
    for name in ("report", "exploit"):
        at = commands[name].add_mutually_exclusive_group()
        at.add_argument("--cpu-hours", type=float, default=None, help="every run at this CPU budget")
        at.add_argument("--round", type=int, default=None, help="every run after this many rounds")
        commands[name].add_argument("--episodes", type=int, default=500)
    for name in ("report", "exploit", "behaviour"):
        commands[name].add_argument("--config", default="tuned", help="the scenario the players play")
    probe = commands["exploit"]
    probe.add_argument("--cpu-minutes", type=float, default=20.0, help="CPU-minutes of each best response")
    probe.add_argument("--seeds", type=int, default=3, help="best responses per side and start (seeds 0 .. K-1)")
    probe.add_argument("--warm", action="store_true", help="also warm-start each response from the run's own player")
    probe.add_argument("--handed-over", action="store_true", help="each run's average.zip players (what it hands over)")
    probe.add_argument("--runs", nargs="+", default=None, help="only these runs (default: every run)")
    ranked = commands["report"]
    ranked.add_argument("--workers", type=int, default=2)
    ranked.add_argument(
        "--average",
        type=int,
        default=1,
        metavar="K",
        help="each run's pursuer: the mean of its weights over the last K rounds",
    )
    ranked.add_argument("--average-evaders", action="store_true", help="with --average: the evaders too")
    learn = commands["train"]
    learn.add_argument("--config", default=None, help="the scenario (default: the experiment's)")
    learn.add_argument(
        "--experiment",
        default="strength",
        help="a built-in experiment or a YAML file of self-play runs; the options below replace its own",
    )
    learn.add_argument(
        "--schedules", nargs="+", default=None, choices=["alternating", "simultaneous", "league", "nash"]
    )
    learn.add_argument("--beliefs", nargs="+", default=None)
    learn.add_argument("--seeds", nargs="+", type=int, default=None)
    learn.add_argument("--cpu-hours", type=float, default=None)
    learn.add_argument("--steps-per-round", type=int, default=None, help="transitions per side per round")
    learn.add_argument("--rounds", type=int, default=None, help="the ceiling of rounds (the curriculum's span)")
    moves = commands["behaviour"]
    moves.add_argument("--pursuer", required=True, help="a checkpoint or built-in pursuer")
    moves.add_argument("--evaders", nargs="+", required=True, help="checkpoints or built-in evaders")
    moves.add_argument("--episodes", type=int, default=200)
    args = parser.parse_args()
    try:
        {"train": train, "report": report, "exploit": exploit, "behaviour": behaviour}[args.what](args)
    except (PecliError, ConfigError) as error:
        sys.exit(str(error))


if __name__ == "__main__":
    main()
