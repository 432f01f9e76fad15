"""``pecli experiment run|show|status|report|exploit|compare``: a whole reproduction (train, rank, tournament, report)
from one experiment file, executed on Ray, and best responses to its players."""

from __future__ import annotations

import socket
from contextlib import ExitStack
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer
from rich.live import Live
from rich.table import Table

from pecli.cli.common import (
    PlayersConfigOption,
    console,
    err_console,
    require_batch,
    require_positive,
    scenario_for,
    sigterm_stops,
    user_errors,
)
from pecli.cli.exploit import CpuMinutesOption, StepsOption, budget_settings, responses_stop
from pecli.errors import PecliError
from pecli.locks import locked
from pecli.scenario import builtin_experiments
from pecli.text import plural

if TYPE_CHECKING:
    from pecli.experiment.folder import RunStatus

app = typer.Typer(
    help="Reproduce the paper's tables with one command: a grid of runs, the paper's ranking, the final "
    "tournament and the report, on Ray (embedded on this machine, or a cluster).",
    no_args_is_help=True,
)

STATUS_STYLE = {
    "done": "green",
    "running": "cyan",
    "failed": "red",
    "stopped": "yellow",
    "paused": "yellow",
    "queued": "dim",
    "pending": "dim",
}


def _minutes(seconds: float) -> str:
    return f"{seconds / 60:.1f} min" if seconds else "-"


def progress_line(rows: list[RunStatus]) -> str:
    """``8/15 runs done, 3.93 CPU-hours of training; about 2.6 CPU-hours left, ...``: the estimate takes
    each unfinished run to need what the finished runs of its kind and schedule took."""
    from pecli.experiment.runs import training_left

    done = sum(row.progress.done for row in rows)
    cpu = sum(row.progress.cpu_seconds for row in rows)
    left, unknown = training_left([(row.run, row.progress) for row in rows])
    estimate = ""
    if done < len(rows) and unknown < len(rows) - done:
        estimate = f"; about {left / 3600:.1f} CPU-hours left, by the finished runs of each kind" + (
            f" ({unknown} runs of kinds not finished yet not counted)" if unknown else ""
        )
    return f"{done}/{len(rows)} runs done, {cpu / 3600:.2f} CPU-hours of training{estimate}"


def rounds_per_cpu_hour(row: RunStatus) -> str:
    """A self-play run's rounds per CPU-hour so far (``-`` before its first round): what a kind costs."""
    p = row.progress
    return f"{p.round / (p.cpu_seconds / 3600):.0f}" if p.rounds and p.round and p.cpu_seconds > 0 else "-"


def runs_table(rows: list[RunStatus], title: str) -> Table:
    """One row per run: kind, seed, schedule (when the grid has several), round, transitions, CPU time, rounds
    per CPU-hour (self-play), status, and the host it runs on (when another machine ran any); below it,
    :func:`progress_line`."""
    schedules = len({row.run.schedule for row in rows}) > 1
    selfplay = any(row.progress.rounds for row in rows)
    hosts = any(row.host not in ("", socket.gethostname()) for row in rows)
    table = Table(title=title, title_justify="left", caption=progress_line(rows), caption_justify="left")
    table.add_column("run", no_wrap=True)
    table.add_column("kind", no_wrap=True)
    table.add_column("seed", justify="right")
    if schedules:
        table.add_column("schedule", no_wrap=True)
    for column in ("round", "steps", "CPU time", *(["rounds/CPU-h"] if selfplay else [])):
        table.add_column(column, justify="right", no_wrap=True)
    table.add_column("status", overflow="fold", min_width=7)
    if hosts:
        table.add_column("host", no_wrap=True)
    for row in rows:
        p = row.progress
        where = (
            f"{p.round}/{p.rounds}" + (f" {p.role}" if p.role and row.status == "running" else "") if p.rounds else "-"
        )
        status = f"[{STATUS_STYLE.get(row.status, '')}]{row.status}[/]"
        if row.error:
            status += f": {row.error}"
        cells = [
            row.run.name,
            row.run.kind,
            str(row.run.seed),
            *([row.run.schedule] if schedules else []),
            where,
            f"{p.steps:,}",
            _minutes(p.cpu_seconds),
            *([rounds_per_cpu_hour(row)] if selfplay else []),
            status,
            *([row.host] if hosts else []),
        ]
        table.add_row(*cells)
    return table


