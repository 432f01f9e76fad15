"""How strong are self-play's players? Schedules and beliefs compared at equal CPU time, and their exploitability.

    python benchmarks/bench_strength.py train [--experiment strength|strength-small|schedules|FILE] \\
        [--schedules league alternating simultaneous] [--beliefs none bimdn] [--seeds 0 1 2] [--cpu-hours 4] \\
        [--config tuned] [--rounds 150] [--steps-per-round 40000] [--zoo runs/bench_strength]
    python benchmarks/bench_strength.py report [--zoo runs/bench_strength] [--episodes 500] [--cpu-hours H | --round N] [--average K [--average-evaders]]
    python benchmarks/bench_strength.py exploit [--zoo runs/bench_strength] [--cpu-minutes 20] [--seeds 3] [--warm] [--handed-over | --cpu-hours H | --round N]
    python benchmarks/bench_strength.py compare --arms control=ZOO_A exploiters=ZOO_B [--episodes 500] [--cpu-hours H | --round N]
    python benchmarks/bench_strength.py behaviour --pursuer P.zip --evaders E.zip hider ... [--episodes 200] [--render F.png]
    python benchmarks/bench_strength.py fork --run ZOO/RUN --to ZOO [--add corner-sitter ...]

``train`` trains runs of the ``strength`` experiment (configs/experiments/strength.yaml; ``--experiment
schedules`` or ``strength-small`` for those, or an experiment file of your own), its grid and budget replaced by
the options given, one at a time in this process, with the experiment's own code
(:func:`pecli.experiment.runs.execute_run`): each stops after the first round at which its recorded CPU time
(the sum of its turns') reaches its CPU budget, so every schedule gets the same CPU, whatever a round costs it,
and ``--rounds`` is a ceiling (over which the curriculum is scheduled, unless the experiment fixes its span in
transitions, as ``schedules`` does). Stopping it at any moment is safe; run it again to continue (each run
resumes from its own durable state).

The same runs as one Ray experiment (2 at a time here, as many as a cluster has cores), each to the same
CPU budget, then the same report::

    pecli experiment run strength --out runs/strength [--address auto]
    python benchmarks/bench_strength.py report --zoo runs/strength/zoo

``report`` takes each run's newest main checkpoints and plays (``pecli.tournament``, cached in
``<zoo>/report``): every final pursuer against greedy, rash, random-walk and pecli's adversaries
(circler, blindside, wall-runner, hider, corner-sitter) and against every other run's final evader (cross-play); every
final evader against pure pursuit. It prints the issue's targets met or missed, each schedule's pursuers
pooled over evaders and seeds, and per schedule that has both, ``bimdn`` against ``none`` pursuers (same
schedule, same CPU) over every evader a pursuer of each kind met, cross-play included (learned evaders count, as
in the paper's Table I): the two-proportion z-test, and beside it the same test stratified by evader
(Mantel–Haenszel), because a run never meets its own evader, so each kind meets its own kind's evaders less
often; the target is met when both say ``bimdn`` captures more. Then the same over the scripted evaders alone
(those every pursuer met), which both kinds catch near 0.99 once trained. The z-tests count every episode as an
independent sample; beside them, Welch's t-test over the runs' own rates takes the training seed as the unit
(wider spread, the stricter test). Each two schedules trained with the same belief are compared by the z-test
and Welch's, over the evaders all their pursuers met. With
``--cpu-hours H`` it takes each run's checkpoints of the round at which a run of budget ``H`` would have
stopped (``--round N``: of round N, equal transitions per main learner instead of equal CPU), and leaves
out runs not there yet: every schedule compared at any equal budget, while the runs are still training.
``--average K`` plays each run's pursuer as the mean of its weights over the K rounds ending at the round read
(``pecli zoo average``; the evaders stay the round's own, unless ``--average-evaders``: then both sides are
averaged, as self-play's ``average.zip`` once those rounds are all after the curriculum).

``exploit`` measures how exploitable each run's pursuer-evader pair is (``pecli exploit --pair`` per run, in
``<zoo>/exploit/<run>``, resumable): best responses of ``--cpu-minutes`` over ``--seeds``, fresh and with
``--warm`` also warm-started from the run's own player of their role, on the real game; it prints the strongest
best evader's capture rate, the strongest best pursuer's and NashConv with its interval, against the targets
(a best evader held to >= 0.75, NashConv <= 0.25). ``--handed-over`` takes each run's ``average.zip`` players.

``compare`` is an A/B of two or more zoos of the same runs (same names: same kind, schedule and seed), e.g. a control
and a copy trained on with other settings from the same checkpoint: every arm's pursuers play the scripted evaders
and the evaders of every *other* run of every arm (not their own, nor their twins in the other arms, which share
their history), so each run meets the same evaders in every arm. When the control (the first arm) has runs that
the others lack (a fork of some runs only), their evaders join every arm's cross-play as bystanders. It prints each
arm's rows, each arm pooled against the first (z-test over episodes) and the per-run differences (paired t-test, a
run as the unit), and how each arm's evaders fare against the other runs' pursuers. Cached in ``--out``.

``fork`` copies a stopped run into another zoo, to train it on as one arm of an A/B whose control is the original
trained on. ``--add`` puts scripted players into its league pools (each in the pools of the roles it plays, as the
scripted players a run starts with), so a run started before pecli had them can be tested with them; other
settings go into the copy's ``config.yaml`` by hand, as ``train`` refuses a run whose settings changed.

``behaviour`` is a diagnostic, not a target: how evaders play against one pursuer (caught, seen, how fast they
move while they see it and while they do not, how far they keep), to tell a lost search from a lost chase.
"""

