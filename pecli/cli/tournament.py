"""``pecli tournament``: pursuers against evaders, the paper's metrics, significance and ratings."""

from __future__ import annotations

import json
import os
from enum import Enum
from pathlib import Path
from typing import Annotated

import typer

from pecli.cli.common import (
    console,
    err_console,
    maxent_slack,
    one_torch_thread,
    require_batch,
    require_positive,
    scenario_for,
    sigterm_stops,
    user_errors,
)
from pecli.errors import PecliError
from pecli.metagame import MAXENT_SLACK, with_meta_solvers
from pecli.progress import WorkProgress


class Mixture(str, Enum):
    """Which of the meta-game's mixtures ``--nash`` writes (pecli.metagame)."""

    nash = "nash"
    maxent = "maxent"


@user_errors
def tournament(
    paths: Annotated[
        list[str] | None,
        typer.Argument(
            help="Zoo folders, run folders, checkpoint files, exported .onnx models, or any policy string "
            "(a built-in name, hj, mix:A,B,..., nash:FOLDER, module:Class).",
            show_default=False,
        ),
    ] = None,
    config: Annotated[
        str | None,
        typer.Option(
            "--config",
            "-c",
            help="Scenario (default: the one the first run or policy file found was trained on, else paper).",
        ),
    ] = None,
    baselines: Annotated[bool, typer.Option("--baselines", help="Add the built-in heuristics of both sides.")] = False,
    episodes: Annotated[int, typer.Option("--episodes", "-n", help="Episodes per seed and pairing.")] = 500,
    seeds: Annotated[int, typer.Option("--seeds", help="Seeds per pairing (0 .. K-1).")] = 3,
    sample: Annotated[
        int | None,
        typer.Option(
            "--sample", help="Each checkpoint against M random opponents (the paper uses 32) instead of the grid."
        ),
    ] = None,
    workers: Annotated[int, typer.Option("--workers", "-w", help="Processes playing pairings.")] = min(
        2, os.cpu_count() or 1
    ),
    out: Annotated[
        Path | None,
        typer.Option(
            "--out",
            "-o",
            help="Folder for results, reports and the pairing cache "
            "(default: <first folder>/tournament, else runs/tournament).",
        ),
    ] = None,
    as_json: Annotated[bool, typer.Option("--json", help="Print the results as JSON.")] = False,
    resume: Annotated[bool, typer.Option("--resume", help="Reuse the pairings already played in --out.")] = False,
    seed: Annotated[
        int | None,
        typer.Option("--seed", "-s", min=0, help="Seed of the --sample draw (the games' seeds are --seeds: 0 .. K-1)."),
    ] = None,
    nash: Annotated[
        bool,
        typer.Option(
            "--nash",
            help="Solve the zoo's meta-game: print each side's Nash mixture and every player's "
            "exploitability within the zoo, and write nash.json (the mixture plays as nash:OUT).",
        ),
    ] = False,
    mixture: Annotated[
        Mixture,
        typer.Option(
            "--mixture",
            help="The mixture --nash writes: the equilibrium the LP finds (often a few members), or the most "
            "spread mixture that keeps within --slack of the game's value (maxent).",
        ),
    ] = Mixture.nash,
    slack: Annotated[
        float | None,
        typer.Option(
            "--slack",
            help="The capture rate the maxent mixture may give up against the value, in (0, 1] "
            f"(default {MAXENT_SLACK:g}: of the order of the payoffs' sampling error at 200 games).",
        ),
    ] = None,
) -> None:
    """Play pursuers against evaders and report capture rate and time-to-capture per pairing.

    Every pairing plays [bold]--episodes[/] games per seed as one batch, from the same start states
    for every pairing. The table follows the paper's Table I (bold: best against that evader, or
    tied with it by a two-proportion z-test); ratings put every player on one Bradley–Terry scale.
    Results go to [bold]--out[/]: results.json, results.csv, capture_rates.png and a cache that
    [bold]--resume[/] reuses.
    """
    from pecli.locks import locked
    from pecli.reports import (
        TABLE_WIDTH,
        nash_record,
        nash_table,
        ratings_table,
        results_tables,
        write_nash,
        write_reports,
    )
    from pecli.tournament import find_players, run_tournament, schedule

    require_batch(episodes, "add --seeds instead")
    if nash and sample is not None:
        raise PecliError("--nash needs every pairing: leave out --sample")
    if not nash and mixture is not Mixture.nash:
        raise PecliError("--mixture chooses the mixture that --nash writes: add --nash")
    spread = maxent_slack(slack, mixture is Mixture.maxent, "add --mixture maxent")
    if seed is not None and sample is None:
        raise PecliError("--seed seeds the --sample draw only; every pairing plays seeds 0 .. K-1 (--seeds)")
    require_positive(seeds, "--seeds")
    require_positive(workers, "--workers")
    paths = paths or []
    if out is None:
        out = Path(paths[0]) / "tournament" if paths and Path(paths[0]).is_dir() else Path("runs/tournament")
    if not paths and not baselines:
        raise PecliError("nothing to play: give zoo folders or checkpoints, and/or --baselines")

    out.mkdir(parents=True, exist_ok=True)
    try:  # SIGTERM (a scheduler, a time limit) stops like Ctrl-C: workers end too
        with sigterm_stops(), locked(out, "tournament output"):
            cache = out / "pairings"
            if cache.is_dir() and any(cache.iterdir()) and not resume:
                raise PecliError(
                    f"{out} already holds tournament results: pass --resume to reuse them, or another --out"
                )
            scenario = scenario_for(paths, config, folders=True)
            found = find_players(paths, scenario, baselines=baselines)
            for reason in found.skipped:
                err_console.print(f"[yellow]skipped[/] {reason}", highlight=False)
            pairings = schedule(found.players, sample=sample, seed=seed or 0)
            one_torch_thread()
            counts = {role: len(players) for role, players in found.players.items()}
            err_console.print(
                f"{counts['pursuer']} pursuers × {counts['evader']} evaders on {scenario.name}: "
                f"{len(pairings)} pairings of {episodes} × {seeds} episodes, "
                f"{workers} worker{'s' if workers > 1 else ''}",
                highlight=False,
            )

            with WorkProgress("pairings", len(pairings), err_console, enabled=not as_json) as progress:
                done = 0

                def report(result, cached: bool) -> None:
                    nonlocal done
                    done += 1
                    note = " (cached)" if cached else ""
                    last = f"{result.pursuer} vs {result.evader}: {result.capture_rate:.2f}{note}"
                    progress.update(done, note=last, skipped=1 if cached else 0)

                results = run_tournament(
                    scenario,
                    found.players,
                    pairings,
                    episodes,
                    list(range(seeds)),
                    out,
                    workers=workers,
                    on_result=report,
                )
            written = write_reports(results, out)
            game = results.meta_game() if nash else None
            if game is not None and mixture is Mixture.maxent:
                game = with_meta_solvers(game, "maxent", "maxent", spread)
            if game is not None:
                written.append(write_nash(results, game, out))
            if as_json:
                data = results.to_json()
                if game is not None:
                    data["nash"] = nash_record(results, game)
                typer.echo(json.dumps(data, indent=2))
                return
            width = min(console.width, TABLE_WIDTH)
            if sample is None or len(pairings) == counts["pursuer"] * counts["evader"]:
                for table in results_tables(results, width):
                    console.print(table, width=width)
            console.print(ratings_table(results, limit=40), width=width)
            if game is not None:
                console.print(nash_table(game, limit=40), width=width)
                err_console.print(
                    f"the mixture plays as nash:{out} (each game draws one member by its weight)",
                    highlight=False,
                    markup=False,
                )
            err_console.print("wrote " + ", ".join(str(p) for p in written), highlight=False)
    except KeyboardInterrupt:
        err_console.print(
            f"[yellow]interrupted[/]: the finished pairings are cached in {out}; continue with --resume",
            highlight=False,
        )
        raise typer.Exit(code=130) from None