@app.command()
@user_errors
def run(
    experiment: Annotated[
        str,
        typer.Argument(
            help=f"A built-in experiment ({', '.join(builtin_experiments())}) or a YAML file.", show_default=False
        ),
    ],
    address: Annotated[
        str | None,
        typer.Option(
            "--address",
            help="Join a running Ray cluster: auto, HOST:PORT or ray://HOST:PORT "
            "(default: start Ray on this machine). Every node must see --out at the same path.",
        ),
    ] = None,
    cpus: Annotated[
        int | None, typer.Option("--cpus", help="Workers of the embedded Ray (default: all cores).")
    ] = None,
    out: Annotated[
        Path | None,
        typer.Option(
            "--out",
            "-o",
            help="The experiment's folder (default: runs/experiments/<name>); run again on it to continue.",
        ),
    ] = None,
    quiet: Annotated[bool, typer.Option("--quiet", "-q", help="No live table.")] = False,
    until_cpu_hours: Annotated[
        float | None,
        typer.Option(
            "--until-cpu-hours",
            help="Train each self-play run only until it has used this many CPU-hours (at most its own "
            "budget); while any run is short of its own budget, stop before the ranking: every run at "
            "an equal budget first.",
        ),
    ] = None,
) -> None:
    """Run an experiment: train its runs, rank their checkpoints, play the tournament, write the report.

    The report (Markdown, JSON, PNG) and everything else go to [bold]--out[/]. Each run is one Ray
    task holding one CPU; the tournaments' pairings are Ray tasks too. Interrupted (Ctrl-C, a killed
    driver, a lost worker), it continues with the same command: finished runs and played pairings are
    kept, unfinished runs continue from their last checkpoint.

    On a machine smaller than the grid, [bold]--until-cpu-hours 1[/] brings every run to one CPU-hour
    before any goes further, so that all can be compared at that budget ([bold]pecli experiment status[/]
    shows where each run stands); run again with a larger value, or without it, to go on.
    """
    from pecli.experiment import ExperimentRunner, RayCluster, load_experiment

    loaded = load_experiment(experiment)
    out = out or Path("runs/experiments") / loaded.name
    live = (
        Live(console=err_console, refresh_per_second=2, transient=False, auto_refresh=True)
        if not quiet and err_console.is_terminal
        else None
    )
    title = f"experiment {loaded.name} in {out}"
    last_stage = ""

    def update(rows: list[RunStatus], stage: str) -> None:
        nonlocal last_stage
        if live is not None:
            live.update(runs_table(rows, f"{title}: {stage}"))
        elif stage.split(" ")[0] != last_stage:
            err_console.print(f"{loaded.name}: {stage.split(' ')[0]}", highlight=False)
        last_stage = stage.split(" ")[0]

    runner = ExperimentRunner(loaded, out, on_update=update, until_cpu_hours=until_cpu_hours)
    again = f"pecli experiment run {experiment} --out {out}" + (f" --address {address}" if address else "")
    cluster = RayCluster(address=address, cpus=cpus)  # refuses bad --cpus/--address before anything is written
    out.mkdir(parents=True, exist_ok=True)
    stack = ExitStack()
    stack.enter_context(locked(out, "experiment output"))  # one driver per --out, however the other one started
    stack.enter_context(sigterm_stops())  # SIGTERM stops like Ctrl-C; the handler before comes back at the end
    try:
        runner.prepare()  # refuses another experiment's --out before Ray starts
        if live is not None:
            live.start()
        with cluster:
            where = (
                f"embedded Ray, {plural(cluster.total_cpus(), 'CPU')}"
                if cluster.embedded
                else f"Ray cluster {address}: {plural(cluster.nodes(), 'node')}, {plural(cluster.total_cpus(), 'CPU')}"
            )
            err_console.print(
                f"experiment [bold]{loaded.name}[/]: {len(runner.rows)} runs on {where}; output in {out}",
                highlight=False,
            )
            report = runner.run(cluster)
    except KeyboardInterrupt:
        if live is not None:
            live.stop()
        err_console.print(
            f"[yellow]interrupted[/]: finished runs and pairings are saved, unfinished runs continue "
            f"from their last checkpoint: {again}",
            highlight=False,
        )
        raise typer.Exit(code=130) from None
    finally:
        if live is not None:
            live.stop()
        stack.close()
    session = runner.session
    err_console.print(
        f"runs: {session.runs_started} started, {session.runs_resumed} resumed, {session.runs_skipped} "
        f"finished before; pairings: {session.pairings_played} played, {session.pairings_cached} cached",
        highlight=False,
    )
    if report is None:  # paused at --until-cpu-hours
        if live is None:
            console.print(runs_table(runner.rows, f"experiment {loaded.name} in {out}"))
        err_console.print(
            f"[yellow]paused[/]: every self-play run has trained to {until_cpu_hours:g} CPU-h or "
            f"its own budget; the ranking waits for all of them: {again} [--until-cpu-hours H]",
            highlight=False,
        )
        return
    _print_report(out)
    err_console.print(f"wrote {report}, {out / 'report.json'}, {out / 'table.png'}", highlight=False)


