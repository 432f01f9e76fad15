"""``pecli tune``: search training settings with Optuna (pursuer, evader or self-play), and report on a study."""

from __future__ import annotations

import enum
from pathlib import Path
from typing import Annotated, Any

import typer

from pecli.cli.common import (
    TrainConfigOption,
    console,
    err_console,
    sigterm_stops,
    user_errors,
)
from pecli.cli.train import AlgoChoice, DeviceOption
from pecli.errors import PecliError

DEFAULT_TRIALS = 30
TRIALS_ATTR = "trials"  # the study's user attribute: how many trials it has when done

app = typer.Typer(help="Search training settings with Optuna, and report on a study.", no_args_is_help=True)

DEFAULT_DIR = Path("tune")
DB_NAME = "studies.db"


class PrunerChoice(str, enum.Enum):
    median = "median"
    halving = "halving"
    none = "none"


DirOption = Annotated[
    Path,
    typer.Option(
        "--dir", help=f"Folder of the default SQLite storage ({DB_NAME}) and of each study's report and scratch files."
    ),
]
StorageOption = Annotated[
    str | None,
    typer.Option(
        "--storage",
        help="Any Optuna storage URL, e.g. "
        "sqlite:///studies.db or postgresql://host/db (default: "
        f"sqlite:///<dir>/{DB_NAME}).",
    ),
]


def _tune(what: str, **options: Any) -> None:
    from pecli.models.algorithms import torch_device
    from pecli.rl.budget import check_cpu_minutes
    from pecli.rl.search_space import load_space
    from pecli.rl.tune import (
        TuneSettings,
        Worker,
        load_study,
        new_study,
        run_workers,
        sqlite_url,
        stored_settings,
    )
    from pecli.rl.tune_report import write_report
    from pecli.roles import DEFAULT_OPPONENT
    from pecli.scenario import load_scenario

    o = options
    torch_device(o["device"])  # a machine without CUDA refuses --device cuda before any trial
    for option in ("jobs", "trials"):
        if o[option] is not None and o[option] < 1:
            raise PecliError(f"--{option} must be at least 1, not {o[option]}")
    storage = o["storage"] or sqlite_url(o["dir"] / DB_NAME)
    if o["resume"]:
        if o["study"] is None:
            raise PecliError("--resume needs the --study to continue")
        given = [
            f"--{k.replace('_', '-')}"
            for k in (
                "config",
                "opponent",
                "eval_opponents",
                "cpu_minutes",
                "evaluations",
                "eval_episodes",
                "space",
                "pruner",
                "seed",
                "algo",
                "repeats",
            )
            if o[k] is not None
        ]
        if given:
            raise PecliError(
                f"a resumed study keeps its settings (not {', '.join(given)}); only --trials, --jobs "
                "and --device may be given"
            )
        study = load_study(storage, o["study"])
        settings = stored_settings(study)
        if settings.what != what:
            raise PecliError(f"study '{o['study']}' tunes {settings.what}, not {what}")
    else:
        scenario = load_scenario(o["config"] or "paper")
        space, text = load_space(o["space"], scenario)
        if o["algo"] is not None:  # the study searches this algorithm's settings only
            space.parameters.pop("algo", None)
            space.fixed["algo"] = o["algo"].value
            space.check(scenario, "--algo")
        opponent = None if what == "selfplay" else (o["opponent"] or DEFAULT_OPPONENT[what])
        evaluated = (
            []
            if what == "selfplay"
            else [name.strip() for name in (o["eval_opponents"] or opponent).split(",") if name.strip()]
        )
        given = {
            k: o[k] for k in ("cpu_minutes", "evaluations", "eval_episodes", "seed", "repeats") if o[k] is not None
        }
        settings = TuneSettings(
            what=what,
            scenario=scenario.model_dump(mode="json"),
            space=space.model_dump(mode="json"),
            opponent=opponent,
            eval_opponents=evaluated,
            pruner=(o["pruner"] or PrunerChoice.median).value,
            space_text=text,
            **{"cpu_minutes": 3.0, **given},
        )
        check_cpu_minutes(settings.cpu_minutes)
        for option in ("evaluations", "eval_episodes", "repeats"):
            if getattr(settings, option) <= 0:
                raise PecliError(f"--{option.replace('_', '-')} must be positive, not {getattr(settings, option):g}")
        if not 0 <= settings.seed < 2**32:
            raise PecliError("--seed must be between 0 and 2**32 - 1")
        _check_opponents(settings, scenario)
        study = new_study(settings, storage, o["study"] or f"{scenario.name}-{what}")
    kept = study.user_attrs.get(TRIALS_ATTR)
    if o["trials"] is not None:
        total = o["trials"]
    elif o["resume"] and isinstance(kept, int) and not isinstance(kept, bool) and kept >= 1:
        total = kept  # a resumed study goes on to its own number of trials, not to the default
    elif o["resume"]:  # a study of an older pecli, which did not record it: finish what is started
        total = max(len(study.trials), 1)
    else:
        total = DEFAULT_TRIALS
    study.set_user_attr(TRIALS_ATTR, total)
    folder = o["dir"] / study.study_name
    runs = f"{settings.repeats} runs of " if settings.repeats > 1 else ""
    err_console.print(
        f"study [bold]{study.study_name}[/] in {storage}: {what} on {settings.scenario['name']}, "
        f"{total} trials of {runs}{settings.cpu_minutes:g} CPU-min, {o['jobs']} at a time",
        highlight=False,
    )
    worker = Worker(
        storage,
        study.study_name,
        total,
        folder,
        o["device"],
        settings.seed,
        report=lambda line: err_console.print(line, highlight=False, markup=False),
    )

    try:
        with sigterm_stops():
            run_workers(worker, o["jobs"])
    except KeyboardInterrupt:
        err_console.print(
            f"[yellow]interrupted[/]: finished trials are stored; continue with "
            f"--resume --study {study.study_name}" + (f" --storage {storage}" if o["storage"] else ""),
            highlight=False,
        )
        raise typer.Exit(code=130) from None
    written = write_report(study, folder)
    err_console.print(f"[green]done[/]: report {written[0]}", highlight=False)


