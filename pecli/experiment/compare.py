"""Self-play runs compared at an equal budget: each run's main players, an A/B of zoos, and the tests between groups.

``pecli experiment compare --arms control=ZOO_A other=ZOO_B`` is an A/B of two or more zoos of the same runs (same
names: same belief kind, schedule and seed), e.g. a control and a copy trained on with other settings from the same
checkpoint (``pecli zoo fork``). Every arm's pursuers play the scripted evaders and the evaders of every *other*
run of every arm (not their own, nor their twins in the other arms, which share their history), so each run meets
the same evaders in every arm; runs the control has and the others lack join every arm's cross-play as bystanders.
With one arm it is the strength table of one zoo. Each arm is pooled against the first (two-proportion z-test over
games) and per run (paired t-test, the run as the unit).

The players are each run's main checkpoints of the round at which a run of ``cpu_hours`` would have stopped (or of
round ``at_round``, or the newest), so runs still training compare at any equal budget.
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable, Hashable, Iterable
from dataclasses import dataclass, field
from pathlib import Path

from scipy.stats import ttest_ind, ttest_rel

from pecli.errors import PecliError
from pecli.io import file_digest, read_json
from pecli.records import SelfPlayRecord, validated
from pecli.rl.budget import cpu_through
from pecli.rl.handover import STATE_FILE
from pecli.roles import ROLES, Role
from pecli.scenario import Scenario
from pecli.stats import mantel_haenszel_test, two_proportion_z_test
from pecli.text import cpu_time
from pecli.tournament import Player, find_players, run_tournament
from pecli.zoo import AVERAGE_FILE

HEURISTIC_EVADERS = ("greedy", "rash", "random-walk")
ADVERSARIES = ("circler", "blindside", "wall-runner", "hider", "corner-sitter")

Faced = dict[Hashable, dict[Hashable, tuple[int, int]]]  # pursuer -> each evader it met -> (captures, games)


@dataclass(frozen=True)
class Targets:
    """What each run of a self-play recipe must reach: its pursuer against the paper's heuristic evaders, against
    each adversarial evader and on average against the other runs' evaders (cross-play), and its evader against
    pure pursuit (the most that pure pursuit may catch)."""

    heuristics: float = 0.90
    adversaries: float = 0.85
    cross_play: float = 0.80
    pure_pursuit_held_to: float = 0.25

    def describe(self) -> str:
        return (
            f"pursuers >= {self.heuristics:.2f} vs the heuristics, >= {self.adversaries:.2f} vs each adversary, "
            f">= {self.cross_play:.2f} in cross-play; evaders hold pure pursuit to <= {self.pure_pursuit_held_to:.2f}"
        )


LEAGUE_TARGETS = Targets()  # the league recipe's (configs/league.yaml)


@dataclass(frozen=True)
class RunPlayers:
    """One run's main players at the budget asked for: its checkpoints, their round and the run's CPU-hours by then."""

    pursuer: Path
    evader: Path
    round: int
    cpu_hours: float

    def of(self, role: Role) -> Path:
        return self.pursuer if role == "pursuer" else self.evader


def _main_turns(state: Path) -> tuple[dict[tuple[int, Role], Path], list[dict]]:
    """Each main turn's checkpoint by (round, role), and every turn as recorded; :class:`PecliError` if damaged."""
    record = validated(SelfPlayRecord, read_json(state, "self-play record"), state, "self-play record")
    main = {(t.round, t.role): state.parent / t.checkpoint for t in record.turns if t.learner == "main"}
    return main, [t.model_dump() for t in record.turns]


def _finished_rounds(main: dict[tuple[int, Role], Path]) -> list[int]:
    """The rounds in which both main learners ended their turns, in order."""
    return sorted(r for r, role in main if role == "pursuer" and (r, "evader") in main)


def handed_over(zoo: Path) -> dict[str, RunPlayers]:
    """What each self-play run under ``zoo`` hands over (its ``pursuer/average.zip`` and ``evader/average.zip``),
    by run name, with the run's newest round and CPU-hours; runs without both are left out."""
    runs = {}
    for state in sorted(zoo.glob(f"*/{STATE_FILE}")):
        run = state.parent
        files = {role: run / role / AVERAGE_FILE for role in ROLES}
        if not all(path.is_file() for path in files.values()):
            continue
        main, turns = _main_turns(state)
        done = _finished_rounds(main)
        runs[run.name] = RunPlayers(
            files["pursuer"], files["evader"], max(done, default=0), cpu_through(turns, math.inf) / 3600
        )
    return runs


