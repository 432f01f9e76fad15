"""``pecli psro``: PSRO from a pair or from populations, trained best responses as the oracle, NashConv per
iteration."""

from __future__ import annotations

import json
from enum import Enum
from pathlib import Path
from typing import Annotated

import typer
from rich.table import Table

from pecli.cli.common import (
    PlayersConfigOption,
    console,
    err_console,
    maxent_slack,
    require_batch,
    require_positive,
    scenario_for,
    user_errors,
)
from pecli.cli.exploit import responses_stop
from pecli.errors import PecliError
from pecli.metagame import MAXENT_SLACK
from pecli.roles import Role
from pecli.scenario import Scenario


class MetaSolver(str, Enum):
    """Which mixture of a population the other side's responses train against (pecli.metagame.META_SOLVERS)."""

    nash = "nash"
    maxent = "maxent"
    uniform = "uniform"
    last = "last"


def _table(iterations: list) -> Table:  # noqa: ANN001 (pecli.psro loads torch: imported in the command)
    table = Table(
        title="PSRO: each iteration's mixtures and the best responses to them",
        caption="NashConv = capture(BR pursuer vs evader mixture) − capture(pursuer mixture vs BR evader), 95 % "
        "interval over the held-out games; value: the two mixtures against each other in the meta-game; "
        "pursuer-K, evader-K: member K (from 0) of each population (the players given, then the responses joined; "
        "OUT/iter-NN/nash.json names their files)",
    )
    for column in ("iteration", "pursuers", "evaders", "value", "BR pursuer", "vs BR evader", "NashConv", "95 %"):
        table.add_column(column, justify="left" if column in ("pursuers", "evaders") else "right", overflow="fold")
    for index, it in enumerate(iterations, start=1):
        low, high = it.interval
        table.add_row(
            str(index),
            ", ".join(f"{name} {w:.2f}" for name, w in it.pursuer_mixture.items()),
            ", ".join(f"{name} {w:.2f}" for name, w in it.evader_mixture.items()),
            f"{it.value:.3f}",
            f"{it.best_pursuer:.3f}",
            f"{it.best_evader:.3f}",
            f"{it.nash_conv:.3f}",
            f"[{low:.3f}, {high:.3f}]",
        )
    return table


def _populations(players: list[str], scenario: Scenario, quiet: bool) -> dict[Role, tuple[str, ...]]:
    """Two players, neither a folder: the pursuer then the evader. More: each joins the side it plays, as a
    tournament lists them (a checkpoint its own role, a built-in the side it is built for, a folder every
    checkpoint below it, in sorted order)."""
    from pecli.tournament import find_players

    if len(players) == 2 and not any(Path(player).is_dir() for player in players):
        return {"pursuer": (players[0],), "evader": (players[1],)}
    found = find_players(players, scenario, both_sides=False)
    for role, members in found.players.items():
        if not members:
            why = f" ({len(found.skipped)} checkpoint(s) skipped, e.g. {found.skipped[0]})" if found.skipped else ""
            raise PecliError(f"no {role} among the players: PSRO starts from at least one of each side{why}")
    if found.skipped and not quiet:
        err_console.print(f"skipped {len(found.skipped)} checkpoint(s), e.g. {found.skipped[0]}", markup=False)
    return {role: tuple(p.spec for p in members) for role, members in found.players.items()}