from __future__ import annotations

import argparse
import copy
import dataclasses
import json
import os
import re
import sys
from pathlib import Path

import numpy as np
import yaml
from scipy.stats import ttest_ind, ttest_rel

os.environ.setdefault("OMP_NUM_THREADS", "1")

from pecli.cli.common import one_torch_thread, sigterm_stops  # noqa: E402
from pecli.errors import ConfigError, PecliError  # noqa: E402
from pecli.experiment.pipeline import changes  # noqa: E402
from pecli.experiment.runs import execute_run  # noqa: E402
from pecli.experiment.spec import RunSpec, experiment_from_dict, experiment_path, read_experiment  # noqa: E402
from pecli.io import file_digest  # noqa: E402
from pecli.match import Recording, play_match  # noqa: E402
from pecli.policies import resolve_policy  # noqa: E402
from pecli.rl.averaging import average_checkpoints  # noqa: E402
from pecli.rl.budget import cpu_through  # noqa: E402
from pecli.rl.fork import run_cpu_hours  # noqa: E402
from pecli.rl.handover import AVERAGE_FILE  # noqa: E402
from pecli.rl.selfplay import STATE_FILE, SelfPlayInterrupted, round_of  # noqa: E402
from pecli.scenario import Scenario, load_scenario, read_yaml  # noqa: E402
from pecli.stats import mantel_haenszel_test, two_proportion_z_test  # noqa: E402
from pecli.tournament import Player, find_players, run_tournament  # noqa: E402

HEURISTIC_EVADERS = ("greedy", "rash", "random-walk")
ADVERSARIES = ("circler", "blindside", "wall-runner", "hider", "corner-sitter")
RUN_NAME = re.compile(r"[a-z-]+-(alternating|simultaneous|league|nash)-s\d+")  # <belief>-<schedule>-s<seed>
TARGETS = {"heuristics": 0.90, "adversaries": 0.85, "cross-play": 0.80, "pure-pursuit held to": 0.25}


def strength_runs(args: argparse.Namespace) -> list[RunSpec]:
    """The runs of ``--experiment`` (``strength`` by default), its grid and budget replaced by the schedules,
    beliefs, seeds, CPU budget and scenario given."""
    try:
        path = experiment_path(args.experiment)
        data = read_experiment(path)
        experiment_from_dict(copy.deepcopy(data), str(path), base=path.parent)  # the file as written is valid
        if args.config is not None:
            data["scenario"] = args.config
        given = {"kinds": args.beliefs, "seeds": args.seeds, "schedules": args.schedules, "cpu_hours": args.cpu_hours,
                 "rounds": args.rounds, "steps_per_round": args.steps_per_round}
        data["runs"].update({key: value for key, value in given.items() if value is not None})
        return experiment_from_dict(data, str(path), base=path.parent).runs()
    except ConfigError as error:  # a bad file, or an option its checks refuse (a belief kind, a budget)
        sys.exit(str(error))


def train(args: argparse.Namespace) -> None:
    args.zoo.mkdir(parents=True, exist_ok=True)
    runs = strength_runs(args)
    for run in runs:  # every run first: a resumed run keeps its settings (--config, --rounds, --steps-per-round)
        recorded = args.zoo / run.name / "config.yaml"
        changed = changes(read_yaml(recorded), run.scenario.model_dump(mode="json")) if recorded.is_file() else []
        if changed:
            sys.exit(f"{run.name} was started with other settings ({changed[0]}): give them again, or another --zoo")
    for run in runs:
        limit = f"of {run.cpu_hours:g} CPU-h" if run.cpu_hours is not None else "CPU-h (no CPU budget)"
        print(f"{run.name}: {run_cpu_hours(args.zoo / run.name):.2f} {limit}", flush=True)
        try:
            with sigterm_stops():  # `kill` (or a job's time limit) commits and stops like Ctrl-C
                outcome = execute_run(run, args.zoo, progress=sys.stderr.isatty(),  # a log gets a line a round
                                      report=lambda line, name=run.name: print(f"{name}: {line}", flush=True))
        except SelfPlayInterrupted as stop:
            sys.exit(f"{run.name}: stopped in {stop}; its finished work is kept: run the same command to continue")
        except KeyboardInterrupt:  # before its first round started: nothing of it to keep yet
            sys.exit(f"{run.name}: stopped; run the same command to continue")
        did = "trained before" if outcome["did"] == "finished" else f"{outcome['did']} by this command"
        print(f"{run.name}: to round {outcome['progress']['round']}, {run_cpu_hours(args.zoo / run.name):.2f} CPU-h "
              f"({did})", flush=True)