def main_players(
    zoo: Path,
    cpu_hours: float | None = None,
    at_round: int | None = None,
    average: int = 1,
    averaged: Iterable[Role] = ("pursuer",),
    pattern: re.Pattern[str] | None = None,
    report: Callable[[str], None] = lambda line: None,
) -> dict[str, RunPlayers]:
    """Each self-play run's main players: of its newest round, of round ``at_round``, or with ``cpu_hours`` of the
    first round by whose end the run had spent that much CPU (where a run of that budget stops). A run not there yet
    is left out, and ``report`` says so. With ``average`` k > 1 the players of the roles ``averaged`` are the means
    of the main learner's weights over the k rounds ending there (written once to ``<zoo>/report/average``).
    ``pattern``: only runs whose names match it. :class:`PecliError` if no run qualifies."""
    from pecli.rl.averaging import average_checkpoints

    runs = {}
    for state in sorted(zoo.glob(f"*/{STATE_FILE}")):
        name = state.parent.name
        if pattern is not None and not pattern.fullmatch(name):
            continue
        main, turns = _main_turns(state)
        done = _finished_rounds(main)
        spent = [cpu_through(turns, r) / 3600 for r in done]
        chosen = done[-1:]
        if cpu_hours is not None:
            chosen = [r for r, hours in zip(done, spent) if hours >= cpu_hours][:1]
        elif at_round is not None:
            chosen = [r for r in done if r == at_round]
        if not chosen:
            where = (
                cpu_time(3600 * max(spent, default=0.0), 3600 * cpu_hours)
                if cpu_hours is not None
                else f"round {max(done, default=0)} of {at_round}"
                if at_round is not None
                else "no round"
            )
            report(f"{name}: left out, {where} so far")
            continue
        last = chosen[0]
        players = {role: main[(last, role)] for role in ROLES}
        rounds = [r for r in done if r <= last][-average:]
        if average > 1 and len(rounds) < average:
            report(f"{name}: left out, {len(rounds)} rounds to average, not {average}")
            continue
        for role in averaged if average > 1 else ():
            out = zoo / "report" / "average" / f"{name}-{role}-{rounds[0]:03d}-{rounds[-1]:03d}.zip"
            if not out.is_file():
                try:
                    average_checkpoints([main[(r, role)] for r in rounds], out)
                except PecliError as error:  # checkpoints of another network (a run resumed with other settings)
                    raise PecliError(f"{name}: cannot average its {role}s: {error}") from None
            players[role] = out
        runs[name] = RunPlayers(players["pursuer"], players["evader"], last, spent[done.index(last)])
    if not runs:
        raise PecliError(f"no self-play run under {zoo} has the rounds asked for: train longer, or ask for fewer")
    return runs


# --- tests between groups of runs ---------------------------------------------------------------------------------


def pool(faced: Faced, runs: Iterable[Hashable], evaders: set | None = None) -> tuple[int, int]:
    """Captures and games of the pursuers of ``runs`` summed over the evaders they met (or ``evaders``)."""
    rates = [r for name in runs for e, r in faced[name].items() if evaders is None or e in evaders]
    return sum(c for c, _ in rates), sum(n for _, n in rates)


def run_rates(faced: Faced, runs: Iterable[Hashable], evaders: set | None = None) -> list[float]:
    """Each run's capture rate over ``evaders`` (or every evader it met)."""
    return [c / n for c, n in (pool(faced, [name], evaders) for name in runs)]


def welch_p(first: list[float], second: list[float]) -> float | None:
    """Welch's t-test of two groups of runs' rates, the training seed as the unit; None under 2 runs a side.

    The z-test pools games as if each were independent; runs spread more than that from one seed to another, so
    this test is the stricter one."""
    if min(len(first), len(second)) < 2:
        return None
    return float(ttest_ind(first, second, equal_var=False).pvalue)


def pooled_z_test(faced: Faced, first: list, second: list, evaders: set) -> tuple[float, float, float]:
    """The capture rates of the pursuers of ``first`` and ``second`` pooled over ``evaders``, and the z-test's p."""
    (ca, na), (cb, nb) = pool(faced, first, evaders), pool(faced, second, evaders)
    return ca / na, cb / nb, two_proportion_z_test(ca, na, cb, nb)


def contrast(faced: Faced, first: list, second: list) -> tuple[set, float, float, float]:
    """The evaders every pursuer of ``first`` and ``second`` met, each side's capture rate over them and the
    two-proportion z-test's p of one against the other."""
    common = set.intersection(*(set(faced[name]) for name in (*first, *second)))
    if not common:
        raise ValueError("no evader was met by every pursuer of both sides")
    return common, *pooled_z_test(faced, first, second, common)