def _check_opponents(settings: Any, scenario: Any) -> None:
    """Every named opponent resolves now, not in the first trial."""
    from pecli.policies import resolve_policy
    from pecli.roles import opponent_of

    if settings.what == "selfplay":
        return
    for name in {settings.opponent, *settings.eval_opponents}:
        resolve_policy(name, opponent_of(settings.what), scenario)


def _command(what: str, doc: str) -> Any:
    @user_errors
    def command(
        config: TrainConfigOption = None,
        opponent: Annotated[
            str | None,
            typer.Option(
                "--opponent",
                help="The frozen opponent (default: greedy for a pursuer, pure-pursuit for an evader).",
            ),
        ] = None,
        eval_opponents: Annotated[
            str | None,
            typer.Option(
                "--eval-opponents",
                help="Comma-separated opponents the learner is scored against (default: --opponent).",
            ),
        ] = None,
        trials: Annotated[
            int | None,
            typer.Option(
                "--trials",
                "-t",
                help="Trials the study has when done (complete or pruned; default 30, a resumed study its own).",
            ),
        ] = None,
        cpu_minutes: Annotated[
            float | None,
            typer.Option(
                "--cpu-minutes", help="CPU budget of a training run (a trial has --repeats of them; default 3)."
            ),
        ] = None,
        evaluations: Annotated[
            int | None,
            typer.Option(
                "--evaluations",
                help="Evaluations per training run, evenly over its budget, reported to the pruner (default 6).",
            ),
        ] = None,
        eval_episodes: Annotated[
            int | None, typer.Option("--eval-episodes", help="Games per opponent and evaluation (default 200).")
        ] = None,
        jobs: Annotated[
            int,
            typer.Option(
                "--jobs",
                "-j",
                help="Trials run in parallel processes, one torch thread "
                "each; the study may end up to J - 1 trials over --trials.",
            ),
        ] = 1,
        storage: StorageOption = None,
        study: Annotated[str | None, typer.Option("--study", help="Study name (default: <config>-<what>).")] = None,
        resume: Annotated[
            bool, typer.Option("--resume", help="Continue the stored --study (its own settings).")
        ] = False,
        space: Annotated[
            Path | None, typer.Option("--space", help="Search space YAML (default: `pecli tune space`).")
        ] = None,
        algo: Annotated[AlgoChoice | None, typer.Option("--algo", help="Tune this algorithm only.")] = None,
        pruner: Annotated[
            PrunerChoice | None,
            typer.Option("--pruner", help="median (default), halving (successive halving) or none."),
        ] = None,
        seed: Annotated[
            int | None,
            typer.Option(
                "--seed",
                "-s",
                help="Seed of trial 0 (trial i trains with seed + i, or seed + i*R with --repeats R; default 0).",
            ),
        ] = None,
        repeats: Annotated[
            int | None,
            typer.Option(
                "--repeats",
                help="Training runs per trial, each on its "
                "own seed (trial i: seed + i*R ... seed + i*R + R-1), each "
                "with --cpu-minutes; the trial scores their mean (default 1).",
            ),
        ] = None,
        device: DeviceOption = "cpu",
        folder: DirOption = DEFAULT_DIR,
    ) -> None:
        _tune(
            what,
            config=config,
            opponent=opponent,
            eval_opponents=eval_opponents,
            trials=trials,
            cpu_minutes=cpu_minutes,
            evaluations=evaluations,
            eval_episodes=eval_episodes,
            jobs=jobs,
            storage=storage,
            study=study,
            resume=resume,
            space=space,
            algo=algo,
            pruner=pruner,
            seed=seed,
            repeats=repeats,
            device=device,
            dir=folder,
        )

    command.__doc__ = doc
    if what == "selfplay":  # no frozen opponent: the command takes neither option (nor shows it in --help)
        import inspect

        signature = inspect.signature(command, eval_str=True)
        dropped = ("opponent", "eval_opponents")
        command.__signature__ = signature.replace(  # type: ignore[attr-defined]
            parameters=[p for p in signature.parameters.values() if p.name not in dropped]
        )
    return command