def final_players(zoo: Path, cpu_hours: float | None = None, at_round: int | None = None,
                  average: int = 1, averaged: tuple[str, ...] = ("pursuer",)) -> dict[str, dict[str, Path]]:
    """Each run's main checkpoint per role, ``{run: {role: path}}``: those of its newest round, of round
    ``at_round``, or with ``cpu_hours`` of the first round by whose end the run had spent that much CPU (where
    a run of that budget would have stopped); ``"at"`` is that round's evader checkpoint (its round and CPU). A
    run not there yet is left out, and said so. With ``average`` k > 1 the players of the roles ``averaged`` are
    the means of the main learner's weights over the k rounds ending there (written once to
    ``<zoo>/report/average``; self-play's ``average.zip`` is the same once those rounds are all after the
    curriculum)."""
    runs = {}
    for state in sorted(zoo.glob("*/selfplay.json")):
        name = state.parent.name
        if not RUN_NAME.fullmatch(name):  # not a run of the strength experiment
            continue
        turns = json.loads(state.read_text())["turns"]
        main = {(t["round"], t["role"]): state.parent / t["checkpoint"]
                for t in turns if t.get("learner", "main") == "main"}
        done = sorted(r for r, role in main if role == "pursuer" and (r, "evader") in main)  # rounds both sides ended
        spent = [cpu_through(turns, r) / 3600 for r in done]
        chosen = done[-1:]
        if cpu_hours is not None:
            chosen = [r for r, hours in zip(done, spent) if hours >= cpu_hours][:1]
        elif at_round is not None:
            chosen = [r for r in done if r == at_round]
        if not chosen:
            where = (f"{max(spent, default=0.0):.2f} of {cpu_hours} CPU-h" if cpu_hours is not None
                     else f"round {max(done, default=0)} of {at_round}" if at_round is not None else "no round")
            print(f"{name}: left out, {where} so far", file=sys.stderr)
            continue
        runs[name] = {role: main[(chosen[0], role)] for role in ("pursuer", "evader")}
        runs[name]["at"] = main[(chosen[0], "evader")]
        rounds = [r for r in done if r <= chosen[0]][-average:]
        if average > 1 and len(rounds) < average:
            print(f"{name}: left out, {len(rounds)} rounds to average, not {average}", file=sys.stderr)
            del runs[name]
            continue
        for role in averaged if average > 1 else ():
            out = zoo / "report" / "average" / f"{name}-{role}-{rounds[0]:03d}-{rounds[-1]:03d}.zip"
            if not out.is_file():
                try:
                    average_checkpoints([main[(r, role)] for r in rounds], out)
                except PecliError as error:  # checkpoints of another network (a run resumed with other settings)
                    sys.exit(f"{name}: cannot average its {role}s: {error}")
            runs[name][role] = out
    if not runs:
        sys.exit(f"no self-play run under {zoo} has the rounds asked for: run `train` first, or ask for fewer")
    return runs


def cpu_hours_to(checkpoint: Path) -> float:
    """CPU hours its run had spent by the end of the round that wrote ``checkpoint`` (``<run>/<role>/round-N.zip``)."""
    turns = json.loads((checkpoint.parent.parent / "selfplay.json").read_text())["turns"]
    return cpu_through(turns, round_of(checkpoint)) / 3600


Faced = dict[str, dict[str, tuple[int, int]]]  # run -> each evader its pursuer met -> (captures, episodes)


def pool(faced: Faced, runs: list[str], evaders: set[str] | None = None) -> tuple[int, int]:
    """Captures and episodes of the pursuers of ``runs`` summed over the evaders they met (or ``evaders``)."""
    rates = [r for name in runs for e, r in faced[name].items() if evaders is None or e in evaders]
    return sum(c for c, _ in rates), sum(n for _, n in rates)


def seed_level(faced: Faced, sides: dict[str, list[str]], evaders: set[str]) -> str:
    """Each run's capture rate over ``evaders`` and Welch's t-test of the two ``sides`` (label -> its runs).

    The z-test pools episodes as if each were independent; the runs' spread from one training seed to another is
    wider than that, so this test, with a run as one sample, is the stricter one."""
    rates = {}
    for name in (name for names in sides.values() for name in names):
        captures, episodes = pool(faced, [name], evaders)
        rates[name] = captures / episodes
    listed = "; ".join(f"{label} {', '.join(f'{rates[n]:.3f}' for n in names)}" for label, names in sides.items())
    if min(len(names) for names in sides.values()) < 2:
        return f"{listed} (a test needs 2 runs of each)"
    first, second = ([rates[n] for n in names] for names in sides.values())
    return f"{listed}; Welch t-test p = {ttest_ind(first, second, equal_var=False).pvalue:.2g}"


def contrast(faced: Faced, first: list[str], second: list[str]) -> tuple[set[str], float, float, float]:
    """The evaders that every pursuer of ``first`` and ``second`` met (not their runs' own), each side's capture
    rate over them and the two-proportion z-test's p of one against the other."""
    common = set.intersection(*(set(faced[name]) for name in (*first, *second)))
    if not common:
        raise ValueError("no evader was met by every pursuer of both sides")
    return common, *pooled_z_test(faced, first, second, common)


def pooled_z_test(faced: Faced, first: list[str], second: list[str], evaders: set[str]) -> tuple[float, float, float]:
    """The capture rates of the pursuers of ``first`` and ``second`` pooled over ``evaders``, and the z-test's p."""
    (ca, na), (cb, nb) = pool(faced, first, evaders), pool(faced, second, evaders)
    return ca / na, cb / nb, two_proportion_z_test(ca, na, cb, nb)


def over_every_evader(faced: Faced, first: list[str],
                      second: list[str]) -> tuple[set[str], float, float, float, float, float]:
    """The pursuers of ``first`` against those of ``second`` over every evader a pursuer of each side met, cross-play
    included (learned evaders count, as in the paper's Table I): those evaders, each side's pooled rate, the
    z-test's p, and ``first``'s captures above equal rates per evader with the Mantel–Haenszel test's p. The sides
    meet the learned evaders in different proportions (a run never meets its own), so the stratified test is the
    one to trust."""
    common = set().union(*(faced[n] for n in first)) & set().union(*(faced[n] for n in second))
    if not common:
        raise ValueError("no evader was met by a pursuer of each side")
    excess, p_stratified = mantel_haenszel_test([(*pool(faced, first, {e}), *pool(faced, second, {e}))
                                                 for e in sorted(common)])
    return common, *pooled_z_test(faced, first, second, common), excess, p_stratified


