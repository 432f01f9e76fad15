"""``pecli play``: one pursuer against one evader, all episodes as one batch."""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path
from typing import Annotated

import typer
from rich.markup import escape
from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn
from rich.table import Table

from pecli.cli.common import (
    PlayersConfigOption,
    SeedOption,
    console,
    err_console,
    one_torch_thread,
    require_batch,
    scenario_for,
    user_errors,
)
from pecli.errors import PecliError
from pecli.match import Behaviour, play_match
from pecli.policies import builtin_names, resolve_policy
from pecli.render import MAX_PANELS

EPISODES = 100  # played without --episodes (one with --render to a .gif)
MAX_BEHAVIOUR = 10_000  # episodes recorded whole for --behaviour
MAX_FRAMES = 10_000_000  # and their steps in all (a few hundred MB of states)
POLICY_HELP = (
    "A built-in name ({names}), hj[:OPTIONS] (see docs/hj.md), a policy file, module:Class, mix:A,B@2,... "
    "(several players, each game one of them, drawn by weight) or nash:FOLDER (a tournament's --nash mixture)."
)


@user_errors
def play(
    pursuer: Annotated[
        str, typer.Option("--pursuer", "-p", help=POLICY_HELP.format(names=", ".join(builtin_names("pursuer"))))
    ] = "pure-pursuit",
    evader: Annotated[
        str, typer.Option("--evader", "-e", help=POLICY_HELP.format(names=", ".join(builtin_names("evader"))))
    ] = "greedy",
    config: PlayersConfigOption = None,
    episodes: Annotated[
        int | None,
        typer.Option(
            "--episodes",
            "-n",
            help=f"Episodes to play, all at once (default: {EPISODES}; 1 when --render writes a .gif).",
            show_default=False,
        ),
    ] = None,
    seed: SeedOption = 0,
    as_json: Annotated[bool, typer.Option("--json", help="Print the metrics as one JSON object.")] = False,
    render: Annotated[
        Path | None,
        typer.Option(
            "--render",
            help=f"Draw episodes: a .png of each (the first {MAX_PANELS} at most), or a .gif of the first one.",
        ),
    ] = None,
    behaviour: Annotated[
        bool,
        typer.Option(
            "--behaviour",
            help="Also how the evader plays: how often each sees the other, its speed while "
            f"it sees the pursuer and while not, its distance to it and to the walls (at most "
            f"{MAX_BEHAVIOUR:,} episodes).",
        ),
    ] = False,
) -> None:
    """Play a pursuer against an evader and report the capture rate and time-to-capture.

    The time-to-capture is normalised by the horizon T; a timeout counts 1.0.
    Episode i under one seed always starts from the same state, whoever plays it.
    """
    gif = render is not None and render.suffix.lower() == ".gif"
    if episodes is None:
        episodes = 1 if gif else EPISODES  # a GIF shows one episode: play that one
    require_batch(episodes, "play fewer (a tournament plays more over several --seeds)")
    if behaviour and episodes > MAX_BEHAVIOUR:
        raise PecliError(f"--behaviour records every episode: play at most {MAX_BEHAVIOUR:,}")
    if behaviour and episodes * (scenario_horizon := scenario_for([pursuer, evader], config).horizon) > MAX_FRAMES:
        raise PecliError(
            f"--behaviour records every step of every episode: at most {MAX_FRAMES:,} steps in all, "
            f"not {episodes:,} x {scenario_horizon:,}"
        )
    if render is not None and render.suffix.lower() not in (".png", ".gif"):
        raise PecliError(f"--render must end in .png or .gif, got '{render.name}'")
    if render is not None:
        render.parent.mkdir(parents=True, exist_ok=True)  # fail before playing, not after
    scenario = scenario_for([pursuer, evader], config)
    pursuer_policy = resolve_policy(pursuer, "pursuer", scenario)
    evader_policy = resolve_policy(evader, "evader", scenario)
    one_torch_thread()
    record = 0 if render is None else (1 if gif else min(episodes, MAX_PANELS))
    title = f"{pursuer} vs {evader} on {scenario.name} (seed {seed})"

    with Progress(
        TextColumn("[bold]playing[/] {task.description}"),
        BarColumn(),
        TextColumn("step {task.completed:.0f}/{task.total:.0f}  {task.fields[running]} running"),
        TimeElapsedColumn(),
        console=err_console,
        transient=True,
        disable=as_json or not err_console.is_terminal,
    ) as progress:
        task = progress.add_task(f"{episodes} episodes", total=scenario.horizon, running=episodes)
        result, recording = play_match(
            scenario,
            pursuer_policy,
            evader_policy,
            episodes=episodes,
            seed=seed,
            record=episodes if behaviour else record,
            on_step=lambda step, running: progress.update(task, completed=step, running=running),
        )

    seen = Behaviour.of(recording) if behaviour and recording is not None else None
    if as_json:
        behaved = (
            {key: None if math.isnan(value) else value for key, value in dataclasses.asdict(seen).items()}
            if seen
            else None
        )  # a share of no step (never saw it) is no number: null
        typer.echo(json.dumps(result.summary() | ({"behaviour": behaved} if behaved else {})))
    else:
        table = Table(title=title)
        table.add_column("episodes", justify="right")
        table.add_column("capture rate", justify="right")
        table.add_column("time-to-capture (σ)", justify="right")
        table.add_row(
            str(result.episodes),
            f"{result.capture_rate:.3f}",
            f"{result.time_to_capture_mean:.3f} ({result.time_to_capture_std:.3f})",
        )
        console.print(table)
        if seen is not None:
            _print_behaviour(seen)

    if render is not None and recording is not None:
        from pecli.render import animate_episode, draw_episodes

        if gif:
            animate_episode(recording, render, title=title)
            drawn = f"episode 1 of the {episodes}" if episodes > 1 else "the episode"
        else:
            draw_episodes(recording, render, episodes=record, title=title)
            drawn = (
                f"the first {record} of the {episodes} episodes (a drawing holds at most {MAX_PANELS})"
                if episodes > record
                else (f"the {episodes} episodes" if episodes > 1 else "the episode")
            )
        err_console.print(f"wrote {escape(str(render))}: {drawn}", highlight=False)


def _print_behaviour(seen: Behaviour) -> None:
    """The evader's behaviour as a table."""
    table = Table(title="how the evader plays (means over the steps its games lasted)")
    for column in (
        "seen by the pursuer",
        "sees the pursuer",
        "speed unseen / seeing (m/step)",
        "distance",
        "to the nearest wall",
    ):
        table.add_column(column, justify="right")
    table.add_row(
        f"{seen.seen:.2f}",
        f"{seen.sees:.2f}",
        f"{seen.speed_unseen:.3f} / {seen.speed_seeing:.3f}",
        f"{seen.distance:.1f} m",
        f"{seen.wall:.2f} m",
    )
    console.print(table)