_COMMON = (
    "\n\nEach trial draws training settings from the search space ([bold]--space[/], default: `pecli tune space`), "
    "trains within [bold]--cpu-minutes[/] of CPU time and is evaluated [bold]--evaluations[/] times on held-apart "
    "seeds; the pruner stops trials that fall behind, and the last evaluation is the trial's score. The first trial "
    "of a new study is the config's own settings. The study is stored (SQLite by default), so [bold]--resume[/] "
    "continues it after Ctrl-C or a kill, and processes on other machines can share it through [bold]--storage[/]. "
    "At the end, the report (best trials, importances, history PNGs) is written to <dir>/<study>/."
)
app.command("pursuer")(_command("pursuer", "Tune the training of a pursuer against a frozen evader." + _COMMON))
app.command("evader")(_command("evader", "Tune the training of an evader against a frozen pursuer." + _COMMON))
app.command("selfplay")(
    _command("selfplay", "Tune self-play; a trial scores both sides against the other's baselines." + _COMMON)
)


@app.command("report")
@user_errors
def report(
    study_name: Annotated[str, typer.Argument(help="The study.", metavar="STUDY")],
    storage: StorageOption = None,
    folder: DirOption = DEFAULT_DIR,
    out: Annotated[Path | None, typer.Option("--out", "-o", help="Report folder (default: <dir>/<study>).")] = None,
    profile: Annotated[
        Path | None,
        typer.Option("--profile", help="Also write the best trial's settings as a scenario YAML (a training profile)."),
    ] = None,
    name: Annotated[
        str | None, typer.Option("--name", help="The profile's scenario name (default: the file's stem).")
    ] = None,
    trial: Annotated[
        int | None, typer.Option("--trial", help="Take the profile from this trial, not the best.")
    ] = None,
) -> None:
    """Print a study's best trials and importances; write report.md and the PNGs, and optionally a profile."""
    import optuna

    from pecli.io import atomic_write_text
    from pecli.rl.tune import load_study, sqlite_url
    from pecli.rl.tune_report import profile as make_profile
    from pecli.rl.tune_report import summary, write_report

    url = storage or sqlite_url(folder / DB_NAME)
    if url.startswith("sqlite:///") and not Path(url.removeprefix("sqlite:///")).is_file():
        raise PecliError(f"no study storage at {url.removeprefix('sqlite:///')}")
    study = load_study(url, study_name)
    console.print(summary(study), highlight=False, markup=False, soft_wrap=True)
    written = write_report(study, out or folder / study_name)
    err_console.print(f"wrote {', '.join(str(p) for p in written)}", highlight=False)
    if profile is not None:
        complete = [
            t.number
            for t in study.get_trials(deepcopy=False)
            if t.value is not None and t.state == optuna.trial.TrialState.COMPLETE
        ]
        if not complete or (trial is not None and trial not in complete):
            raise PecliError(
                f"study '{study_name}' has no complete trial {trial if trial is not None else ''}".rstrip()
            )
        atomic_write_text(profile, make_profile(study, name or profile.stem, trial))
        err_console.print(f"wrote the profile {profile}", highlight=False)


@app.command("space")
@user_errors
def space() -> None:
    """Print the default search space (YAML), to copy and edit for --space."""
    from pecli.rl.search_space import DEFAULT_SPACE

    typer.echo(DEFAULT_SPACE.read_text(), nl=False)