def print_schedules(faced: Faced, groups: dict[tuple[str, str], list[str]], budget: str) -> None:
    """Each two schedules trained with the same belief, their pursuers over the evaders all of them met."""
    keys = sorted(groups, key=lambda key: (key[1], key[0]))  # by belief, then schedule
    pairs = [(belief, first, second) for (first, belief) in keys for (second, other) in keys
             if other == belief and first < second]
    if pairs:
        print(f"\nschedules against each other (same belief), {budget}: z-test over episodes, Welch over runs")
    for belief, first, second in pairs:
        a, b = groups[(first, belief)], groups[(second, belief)]
        common, rate_a, rate_b, p = contrast(faced, a, b)
        print(f"- {belief}: {first} {rate_a:.3f} vs {second} {rate_b:.3f} over the {len(common)} evaders all of "
              f"them met ({', '.join(sorted(common))}): z-test p = {p:.2g}")
        print(f"  per run: {seed_level(faced, {first: a, second: b}, common)}")


def print_beliefs(faced: Faced, schedule: str, bimdn: list[str], none: list[str],
                  hours: dict[str, float]) -> str | None:
    """The target ``bimdn`` > ``none`` for one schedule's pursuers (``hours``: each kind's mean CPU-hours), judged
    over every evader, then the scripted evaders' reading; the missed target's line, or None when met."""
    every, every_b, every_n, p_every, excess, p_stratified = over_every_evader(faced, bimdn, none)
    better = every_b > every_n and p_every < 0.05 and excess > 0 and p_stratified < 0.05
    print(f"\n{schedule}: bimdn pursuers {every_b:.3f} vs none {every_n:.3f} over every evader a pursuer of each "
          f"kind met ({len(every)}, cross-play included) and every seed, at {hours['bimdn']:.2f} and "
          f"{hours['none']:.2f} CPU-h on average: z-test p = {p_every:.2g}; stratified by evader (Mantel-Haenszel) "
          f"{excess:+.1f} captures, p = {p_stratified:.2g} ({'met' if better else 'NOT met'}: bimdn must capture "
          "more, p < 0.05 in both)")
    sides = {"bimdn": bimdn, "none": none}
    print(f"  per run (the training seed as the unit): {seed_level(faced, sides, every)}")
    common, rate_b, rate_n, p = contrast(faced, bimdn, none)
    print(f"  over the {len(common)} evaders every one of them met ({', '.join(sorted(common))}): bimdn "
          f"{rate_b:.3f} vs none {rate_n:.3f}, z-test p = {p:.2g}")
    print(f"  per run over those: {seed_level(faced, sides, common)}")
    if better:
        return None
    return (f"{schedule}: bimdn pursuers capture more than none over every evader (z-test p = {p_every:.2g}, "
            f"stratified p = {p_stratified:.2g})")


def print_cross_play(faced: Faced, runs: list[str]) -> None:
    """Each run's pursuer (rows) against each other run's evader (columns): where cross-play is lost."""
    print("\ncross-play: capture rate of each run's pursuer (row) against each other run's evader (column)\n")
    print(f"| pursuer \\ evader | {' | '.join(runs)} |")
    print(f"| --- |{' ---: |' * len(runs)}")
    for name in runs:
        cells = [f"{faced[name][o][0] / faced[name][o][1]:.2f}" if o in faced[name] else "—" for o in runs]
        print(f"| {name} | {' | '.join(cells)} |")


def checkpoint_players(paths: list[Path], config: str) -> tuple[Scenario, dict[Path, Player], dict[str, list[Player]]]:
    """The scenario ``config``, the tournament player of each checkpoint of ``paths`` and every player found; a
    checkpoint is matched by its content, so copies of one (an A/B's arms share their history) are one player.
    Exits with one line when the scenario or a checkpoint does not load, or a checkpoint plays another game."""
    try:
        scenario = load_scenario(config)
        found = find_players([str(p) for p in paths], scenario).players
    except PecliError as error:  # a scenario the runs did not train on, a damaged checkpoint
        sys.exit(f"{error} (--config {config})")
    by_identity = {p.identity: p for role in found for p in found[role]}
    of = {path: by_identity.get(file_digest(path)) for path in paths}
    unplayable = sorted(str(path) for path, player in of.items() if player is None)
    if unplayable:
        sys.exit(f"{unplayable[0]} does not play scenario '{scenario.name}' (--config {config})")
    return scenario, of, found


def with_scripted(found: dict[str, list[Player]]) -> tuple[dict[str, Player], Player, dict[str, list[Player]]]:
    """The scripted evaders the pursuers meet (by name), pure pursuit (which the evaders meet), and ``found``'s
    players with them added."""
    scripted = {name: Player(name, name, "evader", f"builtin:{name}") for name in (*HEURISTIC_EVADERS, *ADVERSARIES)}
    pure = Player("pure-pursuit", "pure-pursuit", "pursuer", "builtin:pure-pursuit")
    return scripted, pure, {"pursuer": [*found["pursuer"], pure], "evader": [*found["evader"], *scripted.values()]}


