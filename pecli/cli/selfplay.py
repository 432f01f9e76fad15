"""``pecli selfplay``: self-play of a pursuer and an evader, alternating against each other's pools or simultaneous."""

from __future__ import annotations

import enum
from pathlib import Path
from typing import Annotated

import typer

from pecli.cli.common import (
    TrainConfigOption,
    err_console,
    sigterm_stops,
    user_errors,
)
from pecli.cli.train import AlgoChoice, BeliefChoice, DeviceOption
from pecli.progress import LOG_EVERY
from pecli.scenario import load_scenario


class ScheduleChoice(str, enum.Enum):
    alternating = "alternating"
    simultaneous = "simultaneous"


class OpponentsChoice(str, enum.Enum):
    latest = "latest"
    uniform = "uniform"
    pfsp = "pfsp"
    league = "league"
    nash = "nash"


@user_errors
def selfplay(
    config: TrainConfigOption = None,
    rounds: Annotated[
        int | None,
        typer.Option(
            "--rounds", "-r", help="Rounds (default: the config's). With --resume: more rounds extend the run."
        ),
    ] = None,
    cpu_hours: Annotated[
        float | None,
        typer.Option(
            "--cpu-hours",
            help="Stop after the first round at which the run's CPU time (both sides' turns) "
            "reaches this many hours; --rounds stays the ceiling. The run keeps it: --resume continues to "
            "it, or to a new one given here.",
        ),
    ] = None,
    steps_per_round: Annotated[
        int | None,
        typer.Option("--steps-per-round", help="Learner transitions per side per round (default: the config's)."),
    ] = None,
    belief: Annotated[
        BeliefChoice | None,
        typer.Option("--belief", help="What each actor knows of the unseen opponent (default: the config's)."),
    ] = None,
    schedule: Annotated[
        ScheduleChoice | None,
        typer.Option(
            "--schedule",
            help="alternating: one side trains at a time against the other's pool; "
            "simultaneous: both learn in the same games every step (the paper's MADDPG). "
            "Default: the config's, alternating.",
        ),
    ] = None,
    opponents: Annotated[
        OpponentsChoice | None,
        typer.Option(
            "--opponents",
            help="How opponents are drawn from the pool: latest, uniform (fictitious self-play), "
            "pfsp (prioritised by how often they win), league (pfsp, plus an exploiter per side and "
            "pecli's scripted adversaries kept in the pools) or nash (the league, with the Nash mixture of "
            "the pools' meta-game in place of pfsp: PSRO). Default: the config's, pfsp.",
        ),
    ] = None,
    seed: Annotated[
        int | None,
        typer.Option(
            "--seed", "-s", min=0, max=2**32 - 1, help="Seed of games, draws, noise and networks (default 0)."
        ),
    ] = None,
    zoo: Annotated[Path, typer.Option("--zoo", help="The zoo folder runs are written to.")] = Path("zoo"),
    name: Annotated[str | None, typer.Option("--name", help="Run name (default: scenario-selfplay-seed-time).")] = None,
    resume: Annotated[
        bool, typer.Option("--resume", help="Continue the run --name from its newest checkpoint.")
    ] = False,
    overrides: Annotated[
        list[str] | None,
        typer.Option("--set", help="Override a training setting, e.g. --set selfplay.pfsp_power=1 --set n_envs=16."),
    ] = None,
    quiet: Annotated[bool, typer.Option("--quiet", "-q", help="No live view (the line per round stays).")] = False,
    algo: Annotated[
        AlgoChoice | None, typer.Option("--algo", help="Override the config's algorithm (both sides).")
    ] = None,
    device: DeviceOption = "cpu",
) -> None:
    """Train a pursuer and an evader by self-play.

    Alternating (the default): each round trains the pursuer against evaders drawn from the evader
    pool, then the evader against the pursuer pool; each new checkpoint joins its side's pool. Pools
    start with the paper's heuristic baselines. Simultaneous ([bold]--schedule simultaneous[/], the
    paper's MADDPG): both learners play each other in the same games and both learn every step.
    Both learners keep their networks and replay buffers from round to round. Checkpoints go to
    [bold]zoo/<run>/<role>/round-NNN.zip[/] with their lineage, and [bold]<role>/average.zip[/], the mean of
    the last rounds' weights (selfplay.average_last), is the player the run hands over; however the run stops,
    [bold]--resume[/] continues from its newest checkpoint. Settings: the config's
    [bold]training.selfplay[/] section.
    """
    from pecli.models.algorithms import torch_device
    from pecli.rl.handover import averaged_from
    from pecli.rl.resume import check_cpu_hours, resume_selfplay
    from pecli.rl.selfplay import (
        KEEP,
        SelfPlay,
        SelfPlayInterrupted,
        SelfPlayJob,
    )
    from pecli.rl.train import default_run_name, parse_overrides, with_overrides

    torch_device(device)  # a machine without CUDA refuses --device cuda in one line
    check_cpu_hours(cpu_hours)
    settings = parse_overrides(overrides or [])
    for key, value in (
        ("selfplay.rounds", rounds),
        ("selfplay.steps_per_round", steps_per_round),
        ("algo", algo.value if algo else None),
        ("belief", belief.value if belief else None),
        ("selfplay.opponents", opponents.value if opponents else None),
        ("selfplay.schedule", schedule.value if schedule else None),
    ):
        if value is not None:
            settings[key] = value
    if resume:
        scenario, seed = resume_selfplay(zoo, name, config, seed, settings)
    else:
        scenario = load_scenario(config or "paper")
        seed = 0 if seed is None else seed
    if settings:
        scenario = with_overrides(scenario, settings, source="options")
    job = SelfPlayJob(
        scenario=scenario,
        zoo=zoo,
        name=name or default_run_name("selfplay", scenario, seed),
        seed=seed,
        resume=resume,
        progress=not quiet and err_console.is_terminal,
        log_every=None if quiet or err_console.is_terminal else LOG_EVERY,
        device=device,
        cpu_hours=KEEP if cpu_hours is None else cpu_hours,
    )

    try:
        with sigterm_stops():
            loop = SelfPlay(job, report=lambda line: err_console.print(line, highlight=False))
            before = len(loop.state.turns)
            err_console.print(loop.plan(), highlight=False)
            final = loop.run()
    except SelfPlayInterrupted as stop:
        err_console.print(
            f"[yellow]interrupted[/] in round {stop.round} ({stop.role}); its progress is saved: "
            f"continue with --resume --name {job.name}",
            highlight=False,
        )
        raise typer.Exit(code=130) from None
    if len(loop.state.turns) == before:
        err_console.print(loop.nothing_trained(), highlight=False)
    averages = loop.averages()
    for role, path in final.items():
        rounds = len(averaged_from(averages[role]) or []) if role in averages else 0
        what = "its last round" if rounds == 1 else f"the mean of its last {rounds} rounds"
        average = f"; to hand over: {averages[role]} ({what})" if rounds else ""
        err_console.print(f"[green]done[/]: {role} {path}{average}", highlight=False, soft_wrap=True)