@app.command()
@user_errors
def show(
    experiment: Annotated[
        str,
        typer.Argument(
            help=f"A built-in experiment ({', '.join(builtin_experiments())}) or a YAML file.", show_default=False
        ),
    ],
) -> None:
    """Print an experiment as it will run (a base it extends merged in), its fingerprint and its runs;
    trains nothing."""
    import yaml

    from pecli.experiment import load_experiment

    loaded = load_experiment(experiment)
    typer.echo(yaml.safe_dump(loaded.spec.model_dump(mode="json"), sort_keys=False, width=120), nl=False)
    runs = loaded.runs()
    typer.echo(f"fingerprint {loaded.spec.fingerprint()}; {len(runs)} runs: {', '.join(r.name for r in runs)}")


@app.command()
@user_errors
def status(
    out: Annotated[Path, typer.Argument(help="The experiment's folder (its --out).", show_default=False)],
) -> None:
    """Show every run of an experiment (kind, seed, round, CPU time, status) and its stages."""
    from pecli.experiment.folder import (
        driver_alive,
        open_experiment,
        read_state,
        stage_lines,
        statuses,
    )

    loaded = open_experiment(out)
    state = read_state(out)
    rows = statuses(loaded, out)
    alive = driver_alive(state)
    console.print(runs_table(rows, f"experiment {loaded.name} in {out}" + (" (running)" if alive else "")))
    for line in stage_lines(out, state, alive):
        console.print(line, highlight=False)
    if state.get("stages", {}).get("report") == "done":
        console.print(f"report: {out / 'report.md'}", highlight=False)


@app.command()
@user_errors
def report(
    out: Annotated[Path, typer.Argument(help="The experiment's folder (its --out).", show_default=False)],
) -> None:
    """Write the experiment's report again (report.md, report.json, table.png) and print its table."""
    from pecli.experiment.report import write_report

    paths = write_report(out)
    _print_report(out)
    err_console.print("wrote " + ", ".join(str(p) for p in paths), highlight=False)


@app.command()
@user_errors
def exploit(
    out: Annotated[Path, typer.Argument(help="The experiment's folder (its --out).", show_default=False)],
    cpu_minutes: CpuMinutesOption = None,
    steps: StepsOption = None,
    seeds: Annotated[int, typer.Option("--seeds", help="Best responses per start and side (seeds 0 .. K-1).")] = 3,
    warm: Annotated[
        bool, typer.Option("--warm", help="Also warm-start each response from the run's own player of its role.")
    ] = False,
    episodes: Annotated[
        int, typer.Option("--episodes", "-n", help="Held-out games each response plays against the player.")
    ] = 500,
    mixtures: Annotated[
        bool,
        typer.Option(
            "--mixtures",
            help="Also each group's seeds as one pair of uniform mixtures (mix:...), into OUT/exploit/GROUP-mixed.",
        ),
    ] = False,
    only_mixtures: Annotated[
        bool,
        typer.Option(
            "--only-mixtures",
            help="No run one by one: each group's mixed pair alone (the cheaper), or with --populations the "
            "populations alone (add --mixtures for both).",
        ),
    ] = False,
    populations: Annotated[
        bool,
        typer.Option(
            "--populations",
            help="Also each seed's runs of every kind (under one schedule) as one pair of uniform mixtures, into "
            "OUT/exploit/population-<schedule>-s<seed>.",
        ),
    ] = False,
    workers: Annotated[
        int,
        typer.Option(
            "--workers", "-w", help="Responses trained at once, each in its own process (each keeps its budget)."
        ),
    ] = 1,
) -> None:
    """Best responses to every run's kept pursuer and evader, then the report again with each run's NashConv.

    For each run: evaders trained on its pursuer alone and pursuers trained on its evader alone (as
    [bold]pecli exploit --pair[/]), into OUT/exploit/RUN. With [bold]--mixtures[/], then each group's seeds
    played as one mixed player (each game one seed's, drawn uniformly): a mixture is harder to exploit than
    any of its members; [bold]--only-mixtures[/] measures those alone, a third of the cost with three seeds.
    [bold]--populations[/] also mixes each seed's runs of every kind (the population one seed of the grid
    trained, as diverse as the grid's kinds); with [bold]--only-mixtures[/], those alone.
    Each response trains [bold]--cpu-minutes[/] or [bold]--steps[/] transitions; [bold]--workers[/] trains
    that many at once; stopping is safe and the same command continues.
    """
    from pecli.experiment.exploit import exploit_experiment
    from pecli.experiment.report import write_report

    require_batch(episodes, "play fewer")
    require_positive(seeds, "--seeds")
    require_positive(workers, "--workers")
    settings = {**budget_settings(cpu_minutes, steps), "seeds": tuple(range(seeds)), "episodes": episodes}

    def report(line: str) -> None:
        err_console.print(line, highlight=False, markup=False)

    with responses_stop():
        exploit_experiment(
            out,
            report,
            warm=warm,
            mixtures=mixtures or (only_mixtures and not populations),
            runs=not only_mixtures,
            populations=populations,
            workers=workers,
            **settings,
        )
    paths = write_report(out)
    err_console.print("wrote " + ", ".join(str(p) for p in paths), highlight=False)