def report(args: argparse.Namespace) -> None:
    if args.average_evaders and args.average < 2:
        sys.exit("--average-evaders averages the evaders over --average K rounds: give K of 2 or more")
    runs = final_players(args.zoo, args.cpu_hours, args.round, args.average,
                         ("pursuer", "evader") if args.average_evaders else ("pursuer",))
    scenario, of, found = checkpoint_players([latest[role] for latest in runs.values() for role in ("pursuer", "evader")],
                                             args.config)
    pursuers = {name: of[latest["pursuer"]] for name, latest in runs.items()}
    evaders = {name: of[latest["evader"]] for name, latest in runs.items()}
    scripted, pure, found = with_scripted(found)
    pairings: list[tuple[Player, Player]] = []
    for name, pursuer in pursuers.items():
        pairings += [(pursuer, e) for e in scripted.values()]
        pairings += [(pursuer, evaders[other]) for other in runs if other != name]
    pairings += [(pure, e) for e in evaders.values()]
    results = run_tournament(scenario, found, pairings, episodes=args.episodes, seeds=[0], out=args.zoo / "report",
                             workers=args.workers).grid()

    def rate(p: Player, e: Player) -> tuple[int, int]:
        r = results[(p.name, e.name)]
        return r.captures, r.episodes

    print(f"| run | round | vs {' / '.join(HEURISTIC_EVADERS)} | vs {' / '.join(ADVERSARIES)} | cross-play | "
          f"its evader vs pure pursuit | CPU-h |")
    print("| --- | ---: | --- | --- | ---: | ---: | ---: |")
    missed = []
    faced: Faced = {}
    groups: dict[tuple[str, str], list[str]] = {}  # (schedule, belief) -> its runs
    for name, pursuer in pursuers.items():
        others = [o for o in runs if o != name]
        faced[name] = {e: rate(pursuer, scripted[e]) for e in (*HEURISTIC_EVADERS, *ADVERSARIES)}
        faced[name].update({o: rate(pursuer, evaders[o]) for o in others})
        heuristic = [faced[name][e] for e in HEURISTIC_EVADERS]
        adversary = [faced[name][e] for e in ADVERSARIES]
        cross = [faced[name][o] for o in others]
        held = rate(pure, evaders[name])
        cross_rate = sum(c for c, _ in cross) / max(sum(n for _, n in cross), 1)
        print(f"| {name} | {round_of(runs[name]['at'])} | "
              f"{' / '.join(f'{c / n:.2f}' for c, n in heuristic)} | "
              f"{' / '.join(f'{c / n:.2f}' for c, n in adversary)} | {cross_rate:.2f} | {held[0] / held[1]:.2f} | "
              f"{cpu_hours_to(runs[name]['at']):.2f} |")
        missed += [f"{name} vs {e}: {c / n:.3f} < {TARGETS['heuristics']}" for e, (c, n) in zip(HEURISTIC_EVADERS, heuristic)
                   if c / n < TARGETS["heuristics"]]
        missed += [f"{name} vs {e}: {c / n:.3f} < {TARGETS['adversaries']}" for e, (c, n) in zip(ADVERSARIES, adversary)
                   if c / n < TARGETS["adversaries"]]
        if cross and cross_rate < TARGETS["cross-play"]:
            missed.append(f"{name} cross-play: {cross_rate:.3f} < {TARGETS['cross-play']}")
        if held[0] / held[1] > TARGETS["pure-pursuit held to"]:
            held_to = TARGETS["pure-pursuit held to"]
            missed.append(f"{name}'s evader lets pure pursuit capture {held[0] / held[1]:.3f} > {held_to}")
        training = yaml.safe_load((args.zoo / name / "config.yaml").read_text())["training"]
        selfplay = training.get("selfplay", {})
        schedule = "league" if selfplay.get("opponents") == "league" else selfplay.get("schedule", "alternating")
        groups.setdefault((schedule, training["belief"]), []).append(name)
    print_cross_play(faced, list(runs))
    budget = "at each run's newest round (not an equal budget: give --cpu-hours)"
    if args.cpu_hours is not None:
        budget = f"at {args.cpu_hours} CPU-h"
    elif args.round is not None:
        budget = f"after round {args.round}"
    print(f"\npursuers pooled over every evader (heuristics, adversaries, cross-play) and seed, {budget}:")
    for schedule in sorted({s for s, _ in groups}):
        kinds = {b: (pool(faced, names), len(names)) for (s, b), names in sorted(groups.items()) if s == schedule}
        c, n = (sum(t[i] for t, _ in kinds.values()) for i in (0, 1))
        each = ", ".join(f"{b} {cb / nb:.3f} ({k} run{'s' * (k > 1)})" for b, ((cb, nb), k) in kinds.items())
        print(f"- {schedule}: {c / n:.3f} over {n} episodes; {each}")
    print_schedules(faced, groups, budget)
    for schedule in sorted({s for s, b in groups if b == "bimdn" and (s, "none") in groups}):
        bimdn, none = groups[(schedule, "bimdn")], groups[(schedule, "none")]
        hours = {kind: sum(cpu_hours_to(runs[name]["at"]) for name in names) / len(names)
                 for kind, names in (("bimdn", bimdn), ("none", none))}
        miss = print_beliefs(faced, schedule, bimdn, none, hours)
        if miss:
            missed.append(miss)
    print("\ntargets missed:" if missed else "\nevery target met", *missed, sep="\n- " if missed else "")


