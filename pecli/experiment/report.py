"""The experiment's report: the final tournament grouped by belief kind and laid out as the paper's
Table I (or Table II), our numbers beside the paper's, as Markdown, JSON and a PNG heatmap.

A cell pools every pairing of its pursuer group against its evader group (the kept models of every
seed): capture rate, time-to-capture (σ) and the episodes behind it. Bold marks the best pursuer
group against each evader group and those that tie with it (two-proportion z-test, p > 0.05), as
the paper's bold. A cell played over fewer episodes than the paper's 1500 says so.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from pecli.errors import PecliError
from pecli.experiment.compare import Faced, over_every_evader
from pecli.experiment.compare import pool as faced_totals
from pecli.experiment.exploit import POPULATION, recorded_pairs
from pecli.experiment.folder import KEPT_FILE, open_experiment
from pecli.experiment.spec import SELFPLAY_SCHEDULES, LoadedExperiment
from pecli.io import atomic_write_json, atomic_write_text, read_json
from pecli.metagame import solve
from pecli.policies.mix import first_member
from pecli.records import KeptRecord, PairingRow, TournamentRecord, validated
from pecli.reports import PAPER_TABLE_I, PAPER_TABLE_II, heatmap, is_hj_spec
from pecli.roles import ROLES, Role, opponent_of
from pecli.stats import Rating, interquartile_mean, stratified_bootstrap_interval, ties_with_best
from pecli.tournament import RESULTS_FILE, PairingResult, Player, TournamentResults, rate, read_results

PAPER_EPISODES = 1500  # per cell: 3 models x 500 episodes (paper section V-B)

KIND_LABELS = {"none": "MADDPG", "ukf": "UKF", "image": "Image", "bimdn": "Ours", "bimdn-mixed": "Ours-Mixed"}
BASELINE_LABELS = {"pure-pursuit": "Pure Pursuit", "random-walk": "Random Walk", "greedy": "Greedy", "rash": "Rash"}
TABLE_I_ORDER: dict[Role, list[str]] = {
    "pursuer": ["Pure Pursuit", "MADDPG", "UKF", "Image", "Ours", "Ours-Mixed"],
    "evader": ["Random Walk", "Greedy", "Rash", "MADDPG", "UKF", "Image", "Ours", "Ours-Mixed"],
}
OPTIMAL = "optimal control"
BASE_KIND = "MADDPG"  # the paper's claim (section V-B): every belief beats the pursuer without one


@dataclass
class Cell:
    """One pursuer group against one evader group, pooled over their pairings."""

    pursuer: str
    evader: str
    episodes: int
    captures: int
    time_mean: float
    time_std: float
    best_in_row: bool = False
    paper_capture_rate: float | None = None
    paper_time: float | None = None
    paper_time_std: float | None = None

    @property
    def capture_rate(self) -> float:
        return self.captures / self.episodes

    def to_dict(self) -> dict[str, Any]:
        data = asdict(self)
        data["capture_rate"] = round(self.capture_rate, 4)
        data["difference"] = (
            None if self.paper_capture_rate is None else round(self.capture_rate - self.paper_capture_rate, 4)
        )
        data["fewer_episodes_than_paper"] = self.episodes < PAPER_EPISODES
        return data


def pool(pursuer: str, evader: str, results: Iterable[PairingRow]) -> Cell:
    """Pool pairings: episodes and captures add up; the time's mean and σ are those of all episodes together."""
    rows = list(results)
    n = sum(r.episodes for r in rows)
    mean = sum(r.episodes * r.time_to_capture_mean for r in rows) / n
    second = sum(r.episodes * (r.time_to_capture_std**2 + r.time_to_capture_mean**2) for r in rows) / n
    return Cell(pursuer, evader, n, sum(r.captures for r in rows), mean, max(second - mean**2, 0.0) ** 0.5)


