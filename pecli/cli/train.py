"""``pecli train pursuer|evader``: train one role (TD3, DDPG, SAC, TQC or CrossQ) against a frozen opponent."""

from __future__ import annotations

import enum
from pathlib import Path
from typing import Annotated

import typer
from rich.markup import escape

from pecli.belief import BELIEF_KINDS
from pecli.cli.common import (
    TrainConfigOption,
    err_console,
    sigterm_stops,
    user_errors,
)
from pecli.progress import LOG_EVERY
from pecli.scenario import ALGOS, load_scenario


class RoleChoice(str, enum.Enum):
    pursuer = "pursuer"
    evader = "evader"


AlgoChoice = enum.Enum("AlgoChoice", {name: name for name in ALGOS}, type=str)
BeliefChoice = enum.Enum("BeliefChoice", {kind.replace("-", "_"): kind for kind in BELIEF_KINDS}, type=str)
DeviceOption = Annotated[
    str,
    typer.Option(
        "--device",
        help="Where the networks train: cpu, cuda (cuda:N) or auto (CUDA if there is "
        "one, as in SB3); checkpoints load on the CPU wherever they trained.",
    ),
]


@user_errors
def train(
    role: Annotated[RoleChoice, typer.Argument(help="The role to train.", show_default=False)],
    config: TrainConfigOption = None,
    opponent: Annotated[
        str | None,
        typer.Option(
            "--opponent",
            help="The frozen opponent: a built-in, a checkpoint, or module:Class. "
            "Default: greedy for a pursuer, pure-pursuit for an evader.",
        ),
    ] = None,
    algo: Annotated[AlgoChoice | None, typer.Option("--algo", help="Override the config's algorithm.")] = None,
    belief: Annotated[
        BeliefChoice | None,
        typer.Option("--belief", help="What the actor knows of the unseen opponent (default: the config's, none)."),
    ] = None,
    steps: Annotated[int | None, typer.Option("--steps", help="Override the budget (learner transitions).")] = None,
    cpu_minutes: Annotated[
        float | None,
        typer.Option(
            "--cpu-minutes",
            help="Also stop when the run's CPU time (across resumes) reaches this many minutes, before --steps "
            "if need be. The run keeps it: --resume continues to it, or to a new one given here.",
        ),
    ] = None,
    seed: Annotated[
        int | None,
        typer.Option("--seed", "-s", min=0, max=2**32 - 1, help="Seed of games, noise and networks (default 0)."),
    ] = None,
    zoo: Annotated[Path, typer.Option("--zoo", help="The zoo folder runs are written to.")] = Path("zoo"),
    name: Annotated[str | None, typer.Option("--name", help="Run name (default: scenario-role-seed-time).")] = None,
    resume: Annotated[
        bool, typer.Option("--resume", help="Continue the run --name from its newest checkpoint.")
    ] = False,
    overrides: Annotated[
        list[str] | None,
        typer.Option(
            "--set", help="Override a training setting, e.g. --set batch_size=256 --set curriculum.enabled=false."
        ),
    ] = None,
    quiet: Annotated[bool, typer.Option("--quiet", "-q", help="No progress display.")] = False,
    device: DeviceOption = "cpu",
) -> None:
    """Train a pursuer or an evader with Stable-Baselines3 against a frozen opponent.

    Hyperparameters come from the config's [bold]training[/] section (the paper's values in
    paper.yaml). Checkpoints go to [bold]zoo/<run>/<role>/[/] every checkpoint_every episodes, each
    with the run's durable state: however the run stops (Ctrl-C, a kill, a power cut), [bold]--resume[/]
    continues it from its newest checkpoint, replay buffer included.
    TensorBoard logs are in zoo/<run>/tb.
    """
    from pecli.models.algorithms import torch_device
    from pecli.rl.budget import check_cpu_minutes
    from pecli.rl.resume import resume_train
    from pecli.rl.train import (
        TrainingInterrupted,
        TrainJob,
        default_run_name,
        parse_overrides,
        with_overrides,
    )
    from pecli.rl.train import train as run_training
    from pecli.roles import DEFAULT_OPPONENT
    from pecli.zoo import Run

    role_name = role.value
    torch_device(device)  # a machine without CUDA refuses --device cuda in one line
    if cpu_minutes is not None:
        check_cpu_minutes(cpu_minutes)
    settings = parse_overrides(overrides or [])
    if steps is not None:
        settings["steps"] = steps
    if algo is not None:
        settings["algo"] = algo.value
    if belief is not None:
        settings["belief"] = belief.value
    curriculum_steps = None
    if resume:
        kept = resume_train(zoo, name, role_name, config, opponent, seed, settings)
        scenario, opponent, seed, curriculum_steps = kept.scenario, kept.opponent, kept.seed, kept.curriculum_steps
        cpu_minutes = kept.cpu_minutes if cpu_minutes is None else cpu_minutes
    else:
        scenario = load_scenario(config or "paper")
    if settings:
        scenario = with_overrides(scenario, settings, source="options")
    seed = 0 if seed is None else seed
    job = TrainJob(
        role=role_name,
        scenario=scenario,
        opponent=opponent or DEFAULT_OPPONENT[role_name],
        zoo=zoo,
        name=name or default_run_name(role_name, scenario, seed),
        seed=seed,
        resume=resume,
        progress=not quiet and err_console.is_terminal,
        log_every=None if quiet or err_console.is_terminal else LOG_EVERY,
        curriculum_steps=curriculum_steps,
        device=device,
        cpu_budget=None if cpu_minutes is None else 60.0 * cpu_minutes,
    )

    def started(run: Run) -> None:
        err_console.print(
            f"run [bold]{escape(str(run.path))}[/]: {role_name} vs {escape(job.opponent)} on "
            f"{escape(scenario.name)}, "
            f"{scenario.training.steps:,} steps"
            + ("" if cpu_minutes is None else f" or {cpu_minutes:g} CPU-minutes, whichever comes first"),
            highlight=False,
        )

    try:
        with sigterm_stops():  # a scheduler's or a benchmark's time limit saves like Ctrl-C
            final = run_training(job, on_start=started, report=lambda line: err_console.print(line, highlight=False))
    except TrainingInterrupted as stop:
        err_console.print(
            f"[yellow]interrupted[/]: saved {stop.checkpoint}; continue with --resume --name {job.name}",
            highlight=False,
        )
        raise typer.Exit(code=130) from None
    run_dir = zoo / job.name
    best = final.with_name("best.zip")
    also = f" (the best evaluation's: {escape(str(best))})" if best.is_file() else ""
    err_console.print(
        f"[green]done[/]: {escape(str(final))}{also}\n  checkpoints and their metadata in "
        f"{escape(str(run_dir / role_name))}/, the run's config and command in {escape(str(run_dir))}/\n"
        f"  learning curves: tensorboard --logdir {escape(str(run_dir / 'tb'))}",
        highlight=False,
    )
