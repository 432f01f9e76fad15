"""Tournament reports: the paper's Table I and Table II layouts, ratings, CSV/JSON files and a capture-rate heatmap."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
from rich.console import Console, RenderableType
from rich.measure import Measurement
from rich.table import Table
from rich.text import Text

from pecli.io import atomic_path, atomic_write_json
from pecli.metagame import WEIGHT_FLOOR, MetaGame
from pecli.policies.nash import NASH_FILE, mixture_record
from pecli.records import TournamentRecord
from pecli.tournament import RESULTS_FILE, TournamentResults

TABLE_WIDTH = 120
"""Columns a printed table may take at most (as ``pecli.cli.common.TABLE_WIDTH``): a grid wider than that is printed
numbered (:func:`results_tables`)."""


def results_table(results: TournamentResults) -> Table:
    """Evaders as rows, pursuers as columns, cells 'time (σ=std) / rate' as in the paper's Table I.

    Bold marks the best pursuer against each evader and those that tie with it (z-test, p > 0.05).
    """
    grid, best = results.grid(), results.best_in_row()
    pursuers = [p.name for p in results.players["pursuer"]]
    evaders = [e.name for e in results.players["evader"]]
    table = Table(
        title=f"{results.scenario.name}: capture time (σ) / capture rate, "
        f"{results.episodes} episodes × {len(results.seeds)} seeds per pairing",
        caption="bold: the best pursuer against that evader, or tied with it (two-proportion z-test, p > 0.05)",
    )
    table.add_column("evader \\ pursuer", style="bold")
    for name in pursuers:
        table.add_column(name, justify="center", overflow="fold")
    for evader in evaders:
        cells = []
        for pursuer in pursuers:
            r = grid.get((pursuer, evader))
            if r is None:
                cells.append("[dim]-[/]")
                continue
            text = f"{r.time_to_capture_mean:.2f} (σ={r.time_to_capture_std:.2f}) / {r.capture_rate:.2f}"
            cells.append(f"[bold]{text}[/]" if (pursuer, evader) in best else text)
        table.add_row(evader, *cells)
    return table


def _natural_width(renderable: RenderableType) -> int:
    """Columns ``renderable`` takes when nothing limits it."""
    console = Console(width=10_000)
    return Measurement.get(console, console.options, renderable).maximum


def results_tables(results: TournamentResults, width: int = TABLE_WIDTH) -> list[RenderableType]:
    """The paper's Table I layout (:func:`results_table`) when it fits ``width`` columns; else a numbered list of
    the players and the capture rates in a grid with numbered columns (:func:`numbered_grids`), split in parts
    that fit."""
    table = results_table(results)
    if _natural_width(table) <= width:
        return [table]
    return [players_legend(results), *numbered_grids(results, width)]


def players_legend(results: TournamentResults) -> Table:
    """The players with the numbers a numbered grid heads its columns (P1, P2, ...) and rows (E1, ...) with."""
    table = Table(title=f"{results.scenario.name}: players")
    for column in ("", "pursuer", " ", "evader"):
        table.add_column(column, justify="right" if column.strip() == "" else "left", overflow="fold")
    pursuers, evaders = results.players["pursuer"], results.players["evader"]
    for i in range(max(len(pursuers), len(evaders))):
        row = []
        for mark, players in (("P", pursuers), ("E", evaders)):
            row += [f"{mark}{i + 1}", Text(players[i].name)] if i < len(players) else ["", ""]
        table.add_row(*row)
    return table


def numbered_grids(results: TournamentResults, width: int = TABLE_WIDTH) -> list[Table]:
    """Capture rates with evaders as rows (E1, E2, ...) and pursuers as columns (P1, P2, ...), as many columns a
    part as fit ``width``; bold as in :func:`results_table`."""
    grid, best = results.grid(), results.best_in_row()
    pursuers = [p.name for p in results.players["pursuer"]]
    evaders = [e.name for e in results.players["evader"]]

    def part(first: int, last: int) -> Table:
        shown = "" if (first, last) == (0, len(pursuers)) else f" (pursuers P{first + 1}-P{last})"
        title = (
            f"{results.scenario.name}: capture rate{shown}, {results.episodes} episodes × {len(results.seeds)} seeds"
        )
        table = Table(
            title=title,
            min_width=min(width, len(title)),  # the title on one line, not wrapped to a few narrow columns
            caption="bold: the best pursuer against that evader, or tied with it (two-proportion z-test, "
            "p > 0.05); time-to-capture per pairing in results.csv",
            box=None,
            collapse_padding=True,
            header_style="bold underline",
        )
        table.add_column("", style="bold", justify="right")
        for j in range(first, last):
            table.add_column(f"P{j + 1}", justify="right", no_wrap=True)
        for i, evader in enumerate(evaders):
            cells = []
            for pursuer in pursuers[first:last]:
                r = grid.get((pursuer, evader))
                text = "-" if r is None else f"{r.capture_rate:.2f}"
                cells.append(Text(text, style="bold" if (pursuer, evader) in best else "dim" if r is None else ""))
            table.add_row(f"E{i + 1}", *cells)
        return table

    parts, first = [], 0
    while first < len(pursuers):
        last = first + 1  # one column always, however narrow ``width``
        while last < len(pursuers) and _natural_width(part(first, last + 1)) <= width:
            last += 1
        parts.append(part(first, last))
        first = last
    return parts


def ratings_table(results: TournamentResults, limit: int | None = None) -> Table:
    """Players ranked by Bradley–Terry rating (Elo scale) with the mean capture rate of their pairings."""
    table = Table(title="ratings (Bradley–Terry, Elo scale; pursuers and evaders on one scale)")
    for column, justify in (
        ("#", "right"),
        ("player", "left"),
        ("role", "left"),
        ("rating", "right"),
        ("± se", "right"),
        ("capture rate", "right"),
        ("episodes", "right"),
    ):
        table.add_column(column, justify=justify, overflow="fold")
    roles = {p.name: role for role, players in results.players.items() for p in players}
    for rank, rating in enumerate(results.ratings[:limit], start=1):
        own = [r for r in results.pairings if rating.name in (r.pursuer, r.evader)]
        captures = sum(r.captures for r in own) / max(1, sum(r.episodes for r in own))
        table.add_row(
            str(rank),
            rating.name,
            roles[rating.name],
            f"{rating.elo:.0f}",
            f"{rating.stderr:.0f}",
            f"{captures:.3f}",
            str(rating.games),
        )
    return table


def write_reports(results: TournamentResults, out: Path) -> list[Path]:
    """Write ``results.json``, ``results.csv`` and ``capture_rates.png`` into ``out``; returns their paths."""
    out.mkdir(parents=True, exist_ok=True)
    data = results.to_json()
    atomic_write_json(out / RESULTS_FILE, data)
    with atomic_path(out / "results.csv") as tmp, tmp.open("w", newline="") as handle:
        writer = csv.writer(handle)
        writer.writerow(
            [
                "pursuer",
                "evader",
                "episodes",
                "captures",
                "capture_rate",
                "time_to_capture_mean",
                "time_to_capture_std",
                "best_in_row",
            ]
        )
        for row in data["pairings"]:
            writer.writerow(
                [
                    row["pursuer"],
                    row["evader"],
                    row["episodes"],
                    row["captures"],
                    f"{row['capture_rate']:.4f}",
                    f"{row['time_to_capture_mean']:.4f}",
                    f"{row['time_to_capture_std']:.4f}",
                    row["best_in_row"],
                ]
            )
    return [out / RESULTS_FILE, out / "results.csv", heatmap(results, out / "capture_rates.png")]


def nash_record(results: TournamentResults, game: MetaGame) -> dict:
    """What ``nash.json`` holds for a tournament's meta-game (:func:`pecli.policies.nash.mixture_record`)."""
    specs = {p.name: p.spec for players in results.players.values() for p in players}
    return mixture_record(results.scenario, game, specs)


