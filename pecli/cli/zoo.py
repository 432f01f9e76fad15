"""``pecli zoo``: list, show, remove, pick and average checkpoints of a zoo."""

from __future__ import annotations

import json
import math
import shutil
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer
from rich.table import Table

from pecli.cli.common import TABLE_WIDTH, console, err_console, shown, user_errors
from pecli.cli.train import RoleChoice
from pecli.errors import PecliError

if TYPE_CHECKING:
    from pecli.scenario import Scenario
    from pecli.zoo import CheckpointMeta

app = typer.Typer(help="List, show, remove, pick and average checkpoints of a zoo.", no_args_is_help=True)

ZooArgument = Annotated[Path, typer.Argument(help="The zoo folder (or one run folder).")]


@app.command("list")
@user_errors
def list_zoo(zoo: ZooArgument = Path("zoo")) -> None:
    """Runs and checkpoints as a table, with tournament ratings where a tournament rated them."""
    from pecli.tournament import tournament_ratings
    from pecli.zoo import checkpoints_in, runs_in

    if not zoo.is_dir():
        raise PecliError(f"no zoo at {zoo}")
    runs = runs_in(zoo)
    if not runs:
        console.print(f"{zoo}: no runs yet (train one with `pecli train`)")
        return
    ratings = tournament_ratings(zoo)
    table = Table(title=f"zoo {zoo}")
    for column in ("run", "role", "checkpoint", "steps", "episodes", "algo", "belief", "scenario", "rating"):
        table.add_column(
            column,
            justify="right" if column in ("steps", "episodes", "rating") else "left",
            overflow="fold",  # a long run name wraps instead of losing its end
        )
    for run in runs:
        for entry in checkpoints_in(run):
            meta = entry.meta
            if meta is None or entry.problem:
                problem = shown(str(entry.problem), style="red")
                table.add_row(shown(run.name), entry.path.parent.name, shown(entry.path.stem), *[""] * 5, problem)
                continue
            rated = ratings.get(str(entry.path.resolve()))
            rating = f"{rated['elo']:.0f} ± {rated['stderr']:.0f}" if rated else ""
            table.add_row(
                shown(run.name),
                entry.path.parent.name,  # the folder: a league's exploiter-pursuer apart from its main pursuer
                shown(entry.path.stem),
                f"{meta.steps:,}",
                str(meta.episodes),
                shown(meta.algo),
                shown(meta.belief),
                shown(meta.scenario),  # a stranger's text: neither markup nor a terminal's escape codes
                rating,
            )
    console.print(table, width=min(console.width, TABLE_WIDTH))


@app.command("show")
@user_errors
def show(checkpoint: Annotated[Path, typer.Argument(help="A checkpoint file (.zip).")]) -> None:
    """Print a checkpoint's metadata (and lineage, for self-play checkpoints) as JSON.

    The metadata is checked against the network it describes first (when the checkpoint's scenario
    is at hand: its run's config.yaml, or the built-in it names); a mismatch is refused.
    """
    from pecli.zoo import checkpoint_problem, read_metadata

    if not checkpoint.is_file():
        raise PecliError(f"no checkpoint at {checkpoint}")
    if problem := checkpoint_problem(checkpoint, thorough=True):
        raise PecliError(f"{checkpoint}: {problem}")
    meta = read_metadata(checkpoint)
    _check_network(checkpoint, meta)
    console.print_json(json.dumps(meta.to_dict()))


def _check_network(checkpoint: Path, meta: CheckpointMeta) -> None:
    """Refuse a checkpoint whose weights do not fit the network its metadata describes; where that cannot be
    checked, say so on stderr and refuse only weights that are no network's (not dense finite tensors)."""
    from pecli.models.checkpoint import POLICY_ENTRY, load_policy, read_weights

    scenario = _scenario_of(checkpoint, meta) if meta.policy_kwargs else None
    if scenario is not None:
        load_policy(checkpoint, meta, scenario)  # ZooError: one line naming the first difference
        return
    read_weights(checkpoint, only=(POLICY_ENTRY,))  # ZooError: damaged or pickled weights, in one line
    if not meta.policy_kwargs:
        err_console.print(f"note: {checkpoint} predates network metadata; its network was not checked", highlight=False)
    else:
        err_console.print(
            f"note: the scenario of {checkpoint} ('{meta.scenario}') is not at hand; its network was not checked",
            highlight=False,
        )