def compare(args: argparse.Namespace) -> None:
    """An A/B of zoos of the same runs at an equal budget (see the module's docstring)."""
    arms: dict[str, dict[str, dict[str, Path]]] = {}
    for entry in args.arms:
        label, _, zoo = entry.partition("=")
        if not label or not zoo or label in arms:
            sys.exit(f"--arms {entry}: give each arm as LABEL=ZOO, with labels of their own")
        print(f"{label}: {zoo}", file=sys.stderr)
        arms[label] = final_players(Path(zoo), args.cpu_hours, args.round)
    if len(arms) < 2:
        sys.exit("--arms: an A/B needs two arms or more")
    names = sorted(set.intersection(*(set(runs) for runs in arms.values())))
    if not names:
        sys.exit("the arms have no run in common at that budget (runs pair by name: kind, schedule, seed)")
    first, *others = arms
    bystanders = sorted(set(arms[first]) - set(names))  # the control's runs no other arm has: evaders for all
    scenario, of, found = checkpoint_players(
        [runs[n][role] for runs in arms.values() for n in names for role in ("pursuer", "evader")]
        + [arms[first][o]["evader"] for o in bystanders], args.config)
    player = {(label, n, role): of[runs[n][role]] for label, runs in arms.items() for n in names
              for role in ("pursuer", "evader")}
    player.update({(first, o, "evader"): of[arms[first][o]["evader"]] for o in bystanders})
    scripted, pure, found = with_scripted(found)
    met = {n: [*scripted, *((label, o) for label in arms for o in names if o != n), *((first, o) for o in bystanders)]
           for n in names}

    def evader(key: str | tuple[str, str]) -> Player:
        return scripted[key] if isinstance(key, str) else player[(*key, "evader")]

    pairings = [(player[(label, n, "pursuer")], evader(e)) for label in arms for n in names for e in met[n]]
    pairings += [(pure, player[(label, n, "evader")]) for label in arms for n in names]
    results = run_tournament(scenario, found, pairings, episodes=args.episodes, seeds=[0], out=args.out,
                             workers=args.workers).grid()
    faced = {}
    for label in arms:
        for n in names:
            mine = [results[(player[(label, n, "pursuer")].name, evader(e).name)] for e in met[n]]
            faced[(label, n)] = {e: (r.captures, r.episodes) for e, r in zip(met[n], mine)}
    budget = f"{args.cpu_hours} CPU-h" if args.cpu_hours is not None else f"round {args.round}" if args.round else "the newest round"
    extra = f" and {first}'s {', '.join(bystanders)}" if bystanders else ""
    print(f"{', '.join(arms)} at {budget}, {args.episodes} games per pairing; cross-play: the other runs' evaders "
          f"of every arm{extra}\n")
    print(f"| arm | run | vs {' / '.join(HEURISTIC_EVADERS)} | vs {' / '.join(ADVERSARIES)} | cross-play | "
          f"its evader: vs pure pursuit / vs the other pursuers | CPU-h |")
    print("| --- | --- | --- | --- | ---: | --- | ---: |")

    def share(rates: list[tuple[int, int]]) -> float:
        return sum(c for c, _ in rates) / max(sum(m for _, m in rates), 1)

    for label in arms:
        for n in names:
            mine = faced[(label, n)]
            against = [faced[(other, o)][(label, n)] for other in arms for o in names if o != n]
            held = results[(pure.name, player[(label, n, "evader")].name)]
            print(f"| {label} | {n} | {' / '.join(f'{share([mine[e]]):.2f}' for e in HEURISTIC_EVADERS)} | "
                  f"{' / '.join(f'{share([mine[e]]):.2f}' for e in ADVERSARIES)} | "
                  f"{share([r for e, r in mine.items() if not isinstance(e, str)]):.2f} | "
                  f"{held.captures / held.episodes:.2f} / {f'{share(against):.2f}' if against else '—'} | "
                  f"{cpu_hours_to(arms[label][n]['pursuer']):.2f} |")
    per_run = {label: [share(list(faced[(label, n)].values())) for n in names] for label in arms}
    c0, n0 = (sum(r[i] for n in names for r in faced[(first, n)].values()) for i in (0, 1))
    print(f"\npursuers pooled over every evader they met ({len(names)} runs, {n0} games per arm): {first} {c0 / n0:.3f}")
    for label in others:
        c1, n1 = (sum(r[i] for n in names for r in faced[(label, n)].values()) for i in (0, 1))
        diffs = [b - a for a, b in zip(per_run[first], per_run[label])]
        paired = f"paired t-test p = {ttest_rel(per_run[label], per_run[first]).pvalue:.2g}" if len(names) > 1 else \
            "a paired test needs 2 runs"
        print(f"- {label} {c1 / n1:.3f}: z-test against {first} p = {two_proportion_z_test(c1, n1, c0, n0):.2g}; "
              f"per run {', '.join(f'{d:+.3f}' for d in diffs)} ({paired})")


def movement(recording: Recording) -> dict[str, float]:
    """What the evader of ``recording`` did, averaged over the steps its games lasted: how it was caught,
    seen and saw, how fast it moved (m/step) while it saw the pursuer and while it did not, how far it kept."""
    evader, pursuer = recording.evader[..., :2], recording.pursuer[..., :2]
    alive = np.arange(len(evader))[:, None] < recording.steps[None, :]  # (T1, r): the steps each game ran
    moved = alive[1:]
    speed = np.linalg.norm(np.diff(evader, axis=0), axis=2)
    sees = recording.seen_by_evader[1:]
    wall = np.min(np.asarray(recording.scenario.arena.half) - np.abs(evader), axis=2)
    return {"caught": recording.captured.mean(), "seen": recording.seen_by_pursuer[alive].mean(),
            "sees": recording.seen_by_evader[alive].mean(), "speed unseen": speed[moved & ~sees].mean(),
            "speed seeing": speed[moved & sees].mean(),
            "distance": np.linalg.norm(evader - pursuer, axis=2)[alive].mean(), "wall": wall[alive].mean()}