def over_every_evader(faced: Faced, first: list, second: list) -> tuple[set, float, float, float, float, float]:
    """The pursuers of ``first`` against those of ``second`` over every evader a pursuer of each side met, cross-play
    included (learned evaders count, as in the paper's Table I): those evaders, each side's pooled rate, the
    z-test's p, and ``first``'s captures above equal rates per evader with the Mantel–Haenszel test's p. The sides
    meet the learned evaders in different proportions (a run never meets its own), so the stratified test is the
    one to trust."""
    common = set().union(*(faced[n] for n in first)) & set().union(*(faced[n] for n in second))
    if not common:
        raise ValueError("no evader was met by a pursuer of each side")
    excess, p_stratified = mantel_haenszel_test(
        [(*pool(faced, first, {e}), *pool(faced, second, {e})) for e in sorted(common, key=str)]
    )
    return common, *pooled_z_test(faced, first, second, common), excess, p_stratified


def recipe(scenario: Scenario) -> tuple[str, str]:
    """A self-play run's group for comparisons: ``(schedule, belief)``, where the ``league`` and ``nash`` opponent
    rules count as schedules of their own (they change what the learners meet, not when they learn)."""
    selfplay = scenario.training.selfplay
    schedule = selfplay.opponents if selfplay.opponents in ("league", "nash") else selfplay.schedule
    return schedule, scenario.training.belief


# --- playing the arms -----------------------------------------------------------------------------------------------


@dataclass
class ArmRow:
    """One run of one arm: its pursuer's rates against each scripted evader and in cross-play, its evader's."""

    arm: str
    run: str
    round: int
    cpu_hours: float
    scripted: dict[str, float]
    cross_play: float | None
    held_by_pure_pursuit: float
    evader_vs_others: float | None


@dataclass
class Comparison:
    """What :func:`compare_arms` measured: rows, every pursuer's games (``faced``), and each arm against the first."""

    arms: list[str]
    runs: list[str]
    bystanders: list[str]
    episodes: int
    rows: list[ArmRow] = field(default_factory=list)
    faced: Faced = field(default_factory=dict)  # (arm, run) -> evader -> (captures, games)
    pooled: dict[str, tuple[int, int]] = field(default_factory=dict)
    z_p: dict[str, float] = field(default_factory=dict)  # each other arm against the first, over games
    paired_p: dict[str, float | None] = field(default_factory=dict)  # the same per run (None under 2 runs)
    differences: dict[str, list[float]] = field(default_factory=dict)  # per run, that arm minus the first

    def missed(self, targets: Targets = LEAGUE_TARGETS) -> list[str]:
        """Each target a run missed, one line each (none: every run met every target)."""
        missed = []
        for row in self.rows:
            name = f"{row.arm}/{row.run}" if len(self.arms) > 1 else row.run
            missed += [
                f"{name} vs {e}: {row.scripted[e]:.3f} < {bound}"
                for evaders, bound in ((HEURISTIC_EVADERS, targets.heuristics), (ADVERSARIES, targets.adversaries))
                for e in evaders
                if row.scripted[e] < bound
            ]
            if row.cross_play is not None and row.cross_play < targets.cross_play:
                missed.append(f"{name} cross-play: {row.cross_play:.3f} < {targets.cross_play}")
            if row.held_by_pure_pursuit > targets.pure_pursuit_held_to:
                missed.append(
                    f"{name}'s evader lets pure pursuit catch {row.held_by_pure_pursuit:.3f} > "
                    f"{targets.pure_pursuit_held_to}"
                )
        return missed

    def lines(self) -> list[str]:
        """The comparison as Markdown."""
        first, *others = self.arms
        extra = f" and {first}'s {', '.join(self.bystanders)}" if self.bystanders else ""
        lines = [
            f"{', '.join(self.arms)}: {self.episodes} games per pairing; cross-play: the other runs' evaders of "
            f"every arm{extra}",
            "",
            f"| arm | run | round | vs {' / '.join(HEURISTIC_EVADERS)} | vs {' / '.join(ADVERSARIES)} | "
            "cross-play | its evader: vs pure pursuit / vs the other pursuers | CPU-h |",
            "| --- | --- | ---: | --- | --- | ---: | --- | ---: |",
        ]
        for row in self.rows:
            cross = "—" if row.cross_play is None else f"{row.cross_play:.2f}"
            others_rate = "—" if row.evader_vs_others is None else f"{row.evader_vs_others:.2f}"
            lines.append(
                f"| {row.arm} | {row.run} | {row.round} | "
                f"{' / '.join(f'{row.scripted[e]:.2f}' for e in HEURISTIC_EVADERS)} | "
                f"{' / '.join(f'{row.scripted[e]:.2f}' for e in ADVERSARIES)} | {cross} | "
                f"{row.held_by_pure_pursuit:.2f} / {others_rate} | {row.cpu_hours:.2f} |"
            )
        if not others:
            return lines
        c0, n0 = self.pooled[first]
        lines += [
            "",
            f"pursuers pooled over every evader they met ({len(self.runs)} runs, {n0} games per arm): "
            f"{first} {c0 / n0:.3f}",
        ]
        for label in others:
            c1, n1 = self.pooled[label]
            paired = (
                "a paired test needs 2 runs"
                if self.paired_p[label] is None
                else f"paired t-test p = {self.paired_p[label]:.2g}"
            )
            lines.append(
                f"- {label} {c1 / n1:.3f}: z-test against {first} p = {self.z_p[label]:.2g}; per run "
                f"{', '.join(f'{d:+.3f}' for d in self.differences[label])} ({paired})"
            )
        return lines