@user_errors
def psro(
    players: Annotated[
        list[str],
        typer.Argument(
            help="The populations PSRO starts from: a pursuer and an evader, in that order, or more players, each "
            "joining the side it plays (a checkpoint, an export, a policy string or a folder of checkpoints); the "
            "last checkpoint of a side is its newest.",
            show_default=False,
        ),
    ],
    config: PlayersConfigOption = None,
    iterations: Annotated[int, typer.Option("--iterations", "-i", help="PSRO iterations (a re-run may add more).")] = 3,
    cpu_minutes: Annotated[
        float, typer.Option("--cpu-minutes", help="CPU-minutes each best response trains (its evaluations included).")
    ] = 20.0,
    seeds: Annotated[
        int, typer.Option("--seeds", help="Best responses per role and iteration (the strongest joins).")
    ] = 1,
    warm: Annotated[
        bool,
        typer.Option(
            "--warm/--fresh",
            help="Start each best response from its population's newest checkpoint (--fresh: from scratch).",
        ),
    ] = True,
    pursuer_mixture: Annotated[
        MetaSolver,
        typer.Option(
            "--pursuer-mixture",
            help="The pursuers the evaders' responses train against and that are handed over: the meta-game's "
            "Nash mixture, the most spread one within --slack of its value (maxent), all alike "
            "(uniform) or the newest alone (last: one network).",
        ),
    ] = MetaSolver.nash,
    evader_mixture: Annotated[
        MetaSolver,
        typer.Option("--evader-mixture", help="The same for the evaders that the pursuers' responses train against."),
    ] = MetaSolver.nash,
    slack: Annotated[
        float | None,
        typer.Option(
            "--slack",
            help="The capture rate a maxent mixture may give up against the meta-game's value, in (0, 1] "
            f"(default {MAXENT_SLACK:g}).",
        ),
    ] = None,
    episodes: Annotated[int, typer.Option("--episodes", "-n", help="Games per pairing of the meta-game.")] = 200,
    held_out: Annotated[
        int, typer.Option("--held-out", help="Held-out games of each best response against the mixture.")
    ] = 500,
    workers: Annotated[
        int, typer.Option("--workers", "-w", help="Processes playing the meta-game and training the best responses.")
    ] = 1,
    out: Annotated[Path, typer.Option("--out", "-o", help="The PSRO folder (a re-run continues it).")] = Path(
        "runs/psro"
    ),
    reuse: Annotated[
        Path | None,
        typer.Option(
            "--reuse",
            help="A tournament's --out or another PSRO folder: its played pairings join the meta-game's cache "
            "(only identical pairings, same scenario, games and pecli version, are taken).",
        ),
    ] = None,
    as_json: Annotated[bool, typer.Option("--json", help="Print the iterations as JSON.")] = False,
) -> None:
    """PSRO from PLAYERS: grow a population of pursuers and one of evaders with trained best responses until
    their mixtures are hard to exploit.

    The populations start from a pair (a league run's handed-over players) or from whole zoos (every round of
    several runs and the evaders a tournament met; [bold]--reuse[/] takes that tournament's played pairings).
    Each iteration plays the populations' meta-game (every pursuer against every evader, [bold]--episodes[/] games,
    cached), solves its Nash equilibrium and writes each side's mixture (the equilibrium's, or by
    [bold]--pursuer-mixture[/] / [bold]--evader-mixture[/]) as OUT/iter-NN/nash.json (a player as
    nash:OUT/iter-NN). A best response of each role then trains [bold]--cpu-minutes[/] against the other side's
    mixture on the real game, and its [bold]--held-out[/] games measure the mixtures' NashConv. The strongest
    response of each role joins its population. Stopping is safe: the same command continues; a larger
    [bold]--iterations[/] goes on. Writes psro.json and nash-conv.png into [bold]--out[/].
    """
    from pecli.psro import PsroJob, iteration_folder
    from pecli.psro import psro as run_psro

    require_batch(episodes, "play fewer")
    require_positive(held_out, "--held-out")
    require_positive(seeds, "--seeds")
    require_positive(workers, "--workers")
    maxent = MetaSolver.maxent in (pursuer_mixture, evader_mixture)
    spread = maxent_slack(slack, maxent, "add --pursuer-mixture maxent or --evader-mixture maxent")
    scenario = scenario_for(players, config, folders=True)
    populations = _populations(players, scenario, quiet=as_json)
    job = PsroJob(
        pursuers=populations["pursuer"],
        evaders=populations["evader"],
        scenario=scenario,
        out=out,
        iterations=iterations,
        cpu_minutes=cpu_minutes,
        seeds=tuple(range(seeds)),
        warm=warm,
        episodes=episodes,
        held_out=held_out,
        workers=workers,
        pursuer_solver=pursuer_mixture.value,
        evader_solver=evader_mixture.value,
        reuse=reuse,
        slack=spread,
    )

    def report(line: str) -> None:
        if not as_json:
            err_console.print(line, highlight=False, markup=False)

    with responses_stop():
        done = run_psro(job, report)
    if as_json:
        typer.echo(json.dumps([it.model_dump(mode="json") for it in done], indent=2))
        return
    console.print(_table(done))
    err_console.print(
        f"wrote {out / 'psro.json'}; the last mixture plays as nash:{iteration_folder(out, len(done))}",
        highlight=False,
        markup=False,
    )