def behaviour(args: argparse.Namespace) -> None:
    """How each evader plays against one pursuer (is it caught by a failed search or a lost chase?)."""
    try:  # the scenario and every player load before the first game: a wrong name ends in one line
        scenario = load_scenario(args.config)
        pursuer = resolve_policy(args.pursuer, "pursuer", scenario, seed=1)
        evaders = {name: resolve_policy(name, "evader", scenario, seed=2) for name in args.evaders}
    except PecliError as error:
        sys.exit(str(error))
    one_torch_thread()
    print(f"against {args.pursuer} on {scenario.name}, {args.episodes} games each (means over the steps they lasted)\n")
    print("| evader | caught | seen by the pursuer | sees the pursuer | speed unseen / seeing it (m/step) | distance "
          "| to the nearest wall |\n| --- | ---: | ---: | ---: | --- | ---: | ---: |")
    drawn: list[Path] = []
    for name, evader in evaders.items():  # play_match resets both players for each match
        _, recording = play_match(scenario, pursuer, evader, args.episodes, seed=0, record=args.episodes)
        m = movement(recording)
        print(f"| {name} | {m['caught']:.2f} | {m['seen']:.2f} | {m['sees']:.2f} | {m['speed unseen']:.3f} / "
              f"{m['speed seeing']:.3f} | {m['distance']:.1f} m | {m['wall']:.2f} m |", flush=True)
        if args.render is not None:
            path = args.render if len(args.evaders) == 1 else args.render.with_stem(f"{args.render.stem}-{len(drawn)}")
            drawn.append(draw_escapes(recording, path))
    if drawn:
        print("\ndrew the games each evader escaped: " + ", ".join(str(path) for path in drawn))


def draw_escapes(recording: Recording, path: Path) -> Path:
    """Draw up to 4 games of ``recording`` that the evader escaped (the first games if it escaped none)."""
    from pecli.render import draw_episodes

    escaped = np.flatnonzero(~recording.captured)
    games = (escaped if len(escaped) else np.arange(len(recording.captured)))[:4]
    picked = dataclasses.replace(
        recording, pursuer=recording.pursuer[:, games], evader=recording.evader[:, games],
        seen_by_pursuer=recording.seen_by_pursuer[:, games], seen_by_evader=recording.seen_by_evader[:, games],
        steps=recording.steps[games], captured=recording.captured[games],
        beliefs={role: tuple(part[:, games] for part in parts) for role, parts in recording.beliefs.items()})
    return draw_episodes(picked, path)


def exploit(args: argparse.Namespace) -> None:
    """Each run's pursuer-evader pair against best responses trained on each alone (:func:`pecli.exploit.exploit_pair`,
    as ``pecli exploit --pair``): the issue's exploitability targets per run."""
    from pecli.exploit import exploit_pair

    if args.handed_over:
        runs = {run.name: {role: run / role / AVERAGE_FILE for role in ("pursuer", "evader")}
                for run in sorted(p.parent for p in args.zoo.glob(f"*/{STATE_FILE}"))
                if all((run / role / AVERAGE_FILE).is_file() for role in ("pursuer", "evader"))}
    else:
        runs = final_players(args.zoo, args.cpu_hours, args.round)
    runs = {name: players for name, players in runs.items() if not args.runs or name in args.runs}
    if not runs:
        sys.exit(f"no run to measure under {args.zoo}")
    print(f"best responses of {args.cpu_minutes:g} CPU-minutes, {args.seeds} seeds{', fresh and warm-started' if args.warm else ''}"
          f", {args.episodes} held-out games; the strongest counts\n")
    print("| run | pair | best evader holds the pursuer to | best pursuer catches the evader | NashConv [95 %] | "
          "targets (>= 0.75, <= 0.25) |\n| --- | ---: | ---: | ---: | ---: | --- |")
    for name, players in runs.items():
        try:
            with sigterm_stops():
                result = exploit_pair(str(players["pursuer"]), str(players["evader"]), load_scenario(args.config),
                                      args.zoo / "exploit" / name, warm=args.warm, cpu_minutes=args.cpu_minutes,
                                      seeds=tuple(range(args.seeds)), episodes=args.episodes,
                                      report=lambda line: print(line, file=sys.stderr, flush=True))
        except PecliError as error:
            sys.exit(str(error))
        except KeyboardInterrupt:
            sys.exit(f"{name}: stopped; every response keeps its state: run the same command to continue")
        held = [r.capture_rate for r in result.against_pursuer.responses]
        caught = [r.capture_rate for r in result.against_evader.responses]
        low, high = result.interval
        met = [result.against_pursuer.strongest().capture_rate >= 0.75, result.nash_conv <= 0.25]
        print(f"| {name} | {result.capture_rate:.2f} | {min(held):.2f} ({min(held):.2f}-{max(held):.2f}) | "
              f"{max(caught):.2f} ({min(caught):.2f}-{max(caught):.2f}) | {result.nash_conv:.2f} [{low:.2f}, {high:.2f}] | "
              f"{' / '.join('met' if m else 'missed' for m in met)} |", flush=True)