def write_nash(results: TournamentResults, game: MetaGame, out: Path) -> Path:
    """Write ``out/nash.json``: the zoo's Nash mixture, a player as ``nash:OUT``."""
    path = out / NASH_FILE
    atomic_write_json(path, nash_record(results, game))
    return path


def nash_table(game: MetaGame, limit: int | None = None) -> Table:
    """The equilibrium mixture of each side and every player's exploitability within the zoo, the least first."""
    title = f"the zoo's Nash equilibrium: value {game.value:.3f} (the capture rate each side's mixture guarantees)"
    if game.slack is not None:
        title = (
            f"the zoo's meta-game: value {game.value:.3f}; weights: the most spread mixtures that keep within "
            f"{game.slack:g} of it"
        )
    table = Table(
        title=title,
        caption=f"the pursuer mixture is held to {game.pursuer_held_to:.3f} by the zoo's strongest evader against "
        f"it, the evader mixture caught {game.evader_caught_at_most:.3f} by its strongest pursuer; "
        "exploitability: how far the zoo's best reply to the player moves its capture rate past "
        "the value (0: the player is an equilibrium strategy)",
    )
    for column, justify in (
        ("player", "left"),
        ("role", "left"),
        ("weight", "right"),
        ("exploitability", "right"),
        ("worst reply in the zoo", "left"),
    ):
        table.add_column(column, justify=justify, overflow="fold")
    exploitability = game.exploitability()
    rows = []
    for i, name in enumerate(game.pursuers):
        worst = game.evaders[int(np.argmin(game.matrix[i]))]
        rows.append((exploitability[name], name, "pursuer", float(game.pursuer_mixture[i]), worst))
    for j, name in enumerate(game.evaders):
        worst = game.pursuers[int(np.argmax(game.matrix[:, j]))]
        rows.append((exploitability[name], name, "evader", float(game.evader_mixture[j]), worst))
    rows.sort(key=lambda row: (row[0], -row[3]))
    for value, name, role, weight, worst in rows[:limit]:
        table.add_row(Text(name), role, f"{weight:.3f}" if weight > WEIGHT_FLOOR else "-", f"{value:.3f}", Text(worst))
    return table