def _print_report(out: Path) -> None:
    from pecli.experiment.report import ExperimentReport
    from pecli.reports import TABLE_WIDTH, results_tables

    for table in results_tables(ExperimentReport(out).grouped_results(), min(console.width, TABLE_WIDTH)):
        console.print(table)


@app.command()
@user_errors
def compare(
    arms: Annotated[
        list[str],
        typer.Option(
            "--arms",
            help="LABEL=ZOO for each arm, the control first (repeat, or one arm for a zoo's strength table).",
            show_default=False,
        ),
    ],
    config: PlayersConfigOption = None,
    episodes: Annotated[int, typer.Option("--episodes", "-n", min=1, help="Games per pairing.")] = 500,
    cpu_hours: Annotated[
        float | None,
        typer.Option(
            "--cpu-hours", help="Every run at this CPU budget (default: each run's newest round).", show_default=False
        ),
    ] = None,
    at_round: Annotated[
        int | None,
        typer.Option(
            "--round",
            min=1,
            help="Every run after this many rounds (equal transitions per main learner, not CPU).",
            show_default=False,
        ),
    ] = None,
    average: Annotated[
        int,
        typer.Option(
            "--average",
            min=1,
            help="Each run's players as the mean of the weights of its last K finished rounds there, both roles "
            "(a run with fewer is left out; 1: the round's own checkpoints).",
        ),
    ] = 1,
    out: Annotated[Path, typer.Option("--out", "-o", help="Where the games are cached.")] = Path("runs/compare"),
    workers: Annotated[int, typer.Option("--workers", "-w", min=1, help="Processes that play the pairings.")] = 2,
) -> None:
    """An A/B of zoos of the same self-play runs at an equal budget.

    Each arm's pursuers play the scripted evaders and the evaders of every other run of every arm; each arm is
    pooled against the first (z-test over games) and per run (paired t-test). Runs pair by name (belief kind,
    schedule, seed), e.g. a control and its copy by `pecli zoo fork` trained on with other settings. Last, every
    target of the league recipe that a run misses.
    """
    import math

    from pecli.experiment.compare import LEAGUE_TARGETS, compare_arms, main_players
    from pecli.roles import ROLES

    if cpu_hours is not None and at_round is not None:
        raise PecliError("give --cpu-hours or --round, not both")
    if cpu_hours is not None and not (math.isfinite(cpu_hours) and cpu_hours > 0):
        raise PecliError("--cpu-hours must be a number of hours above 0")
    zoos: dict[str, Path] = {}
    for entry in arms:
        label, _, zoo = entry.partition("=")
        if not label or not zoo or label in zoos:
            raise PecliError(f"--arms {entry}: give each arm as LABEL=ZOO, with labels of their own")
        if not Path(zoo).is_dir():
            raise PecliError(f"--arms {entry}: {zoo} is not a folder")
        zoos[label] = Path(zoo)
    picked = {
        label: main_players(
            zoo,
            cpu_hours,
            at_round,
            average=average,
            averaged=ROLES,
            report=lambda line: err_console.print(line, highlight=False),
        )
        for label, zoo in zoos.items()
    }
    run_folders = [str(zoos[label] / name) for label, runs in picked.items() for name in runs]
    scenario = scenario_for(run_folders, config, folders=True)  # the runs' own (an average has no run beside it)
    result = compare_arms(picked, scenario, out, episodes=episodes, workers=workers)
    budget = (
        f"{cpu_hours:g} CPU-h" if cpu_hours is not None else f"round {at_round}" if at_round else "the newest round"
    )
    console.print(f"at {budget}", highlight=False)
    for line in result.lines():
        console.print(line, highlight=False)
    missed = result.missed()
    console.print(
        f"\nthe league recipe's targets ({LEAGUE_TARGETS.describe()}): "
        + ("every one met" if not missed else f"{len(missed)} missed\n- " + "\n- ".join(missed)),
        highlight=False,
    )