def fork(args: argparse.Namespace) -> None:
    """``pecli zoo fork`` (:func:`pecli.rl.fork.fork_run`), kept here for the A/B recipes written with it."""
    from pecli.rl.fork import fork_run

    try:
        target = fork_run(args.run, args.to, args.add)
    except PecliError as error:
        sys.exit(str(error))
    added = f", with {', '.join(args.add)} in its pools" if args.add else ""
    print(f"{target}: a copy of {args.run} at {run_cpu_hours(target):.2f} CPU-h{added}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = parser.add_subparsers(dest="what", required=True)
    for name in ("train", "report"):
        command = sub.add_parser(name)
        command.add_argument("--zoo", type=Path, default=Path("runs/bench_strength"))
    probe = sub.add_parser("exploit")
    probe.add_argument("--zoo", type=Path, default=Path("runs/bench_strength"))
    probe.add_argument("--cpu-minutes", type=float, default=20.0, help="CPU-minutes of each best response")
    probe.add_argument("--seeds", type=int, default=3, help="best responses per side and start (seeds 0 .. K-1)")
    probe.add_argument("--warm", action="store_true", help="also warm-start each response from the run's own player")
    probe.add_argument("--episodes", type=int, default=500)
    probe.add_argument("--handed-over", action="store_true", help="each run's average.zip players (what it hands over)")
    probe.add_argument("--runs", nargs="+", default=None, help="only these runs (default: every run)")
    probe.add_argument("--config", default="tuned", help="the scenario they play")
    probe_at = probe.add_mutually_exclusive_group()
    probe_at.add_argument("--cpu-hours", type=float, default=None, help="each run's players at this CPU budget")
    probe_at.add_argument("--round", type=int, default=None, help="each run's players after this many rounds")
    ab = sub.add_parser("compare")
    ab.add_argument("--arms", nargs="+", required=True, help="LABEL=ZOO for each arm, the control first")
    ab.add_argument("--out", type=Path, default=Path("runs/compare"), help="where the games are cached")
    ab.add_argument("--episodes", type=int, default=500)
    ab.add_argument("--workers", type=int, default=2)
    ab.add_argument("--config", default="tuned", help="the scenario they play")
    ab_at = ab.add_mutually_exclusive_group()
    ab_at.add_argument("--cpu-hours", type=float, default=None, help="every run at this CPU budget")
    ab_at.add_argument("--round", type=int, default=None, help="every run after this many rounds")
    moves = sub.add_parser("behaviour")
    moves.add_argument("--pursuer", required=True, help="a checkpoint or built-in pursuer")
    moves.add_argument("--evaders", nargs="+", required=True, help="checkpoints or built-in evaders")
    moves.add_argument("--config", default="tuned", help="the scenario they play")
    moves.add_argument("--episodes", type=int, default=200)
    moves.add_argument("--render", type=Path, default=None,
                       help="draw 4 games each evader escaped to this .png (with -N before the suffix for several)")
    sub.choices["train"].add_argument("--config", default=None, help="the scenario (default: the experiment's)")
    sub.choices["report"].add_argument("--config", default="tuned", help="the scenario the players play")
    sub.choices["train"].add_argument("--experiment", default="strength",
                                      help="the experiment whose runs and settings these are: strength, "
                                      "strength-small, schedules or a YAML file of self-play runs; the options "
                                      "below replace its own")
    sub.choices["train"].add_argument("--schedules", nargs="+", default=None,
                                      choices=["alternating", "simultaneous", "league", "nash"])
    sub.choices["train"].add_argument("--beliefs", nargs="+", default=None)
    sub.choices["train"].add_argument("--seeds", nargs="+", type=int, default=None)
    sub.choices["train"].add_argument("--cpu-hours", type=float, default=None)
    sub.choices["train"].add_argument("--steps-per-round", type=int, default=None,
                                      help="transitions per side per round (default: the experiment's)")
    sub.choices["train"].add_argument("--rounds", type=int, default=None,
                                      help="the ceiling of rounds, over which the curriculum is scheduled "
                                      "(default: the experiment's)")
    sub.choices["report"].add_argument("--episodes", type=int, default=500)
    sub.choices["report"].add_argument("--workers", type=int, default=2)
    sub.choices["report"].add_argument("--average", type=int, default=1, metavar="K",
                                       help="each run's pursuer: the mean of its weights over the last K rounds "
                                       "(pecli zoo average) instead of the last round's")
    sub.choices["report"].add_argument("--average-evaders", action="store_true",
                                       help="with --average: the evaders too (both sides averaged, as self-play "
                                       "hands them over once the last K rounds are all after the curriculum)")
    at = sub.choices["report"].add_mutually_exclusive_group()
    at.add_argument("--cpu-hours", type=float, default=None,
                    help="compare every run at this CPU budget (default: each run's newest round)")
    at.add_argument("--round", type=int, default=None,
                    help="compare every run after this many rounds (equal transitions per main learner, not CPU)")
    branch = sub.add_parser("fork")
    branch.add_argument("--run", type=Path, required=True, help="the run folder to copy (stopped)")
    branch.add_argument("--to", type=Path, required=True, help="the zoo the copy goes into")
    branch.add_argument("--add", nargs="+", default=[], help="scripted players that join the copy's pools")
    args = parser.parse_args()
    commands = {"train": train, "report": report, "exploit": exploit, "compare": compare, "behaviour": behaviour,
                "fork": fork}
    commands[args.what](args)


if __name__ == "__main__":
    main()