def _scenario_of(checkpoint: Path, meta: CheckpointMeta) -> Scenario | None:
    """The scenario ``checkpoint`` was trained on: its run's (:func:`~pecli.policies.registry.stored_scenario`),
    else the built-in scenario of its name if the fingerprint matches; ``None`` otherwise."""
    from pecli.policies.registry import stored_scenario
    from pecli.scenario import builtin_names, load_scenario

    if (scenario := stored_scenario(str(checkpoint))) is not None:
        return scenario
    if meta.scenario in builtin_names():
        scenario = load_scenario(meta.scenario)
        if scenario.fingerprint() == meta.scenario_hash:
            return scenario
    return None


def _is_run(folder: Path) -> bool:
    """Whether ``folder`` is a run folder pecli made."""
    from pecli.zoo import CONFIG_FILE, RUN_MARKS

    return (folder / CONFIG_FILE).is_file() and any((folder / mark).is_file() for mark in RUN_MARKS)


@app.command("rm")
@user_errors
def remove(
    target: Annotated[Path, typer.Argument(help="A run folder or a checkpoint file.")],
    yes: Annotated[bool, typer.Option("--yes", "-y", help="Do not ask for confirmation.")] = False,
) -> None:
    """Delete a run (its folder) or one checkpoint (the zip and its metadata).

    Only what pecli wrote: a run folder (its config.yaml beside a command.txt, run.json or selfplay.json), a
    checkpoint zip (its metadata beside it, a checkpoint's entries inside, or, damaged, in a run's role folder).
    """
    from pecli.locks import locked
    from pecli.zoo import RUN_MARKS, ZooError, checkpoint_problem, metadata_path, read_metadata

    if target.is_dir():
        if not _is_run(target):
            raise PecliError(
                f"{target} is not a pecli run folder (a config.yaml and a {' or '.join(RUN_MARKS)}): "
                "refusing to delete it"
            )
        what = f"run {target} and everything in it"
    elif target.is_file() and target.suffix == ".zip":
        try:
            read_metadata(target)
        except ZooError:
            if checkpoint_problem(target) and not _is_run(target.resolve().parent.parent):
                raise PecliError(f"{target} is not a pecli checkpoint: refusing to delete it") from None
        what = f"checkpoint {target}"
    else:
        raise PecliError(f"nothing to delete at {target} (give a run folder or a checkpoint .zip)")
    if not yes and not typer.confirm(f"Delete {what}?", err=True):
        raise typer.Exit(code=1)
    if target.is_dir():
        with locked(target, f"run '{target.name}'"):  # not while a training writes it
            shutil.rmtree(target)
    else:
        target.unlink()
        metadata_path(target).unlink(missing_ok=True)  # the checkpoint's, damaged or not
    err_console.print(f"deleted {what}", highlight=False)


@app.command("best")
@user_errors
def best(
    role: Annotated[str, typer.Argument(help="pursuer or evader.")],
    zoo: ZooArgument = Path("zoo"),
) -> None:
    """Print the path of the highest-rated checkpoint of ROLE (from the zoo's tournament results).

    A rated checkpoint that is gone, damaged or without its metadata is passed over (with a warning).
    """
    from pecli.tournament import tournament_ratings
    from pecli.zoo import ZooError, checkpoint_problem, read_metadata

    if role not in ("pursuer", "evader"):
        raise PecliError(f"role must be pursuer or evader, not '{role}'")
    rated = [
        r
        for path, r in tournament_ratings(zoo).items()
        if r.get("role") == role and path.endswith(".zip") and Path(path).is_file()
    ]
    if not rated:
        raise PecliError(f"no rated {role} checkpoint in {zoo}: run `pecli tournament {zoo}` first")
    for entry in sorted(rated, key=lambda r: -r["elo"]):
        path = Path(entry["spec"])
        problem = checkpoint_problem(path, thorough=True)
        if not problem:
            try:
                read_metadata(path)
            except ZooError:
                problem = "no readable metadata"
        if not problem:
            typer.echo(path)
            return
        err_console.print(f"[yellow]skipped[/] {path}: {problem}", highlight=False, soft_wrap=True)
    raise PecliError(f"every rated {role} checkpoint in {zoo} is damaged: train or copy them again")