class ExperimentReport:
    """The final tournament of the experiment in ``out``, grouped for the paper's table."""

    def __init__(self, out: Path) -> None:
        self.out = out
        self.experiment: LoadedExperiment = open_experiment(out)
        self.table = self.experiment.spec.report.table
        try:
            if not (out / "tournament" / RESULTS_FILE).is_file() or not (out / KEPT_FILE).is_file():
                raise FileNotFoundError
            kept = read_json(out / KEPT_FILE, "record of kept checkpoints")
        except FileNotFoundError:
            raise PecliError(
                f"{out}: the experiment has not reached its tournament yet "
                "(`pecli experiment status` says how far it got)"
            ) from None
        self.record: TournamentRecord = read_results(out / "tournament")
        validated(KeptRecord, kept, out / KEPT_FILE, "record of kept checkpoints")
        runs = {run.name: run for run in self.experiment.runs()}
        one_schedule = len(self.experiment.spec.runs.schedules) == 1  # then a kind's group is the paper's kind
        self.group_of_spec: dict[str, str] = {}
        learned: list[str] = []
        for name, roles in kept.items():
            run = runs.get(name)
            if run is None:
                continue
            plain = one_schedule or run.schedule == "selfplay"
            label = KIND_LABELS[run.kind] if plain else f"{KIND_LABELS[run.kind]} ({run.schedule})"
            learned.append(label)
            for paths in roles.values():
                for path in paths:
                    self.group_of_spec[path] = label
        self.ours_single = self.table == "II" and len(set(learned)) == 1
        self.groups: dict[Role, list[str]] = {role: [] for role in ROLES}
        self.player_group: dict[str, str] = {}
        for rating in self.record.ratings:
            group = self._group(rating.spec, rating.name)
            self.player_group[rating.name] = group
            if group not in self.groups[rating.role]:
                self.groups[rating.role].append(group)
        for role in ROLES:
            order = self._order(role)
            self.groups[role].sort(key=lambda g: (order.index(g) if g in order else len(order), g))
        self.cells = self._cells()

    def _group(self, spec: str, name: str) -> str:
        if spec in self.group_of_spec:
            label = self.group_of_spec[spec]
            return "ours" if self.ours_single else label
        if is_hj_spec(spec):
            return OPTIMAL
        if spec in BASELINE_LABELS:
            return BASELINE_LABELS[spec]
        return name

    def _order(self, role: Role) -> list[str]:
        if self.table == "II":
            return [OPTIMAL, "ours"]
        return TABLE_I_ORDER[role]

    def _cells(self) -> list[Cell]:
        grouped: dict[tuple[str, str], list[PairingRow]] = {}
        for r in self.record.pairings:
            key = (self.player_group[r.pursuer], self.player_group[r.evader])
            grouped.setdefault(key, []).append(r)
        cells = {key: pool(*key, rows) for key, rows in grouped.items()}
        for evader in self.groups["evader"]:
            row = [cells[(p, evader)] for p in self.groups["pursuer"] if (p, evader) in cells]
            for cell, tie in zip(row, ties_with_best([c.captures for c in row], [c.episodes for c in row])):
                cell.best_in_row = bool(tie)
        for (p, e), cell in cells.items():
            if self.table == "I":
                cell.paper_capture_rate = PAPER_TABLE_I.get((p, e))
            elif self.table == "II" and (p, e) in PAPER_TABLE_II:
                cell.paper_time, cell.paper_time_std, cell.paper_capture_rate = PAPER_TABLE_II[(p, e)]
        return [cells[(p, e)] for e in self.groups["evader"] for p in self.groups["pursuer"] if (p, e) in cells]

    # -- outputs ----------------------------------------------------------------------------------
    def grouped_results(self) -> TournamentResults:
        """The cells as a tournament of groups (for the heatmap and the rich table); its ratings are
        :meth:`group_ratings`'."""
        players = {role: [Player(g, g, role, f"group:{g}") for g in self.groups[role]] for role in ROLES}
        pairings = [
            PairingResult(c.pursuer, c.evader, c.episodes, c.captures, c.time_mean, c.time_std) for c in self.cells
        ]
        return TournamentResults(
            scenario=self.experiment.scenario,
            players=players,
            pairings=pairings,
            ratings=[r for _, _, r in self.group_ratings()],
            episodes=self.record.episodes_per_seed,
            seeds=self.record.seeds,
        )

    def group_ratings(self) -> list[tuple[str, Role, Rating]]:
        """Bradley–Terry ratings of the groups from the pooled cells: ``[(group, role, rating)]``, best first
        (a group name such as "MADDPG" plays both roles, so it is rated once per role)."""

        def key(group: str, role: Role) -> str:
            return f"{group} ({role})"

        players = {
            role: [Player(key(g, role), g, role, f"group:{role}:{g}") for g in self.groups[role]] for role in ROLES
        }
        pairings = [
            PairingResult(
                key(c.pursuer, "pursuer"), key(c.evader, "evader"), c.episodes, c.captures, c.time_mean, c.time_std
            )
            for c in self.cells
        ]
        by_key = {p.name: (p.spec, p.role) for role in ROLES for p in players[role]}
        return [(*by_key[r.name], r) for r in rate(players, pairings)]

    def exploitability(self) -> dict[str, float]:
        """Each player's exploitability within the tournament (:mod:`pecli.metagame`): how far the tournament's best
        reply moves its capture rate past the meta-game's value; empty if a pairing was not played."""
        names = {role: [r.name for r in self.record.ratings if r.role == role] for role in ROLES}
        rates = {(r.pursuer, r.evader): r.captures / r.episodes for r in self.record.pairings}
        if not all(names.values()) or any((p, e) not in rates for p in names["pursuer"] for e in names["evader"]):
            return {}
        matrix = np.array([[rates[p, e] for e in names["evader"]] for p in names["pursuer"]])
        return solve(names["pursuer"], names["evader"], matrix).exploitability()

    def kind_intervals(self) -> list[dict[str, Any]]:
        """Each learned group's players over its runs: the interquartile mean of their rates against every group of
        the other side (captures for pursuers, escapes for evaders) with a 95 % stratified-bootstrap interval
        (players resampled within each opposing group), as rliable reports an algorithm over runs and tasks."""
        totals: dict[tuple[str, str], list[int]] = {}  # (player, opposing group) -> [captures, episodes]
        for r in self.record.pairings:
            for player, other in ((r.pursuer, r.evader), (r.evader, r.pursuer)):
                entry = totals.setdefault((player, self.player_group[other]), [0, 0])
                entry[0] += r.captures
                entry[1] += r.episodes
        learned = set(self.group_of_spec.values()) if not self.ours_single else {"ours"}
        rows = []
        for role in ROLES:
            opponents = self.groups[opponent_of(role)]
            for group in (g for g in self.groups[role] if g in learned):
                players = [r.name for r in self.record.ratings if r.role == role and self.player_group[r.name] == group]
                if not players or any((p, o) not in totals for p in players for o in opponents):
                    continue  # a model that did not meet every group: no interval over groups
                rates = np.array([[c / n for c, n in (totals[(p, o)] for o in opponents)] for p in players])
                scores = rates if role == "pursuer" else 1.0 - rates
                low, high = stratified_bootstrap_interval(scores)
                rows.append(
                    {"group": group, "role": role, "players": len(players), "opponent_groups": len(opponents),
                     "iqm": interquartile_mean(scores), "interval": [low, high]}
                )  # fmt: skip
        return rows

    def ordering(self) -> list[dict[str, Any]]:
        """The paper's ordering claim for Table I: each learned pursuer group against MADDPG's (``none``) over every
        evader both met (heuristics and learned evaders, as the table): the pooled capture rates and their z-test,
        and the group's captures above what one rate shared by both groups would give, evader by evader, with the
        Mantel–Haenszel test stratified by evader (the groups need not meet the evaders in equal proportions: the
        stratified test is the one to trust)."""
        if self.table != "I":
            return []
        faced: Faced = {}
        for r in self.record.pairings:
            captures, games = faced.setdefault(r.pursuer, {}).get(r.evader, (0, 0))
            faced[r.pursuer][r.evader] = (captures + r.captures, games + r.episodes)
        members: dict[str, list[str]] = {}  # each learned group's pursuers
        for rating in self.record.ratings:
            if rating.name in faced and rating.spec in self.group_of_spec:
                members.setdefault(self.player_group[rating.name], []).append(rating.name)
        if BASE_KIND not in members:
            return []
        rows = []
        for group in (g for g in self.groups["pursuer"] if g in members and g != BASE_KIND):
            evaders, rate, base_rate, p, excess, p_stratified = over_every_evader(
                faced, members[group], members[BASE_KIND]
            )
            _, games = faced_totals(faced, members[group], evaders)
            rows.append(
                {"group": group, "against": BASE_KIND, "evaders": len(evaders), "games": games,
                 "capture_rate": rate, "against_capture_rate": base_rate, "z_test_p": p,
                 "excess_per_game": excess / games, "stratified_p": p_stratified}
            )  # fmt: skip
        return rows

    def _ordering_lines(self) -> list[str]:
        rows = self.ordering()
        if not rows:
            return []
        lines = [
            "",
            f"## The paper's ordering: each belief against {BASE_KIND}",
            "",
            f"Each learned pursuer group against {BASE_KIND}'s (no belief) over every evader both met: both capture "
            "rates pooled, with the two-proportion z-test; and, evader by evader, the group's captures above what "
            "one rate shared by both groups would give (per game of the group), with the Mantel–Haenszel test "
            "stratified by evader.",
            "",
            f"| pursuers | evaders | games | capture rate | {BASE_KIND}'s | z-test p | above a shared rate | "
            "stratified p |",
            "| --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: |",
        ]
        for r in rows:
            lines.append(
                f"| {r['group']} | {r['evaders']} | {r['games']:,} | {r['capture_rate']:.3f} | "
                f"{r['against_capture_rate']:.3f} | {r['z_test_p']:.2g} | {r['excess_per_game']:+.3f} | "
                f"{r['stratified_p']:.2g} |"
            )
        return lines

    def _ranking_text(self) -> str:
        ranking = self.experiment.spec.ranking
        if ranking.players == "handed-over":
            return "Players: each run's handed-over average.zip (the mean of its last rounds), no ranking."
        return (
            f"Ranking: each checkpoint against {ranking.sample} random checkpoints of the other side, "
            f"{ranking.episodes} × {ranking.seeds} episodes, best {ranking.keep} per run and role kept."
        )

    def markdown(self) -> str:
        spec, grid = self.experiment.spec, self.experiment.spec.runs
        budget = (
            f"{grid.rounds or self.experiment.scenario.training.selfplay.rounds} rounds of "
            f"{grid.steps_per_round or self.experiment.scenario.training.selfplay.steps_per_round:,} "
            "transitions per side"
            if set(grid.schedules) & set(SELFPLAY_SCHEDULES)
            else f"{grid.steps or '-'} transitions"
        )
        if grid.cpu_hours is not None:
            budget += f" at most, or {grid.cpu_hours:g} CPU-hours per self-play run"
        title = {"I": "Table I", "II": "Table II"}.get(self.table, "results")
        lines = [
            f"# {spec.name}: {title}",
            "",
            f"Scenario `{self.experiment.scenario.name}`; runs: {len(grid.kinds)} kinds × {len(grid.seeds)} seeds "
            f"({', '.join(grid.schedules)}), {budget}. {self._ranking_text()} Tournament: "
            f"{self.record.episodes_per_seed} episodes × {len(self.record.seeds)} seeds per pairing.",
            "",
            "## Capture rate: ours / the paper's (difference)",
            "",
            "Bold: the best pursuer against that evader, or tied with it (two-proportion z-test, p > 0.05). "
            f"†: fewer episodes than the paper's {PAPER_EPISODES} (the count is in the next table).",
            "",
        ]
        lines += self._grid(self._rate_text)
        lines += self._kind_lines()
        lines += self._ordering_lines()
        lines += ["", "## Normalised time to capture (σ) and episodes per cell", ""]
        if self.table == "II":
            lines += ["The paper's time (σ) in brackets.", ""]
        lines += self._grid(self._time_text)
        lines += [
            "",
            "## Bradley–Terry ratings (Elo scale; pursuers and evaders on one scale)",
            "",
            "Groups (all their pairings pooled):",
            "",
            "| # | group | role | rating | ± se |",
            "| ---: | --- | --- | ---: | ---: |",
        ]
        for rank, (group, role, r) in enumerate(self.group_ratings(), start=1):
            lines.append(f"| {rank} | {group} | {role} | {r.elo:.0f} | {r.stderr:.0f} |")
        exploitability = self.exploitability()
        lines += [
            "",
            "Models (each kept checkpoint and heuristic; exploitability: within this tournament's meta-game, "
            "how far its best reply here moves the player's capture rate past the game's value, "
            "`pecli exploit` for a best response trained on it):",
            "",
            "| # | player | group | role | rating | ± se | exploitability |",
            "| ---: | --- | --- | --- | ---: | ---: | ---: |",
        ]
        for rank, rating in enumerate(self.record.ratings, start=1):
            value = exploitability.get(rating.name)
            lines.append(
                f"| {rank} | {rating.name} | {self.player_group[rating.name]} | {rating.role} | {rating.elo:.0f} | "
                f"{rating.stderr:.0f} | {'-' if value is None else f'{value:.2f}'} |"
            )
        lines += self._exploit_lines()
        lines += ["", "![capture rate per cell](table.png)", ""]
        return "\n".join(lines)

    def _kind_lines(self) -> list[str]:
        rows = self.kind_intervals()
        if not rows:
            return []
        lines = [
            "",
            "## Each learned group over its models",
            "",
            "Interquartile mean of each model's capture rate (pursuers) or escape rate (evaders) against every group "
            "of the other side, over models × groups, with a 95 % stratified-bootstrap interval (models resampled "
            "within each group, 2 000 resamples).",
            "",
            "| group | role | models | IQM | 95 % interval |",
            "| --- | --- | ---: | ---: | --- |",
        ]
        for row in rows:
            low, high = row["interval"]
            lines.append(
                f"| {row['group']} | {row['role']} | {row['players']} | {row['iqm']:.3f} | [{low:.3f}, {high:.3f}] |"
            )
        return lines

    def best_responses(self) -> list[dict[str, Any]]:
        """Each run whose kept pair has best responses (``pecli experiment exploit``): the pair's own capture
        rate, the strongest responses' and NashConv, each with its 95 % interval."""
        rows = []
        for run, pair in recorded_pairs(self.out).items():
            best_evader, best_pursuer = pair.against_pursuer.strongest(), pair.against_evader.strongest()
            rows.append(
                {
                    "run": run,
                    "group": "every kind"
                    if run.startswith(POPULATION)
                    else self.group_of_spec.get(first_member(pair.pursuer), ""),
                    "pair_capture_rate": pair.capture_rate,
                    "best_evader_holds_pursuer_to": best_evader.capture_rate,
                    "best_evader_interval": list(best_evader.interval),
                    "best_pursuer_catches_evader": best_pursuer.capture_rate,
                    "best_pursuer_interval": list(best_pursuer.interval),
                    "nash_conv": pair.nash_conv,
                    "nash_conv_interval": list(pair.interval),
                    "responses": len(pair.against_pursuer.responses) + len(pair.against_evader.responses),
                    "cpu_minutes": pair.against_pursuer.cpu_minutes,
                    "steps": pair.against_pursuer.steps,
                    "budget": pair.against_pursuer.budget,
                }
            )
        return rows

    def _exploit_lines(self) -> list[str]:
        rows = self.best_responses()
        if not rows:
            return []
        lines = [
            "",
            "## Best responses to each run's players",
            "",
            "Each run's kept pursuer and evader against best responses trained on each alone "
            f"(`pecli experiment exploit`, {' or '.join(sorted({r['budget'] for r in rows}))} each); the "
            "strongest response counts. NashConv = capture(best pursuer, evader) − capture(pursuer, best evader): "
            "0 for an equilibrium. 95 % intervals over the held-out games. A run named `…-mixed` is its group's seeds "
            "played as one uniform mixture (`mix:`; `pecli experiment exploit --mixtures`), `population-SCHEDULE-sN` "
            "seed N's runs of every kind (`--populations`).",
            "",
            "| run | group | the pair | best evader holds the pursuer to | best pursuer catches the evader | "
            "NashConv | responses |",
            "| --- | --- | ---: | --- | --- | --- | ---: |",
        ]
        for r in rows:
            (e_low, e_high), (p_low, p_high) = r["best_evader_interval"], r["best_pursuer_interval"]
            n_low, n_high = r["nash_conv_interval"]
            lines.append(
                f"| {r['run']} | {r['group']} | {r['pair_capture_rate']:.3f} | "
                f"{r['best_evader_holds_pursuer_to']:.3f} [{e_low:.3f}, {e_high:.3f}] | "
                f"{r['best_pursuer_catches_evader']:.3f} [{p_low:.3f}, {p_high:.3f}] | "
                f"{r['nash_conv']:.3f} [{n_low:.3f}, {n_high:.3f}] | {r['responses']} |"
            )
        return lines

    def _grid(self, text: Callable[[Cell], str]) -> list[str]:
        """A Markdown table: evader groups as rows, pursuer groups as columns, ``text(cell)`` in each cell."""
        cells = {(c.pursuer, c.evader): c for c in self.cells}
        pursuers = self.groups["pursuer"]
        lines = ["| evader \\ pursuer | " + " | ".join(pursuers) + " |", "| --- |" + " --- |" * len(pursuers)]
        for evader in self.groups["evader"]:
            row = [text(cells[(p, evader)]) if (p, evader) in cells else "-" for p in pursuers]
            lines.append(f"| {evader} | " + " | ".join(row) + " |")
        return lines

    @staticmethod
    def _rate_text(cell: Cell) -> str:
        """``**0.91**† / 0.98 (−0.07)``: ours (bold: best or tied; †: fewer episodes than the paper's), the
        paper's, the difference."""
        text = f"{cell.capture_rate:.2f}"
        text = f"**{text}**" if cell.best_in_row else text
        text += "†" if cell.episodes < PAPER_EPISODES else ""
        if cell.paper_capture_rate is not None:
            diff = cell.capture_rate - cell.paper_capture_rate
            text += f" / {cell.paper_capture_rate:.2f} ({diff:+.2f})".replace("-", "−")
        return text

    @staticmethod
    def _time_text(cell: Cell) -> str:
        text = f"{cell.time_mean:.2f} (σ={cell.time_std:.2f}), n={cell.episodes}"
        if cell.paper_time is not None:
            text += f" [{cell.paper_time:.2f} (σ={cell.paper_time_std:.2f})]"
        return text

    def to_json(self) -> dict[str, Any]:
        exploitability = self.exploitability()
        return {
            "experiment": self.experiment.spec.name,
            "table": self.table,
            "scenario": self.experiment.scenario.name,
            "paper_episodes_per_cell": PAPER_EPISODES,
            "groups": self.groups,
            "cells": [c.to_dict() for c in self.cells],
            "group_ratings": [{**asdict(r), "name": group, "role": role} for group, role, r in self.group_ratings()],
            "group_intervals": self.kind_intervals(),
            "ordering": self.ordering(),
            "best_responses": self.best_responses(),
            "ratings": [
                {**r.model_dump(), "group": self.player_group[r.name], "exploitability": exploitability.get(r.name)}
                for r in self.record.ratings
            ],
        }


def write_report(out: Path) -> list[Path]:
    """Write ``report.md``, ``report.json`` and ``table.png`` into ``out``; returns their paths."""
    report = ExperimentReport(out)
    atomic_write_text(out / "report.md", report.markdown())
    atomic_write_json(out / "report.json", report.to_json())
    return [out / "report.md", out / "report.json", heatmap(report.grouped_results(), out / "table.png")]