def heatmap(results: TournamentResults, path: Path) -> Path:
    """Capture rates as a heatmap: evaders as rows, pursuers as columns (blank: not played)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    grid = results.grid()
    pursuers = [p.name for p in results.players["pursuer"]]
    evaders = [e.name for e in results.players["evader"]]
    rates = np.full((len(evaders), len(pursuers)), np.nan)
    for i, evader in enumerate(evaders):
        for j, pursuer in enumerate(pursuers):
            if (pursuer, evader) in grid:
                rates[i, j] = grid[(pursuer, evader)].capture_rate
    width = min(max(4.0, 2 + 0.6 * len(pursuers)), 30)  # room for the labels of a grid of one or two players
    height = min(max(3.0, 1.5 + 0.4 * len(evaders)), 30)
    fig, ax = plt.subplots(figsize=(width, height))
    image = ax.imshow(rates, vmin=0.0, vmax=1.0, cmap="viridis", aspect="auto")
    ax.set_xticks(range(len(pursuers)), pursuers, rotation=60, ha="right", fontsize=7)
    ax.set_yticks(range(len(evaders)), evaders, fontsize=7)
    ax.set_xlabel("pursuer")
    ax.set_ylabel("evader")
    if len(pursuers) * len(evaders) <= 400:
        for (i, j), value in np.ndenumerate(rates):
            if not np.isnan(value):
                ax.text(
                    j,
                    i,
                    f"{value:.2f}",
                    ha="center",
                    va="center",
                    fontsize=6,
                    color="black" if value > 0.6 else "white",
                )
    fig.colorbar(image, ax=ax, label="capture rate")
    ax.set_title(f"{results.scenario.name}: capture rate", fontsize=9)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=110, format="png", bbox_inches="tight")  # the figure grows to fit long names
    plt.close(fig)
    return path


# ---------------------------------------------------------------------- Table I
PAPER_TABLE_I: dict[tuple[str, str], float] = {
    # (pursuer, evader): capture rate, paper Table I (§V-B)
    (pursuer, evader): rate
    for evader, rates in {
        "Random Walk": (0.67, 0.92, 0.98, 0.94, 0.98, 0.98),
        "Greedy": (0.34, 0.83, 0.94, 0.93, 0.98, 0.99),
        "Rash": (0.39, 0.82, 0.83, 0.82, 0.94, 0.99),
        "MADDPG": (0.27, 0.69, 0.79, 0.84, 0.96, 0.98),
        "UKF": (0.09, 0.84, 0.70, 0.75, 0.89, 0.97),
        "Image": (0.09, 0.68, 0.82, 0.75, 0.95, 0.97),
        "Ours": (0.15, 0.83, 0.70, 0.73, 0.89, 0.99),
        "Ours-Mixed": (0.17, 0.69, 0.86, 0.74, 0.99, 0.99),
    }.items()
    for pursuer, rate in zip(("Pure Pursuit", "MADDPG", "UKF", "Image", "Ours", "Ours-Mixed"), rates)
}

# ---------------------------------------------------------------------- Table II
PAPER_TABLE_II: dict[tuple[str, str], tuple[float, float, float]] = {
    # (pursuer, evader): (time-to-capture, its σ, capture rate), paper Table II
    ("optimal control", "optimal control"): (0.62, 0.40, 0.47),
    ("ours", "optimal control"): (0.46, 0.32, 0.83),
    ("optimal control", "ours"): (0.62, 0.40, 0.50),
    ("ours", "ours"): (0.47, 0.32, 0.80),
}


def is_hj_spec(spec: str) -> bool:
    """Whether a player's policy string is a Hamilton–Jacobi player (``hj``, ``hj:...`` or a ``.npz`` solution)."""
    return spec == "hj" or spec.startswith("hj:") or spec.endswith(".npz")