@app.command("rounds")
@user_errors
def rounds(
    run: Annotated[Path, typer.Argument(help="A self-play run's folder.", show_default=False)],
    role: Annotated[RoleChoice, typer.Argument(help="The role whose rounds to mix.", show_default=False)],
    weight: Annotated[
        float | None,
        typer.Option(
            "--weight",
            help="Give each round the weight W/N (N: its number of rounds), so that runs joined into one mix: "
            "string weigh alike however many rounds each hands over. Default: no weights.",
            show_default=False,
        ),
    ] = None,
) -> None:
    """Print the rounds a self-play run hands over the mean of, as one mixed player (a ``mix:`` string).

    What a run hands over, ``ROLE/average.zip``, is one network: the mean of its last rounds' weights. The same
    rounds played as a mixture, each game by one of them, are harder for a best response to exploit and a
    little weaker against fixed opponents (docs/benchmarks/exploitability.md). For example:
    ``pecli exploit "$(pecli zoo rounds zoo/strong pursuer)" --role pursuer -c league``. Runs of several belief
    kinds join into one player, each run drawn in a third of the games:
    ``mix:$(for k in a b c; do pecli zoo rounds zoo/$k pursuer --weight 1 | cut -d: -f2-; done | paste -sd,)``.
    """
    from pecli.policies.mix import check_weight, mix_members
    from pecli.rl.state import handed_over_rounds
    from pecli.zoo import Run

    if not run.is_dir():
        raise PecliError(f"no run at {run}")
    if weight is not None:
        check_weight(weight, "--weight")
    paths, stale = handed_over_rounds(Run(run), role.value)
    share = "" if weight is None else f"@{weight / len(paths):.9g}"
    spec = ",".join(f"{path}{share}" for path in paths)
    mix_members(spec)  # PolicyError in one line for a mixture pecli would refuse (too many, a comma in a path)
    if stale:
        err_console.print(
            f"note: {run}/{role.value}/average.zip is not yet the mean of these rounds "
            f"(`pecli selfplay --name {run.name} --zoo {run.parent} --resume` writes it)",
            highlight=False,
        )
    typer.echo("mix:" + spec)


@app.command("average")
@user_errors
def average(
    checkpoints: Annotated[
        list[Path],
        typer.Argument(
            help="Checkpoints of one network, oldest first; or one folder of a run's rounds (e.g. RUN/pursuer).",
            show_default=False,
        ),
    ],
    last: Annotated[int, typer.Option("--last", min=1, help="With a folder: average its newest N rounds.")] = 10,
    out: Annotated[
        Path | None,
        typer.Option(
            "--out",
            "-o",
            help="The checkpoint to write (default, with a folder: "
            "FOLDER/average-A-B.zip, A and B its first and last round).",
        ),
    ] = None,
) -> None:
    """Write a checkpoint whose weights are the mean of CHECKPOINTS' (weight averaging over a run's last rounds).

    A self-play learner's policy moves from round to round; the mean of its last rounds' weights plays more
    robustly than any one of them, at no training cost (docs/benchmarks/strength.md). The result plays like any
    checkpoint.
    """
    from pecli.rl.averaging import average_checkpoints
    from pecli.rl.selfplay import round_of

    if len(checkpoints) == 1 and checkpoints[0].is_dir():
        folder = checkpoints[0]
        rounds = sorted((path for path in folder.glob("*.zip") if round_of(path) is not None), key=round_of)
        if len(rounds) < last:
            raise PecliError(f"{folder}: {len(rounds)} round checkpoints, fewer than --last {last}")
        checkpoints = rounds[-last:]
        out = out or folder / f"average-{round_of(checkpoints[0]):03d}-{round_of(checkpoints[-1]):03d}.zip"
    for path in checkpoints:
        if not path.is_file():
            raise PecliError(f"no checkpoint at {path}")
    if out is None:
        raise PecliError("give --out: the checkpoint to write")
    if out.suffix != ".zip":
        raise PecliError(f"--out {out}: a checkpoint is a .zip file")
    if any(out.resolve() == path.resolve() for path in checkpoints):
        raise PecliError(f"--out {out} is one of the checkpoints averaged")
    meta = average_checkpoints(checkpoints, out)
    err_console.print(
        f"wrote {out}: the mean of {len(checkpoints)} {meta.role} checkpoints "
        f"({checkpoints[0].name} .. {checkpoints[-1].name})",
        highlight=False,
    )