def _players(paths: list[Path], scenario: Scenario) -> tuple[dict[Path, Player], dict[str, list[Player]]]:
    """The tournament player of each checkpoint, matched by content (copies of one are one player), and all found."""
    found = find_players([str(p) for p in paths], scenario).players
    by_identity = {p.identity: p for role in found for p in found[role]}
    of = {path: by_identity.get(file_digest(path)) for path in paths}
    unplayable = sorted(str(path) for path, player in of.items() if player is None)
    if unplayable:
        raise PecliError(f"{unplayable[0]} does not play scenario '{scenario.name}'")
    return of, found  # type: ignore[return-value]


def compare_arms(
    arms: dict[str, dict[str, RunPlayers]], scenario: Scenario, out: Path, episodes: int = 500, workers: int = 2
) -> Comparison:
    """Play every arm's runs (picked by :func:`main_players`) as the module says; the games are cached in ``out``."""
    if not arms:
        raise PecliError("compare needs one arm or more")
    names = sorted(set.intersection(*(set(runs) for runs in arms.values())))
    if not names:
        raise PecliError("the arms have no run in common at that budget (runs pair by name: kind, schedule, seed)")
    first = next(iter(arms))
    bystanders = sorted(set(arms[first]) - set(names))  # the control's runs no other arm has: evaders for all
    paths = [runs[n].of(role) for runs in arms.values() for n in names for role in ROLES]
    of, found = _players(paths + [arms[first][o].evader for o in bystanders], scenario)
    player = {(label, n, role): of[runs[n].of(role)] for label, runs in arms.items() for n in names for role in ROLES}
    player.update({(first, o, "evader"): of[arms[first][o].evader] for o in bystanders})
    scripted = {name: Player(name, name, "evader", f"builtin:{name}") for name in (*HEURISTIC_EVADERS, *ADVERSARIES)}
    pure = Player("pure-pursuit", "pure-pursuit", "pursuer", "builtin:pure-pursuit")
    players: dict[Role, list[Player]] = {
        "pursuer": [*found["pursuer"], pure],
        "evader": [*found["evader"], *scripted.values()],
    }
    met: dict[str, list[str | tuple[str, str]]] = {
        n: [*scripted, *((label, o) for label in arms for o in names if o != n), *((first, o) for o in bystanders)]
        for n in names
    }

    def evader(key: str | tuple[str, str]) -> Player:
        return scripted[key] if isinstance(key, str) else player[(*key, "evader")]

    pairings = [(player[(label, n, "pursuer")], evader(e)) for label in arms for n in names for e in met[n]]
    pairings += [(pure, player[(label, n, "evader")]) for label in arms for n in names]
    results = run_tournament(scenario, players, pairings, episodes=episodes, seeds=[0], out=out, workers=workers).grid()
    result = Comparison(list(arms), names, bystanders, episodes)
    for label in arms:
        for n in names:
            games = [results[(player[(label, n, "pursuer")].name, evader(e).name)] for e in met[n]]
            result.faced[(label, n)] = {e: (r.captures, r.episodes) for e, r in zip(met[n], games)}

    def share(rates: list[tuple[int, int]]) -> float | None:
        games = sum(m for _, m in rates)
        return sum(c for c, _ in rates) / games if games else None

    for label, runs in arms.items():
        for n in names:
            mine = result.faced[(label, n)]
            against = [result.faced[(other, o)][(label, n)] for other in arms for o in names if o != n]
            held = results[(pure.name, player[(label, n, "evader")].name)]
            result.rows.append(
                ArmRow(
                    label,
                    n,
                    runs[n].round,
                    runs[n].cpu_hours,
                    {e: mine[e][0] / mine[e][1] for e in scripted},
                    share([r for e, r in mine.items() if not isinstance(e, str)]),
                    held.captures / held.episodes,
                    share(against),
                )
            )
        result.pooled[label] = pool(result.faced, [(label, n) for n in names])
    c0, n0 = result.pooled[first]
    per_run = {label: run_rates(result.faced, [(label, n) for n in names]) for label in arms}
    for label in list(arms)[1:]:
        c1, n1 = result.pooled[label]
        result.z_p[label] = two_proportion_z_test(c1, n1, c0, n0)
        result.paired_p[label] = float(ttest_rel(per_run[label], per_run[first]).pvalue) if len(names) > 1 else None
        result.differences[label] = [b - a for a, b in zip(per_run[first], per_run[label])]
    return result