def table_two(record: TournamentRecord) -> Table:
    """A tournament's results (:func:`pecli.tournament.read_results`) in the paper's Table II layout: evaders as
    rows; per pursuer the normalised time-to-capture (σ), then per pursuer the capture rate. HJ players come first
    and are called "optimal control"."""
    players = {(r.role, r.name): r for r in record.ratings}  # a name may stand for a pursuer and an evader
    pairings = {(p.pursuer, p.evader): p for p in record.pairings}

    def ordered(role: str) -> list[str]:
        names = [name for (side, name) in players if side == role]
        return sorted(names, key=lambda name: (not is_hj_spec(players[(role, name)].spec), name))

    pursuers, evaders = ordered("pursuer"), ordered("evader")
    hj_count = {
        role: sum(is_hj_spec(players[(role, n)].spec) for n in names)
        for role, names in (("pursuer", pursuers), ("evader", evaders))
    }

    def label(role: str, name: str) -> str:
        if not is_hj_spec(players[(role, name)].spec):
            return name
        return "optimal control" if hj_count[role] == 1 else f"optimal control ({name})"

    table = Table(
        title=f"{record.scenario}: time-to-capture (σ) and capture rate, Table II layout "
        f"({record.episodes_per_seed} episodes × {len(record.seeds)} seeds per pairing)"
    )
    table.add_column("evader \\ pursuer", style="bold")
    for name in pursuers:
        table.add_column(f"time: {label('pursuer', name)}", justify="center", overflow="fold")
    for name in pursuers:
        table.add_column(f"rate: {label('pursuer', name)}", justify="center", overflow="fold")
    for evader in evaders:
        cells = [pairings.get((pursuer, evader)) for pursuer in pursuers]
        times = [f"{c.time_to_capture_mean:.2f} (σ={c.time_to_capture_std:.2f})" if c else "-" for c in cells]
        rates = [f"{c.captures / c.episodes:.2f}" if c else "-" for c in cells]
        table.add_row(label("evader", evader), *times, *rates)
    return table


def paper_table_two() -> Table:
    """The paper's Table II (point mass vs point mass), for comparison."""
    table = Table(title="the paper's Table II (OptimizedDP optimal control vs the paper's BiMDN players)")
    sides = ("optimal control", "ours")
    table.add_column("evader \\ pursuer", style="bold")
    for name in sides:
        table.add_column(f"time: {name}", justify="center")
    for name in sides:
        table.add_column(f"rate: {name}", justify="center")
    for evader in sides:
        values = [PAPER_TABLE_II[(pursuer, evader)] for pursuer in sides]
        table.add_row(evader, *[f"{t:.2f} (σ={s:.2f})" for t, s, _ in values], *[f"{r:.2f}" for _, _, r in values])
    return table