@app.command("fork")
@user_errors
def fork(
    run: Annotated[Path, typer.Argument(help="The stopped self-play run to copy.", show_default=False)],
    to: Annotated[Path, typer.Option("--to", help="The zoo the copy goes into.", show_default=False)],
    add: Annotated[
        list[str] | None,
        typer.Option("--add", help="A scripted player that joins the copy's pools (repeat for several)."),
    ] = None,
) -> None:
    """Copy a stopped self-play run whole into another zoo, to train on as one arm of an A/B (the original, trained
    on alike, is the control). [bold]--add[/] puts scripted players into its pools, as the ones a run starts with."""
    from pecli.rl.fork import fork_run, run_cpu_hours

    target = fork_run(run, to, add or [])
    added = f", with {', '.join(add)} in its pools" if add else ""
    console.print(
        f"{target}: a copy of {run} at {run_cpu_hours(target):.2f} CPU-h{added}", highlight=False, markup=False
    )


@app.command("generations")
@user_errors
def generations(
    run: Annotated[Path, typer.Argument(help="A self-play run folder.", show_default=False)],
    episodes: Annotated[int, typer.Option("--episodes", "-n", min=1, help="Games per seed and pairing.")] = 200,
    seeds: Annotated[int, typer.Option("--seeds", min=1, help="Seeds per pairing (0 .. K-1).")] = 1,
    workers: Annotated[int, typer.Option("--workers", "-w", min=1, help="Processes playing pairings.")] = 1,
    every: Annotated[
        int, typer.Option("--every", min=1, help="Every K-th round only, counted back from the last (a long run).")
    ] = 1,
    as_json: Annotated[bool, typer.Option("--json", help="Print the matrix and the progress as JSON.")] = False,
) -> None:
    """Play a self-play run's generations against each other: every round's pursuer against every round's evader,
    pure pursuit and the greedy evader as generation 0.

    Prints the capture-rate matrix and two progress shares: how often, of two pursuers trained after an evader,
    the later one catches it more (and likewise for evaders escaping older pursuers). Above 0.5 the run improves on
    what it has met; near 0.5 it goes round in circles. The games are cached in RUN/generations, with the matrix as
    RUN/generations/generations.png.
    """
    from pecli.cli.common import require_batch
    from pecli.rl.generations import GENERATIONS_DIR, draw_heatmap, round_robin
    from pecli.zoo import RUN_MARKS, Run

    require_batch(episodes, "add --seeds instead")
    if not _is_run(run):
        raise PecliError(f"{run} is not a run folder (a config.yaml and a {' or '.join(RUN_MARKS)})")
    scenario = Run(run).scenario()
    result = round_robin(
        run,
        scenario,
        episodes,
        list(range(seeds)),
        workers,
        on_result=lambda line: err_console.print(line, highlight=False, markup=False),
        every=every,
    )
    pursuer, evader = result.progress()
    picture = draw_heatmap(
        result,
        run / GENERATIONS_DIR / "generations.png",
        f"{run.name}: capture rate, generation against generation ({episodes * seeds} games a cell)",
    )
    if as_json:
        data = {
            "run": str(run),
            "episodes": episodes * seeds,
            "pursuers": result.labels["pursuer"],
            "evaders": result.labels["evader"],
            "capture_rates": result.rates.round(4).tolist(),
            "pursuer_progress": None if math.isnan(pursuer) else pursuer,
            "evader_progress": None if math.isnan(evader) else evader,
            "picture": str(picture),
        }
        console.print_json(json.dumps(data))
        return
    table = Table(title=f"{run.name}: capture rate, pursuer generation (rows) against evader generation")
    table.add_column("")
    for label in result.labels["evader"]:
        table.add_column(label, justify="right")
    for label, row in zip(result.labels["pursuer"], result.rates):
        table.add_row(label, *(f"{value:.2f}" for value in row))
    console.print(table)

    def shown(value: float) -> str:
        return "- (too few generations)" if math.isnan(value) else f"{value:.2f}"

    console.print(
        f"later pursuers catch older evaders more often than earlier pursuers did: {shown(pursuer)} of pairs\n"
        f"later evaders escape older pursuers more often than earlier evaders did: {shown(evader)} of pairs\n"
        f"(above 0.5: progress; near 0.5: cycling)   picture: {picture}",
        highlight=False,
        markup=False,
    )
