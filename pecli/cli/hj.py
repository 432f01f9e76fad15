"""``pecli hj``: solve the point-mass game by dynamic programming, inspect solutions, print Table II."""

from __future__ import annotations

import json
from enum import Enum
from pathlib import Path
from typing import Annotated

import typer
from rich.markup import escape
from rich.table import Table

from pecli.cli.common import console, err_console, user_errors
from pecli.errors import PecliError
from pecli.progress import WorkProgress

app = typer.Typer(
    help="Hamilton–Jacobi baseline: solve the point-mass game, inspect solutions, print Table II.",
    no_args_is_help=True,
)


class HJModel(str, Enum):
    """The state space of the solved game (pecli.hj.grid.MODELS)."""

    abs8d = "abs8d"
    rel4d = "rel4d"
    rel6d = "rel6d"


class HJOrder(str, Enum):
    """Who answers whom within a step (pecli.hj.problem.ORDERS)."""

    maxmin = "maxmin"
    minmax = "minmax"


class HJBackend(str, Enum):
    """The solver (pecli.hj.problem.BACKENDS)."""

    numpy = "numpy"
    hj_reachability = "hj-reachability"


HJ_CONFIG_HELP = "Scenario with two point masses: a YAML file or a built-in name (point_mass)."
GridOption = Annotated[
    str | None,
    typer.Option(
        "--grid",
        "-g",
        help="Nodes per position axis and per velocity axis, e.g. 15,5 "
        "(default: abs8d 15,5; rel4d 81,21; rel6d 41,11).",
    ),
]
ModelOption = Annotated[
    HJModel | None,
    typer.Option(
        "--model",
        "-m",
        help="abs8d (both players in the arena, with its walls; the default), rel4d "
        "(relative position and velocity, open plane) or rel6d (relative position, both velocities).",
    ),
]
OrderOption = Annotated[
    HJOrder,
    typer.Option("--order", help="maxmin (the pursuer answers the evader's input) or minmax (the evader answers)."),
]


def _problem(
    config: str, model: HJModel | None, grid: str | None, order: HJOrder, steps: int | None, backend: HJBackend
):
    from pecli.hj.grid import DEFAULT_MODEL, parse_sizes
    from pecli.hj.problem import Problem
    from pecli.scenario import load_scenario

    if model is None:  # hj-reachability solves rel4d only
        name = "rel4d" if backend is HJBackend.hj_reachability else DEFAULT_MODEL
    else:
        name = model.value
    scenario = load_scenario(config)
    sizes = parse_sizes(grid) if grid is not None else None
    return scenario, Problem.for_scenario(
        scenario,
        name,
        sizes,
        order.value,
        steps,
        backend.value,  # type: ignore[arg-type]
    )


@app.command("solve")
@user_errors
def solve(
    config: Annotated[str, typer.Option("--config", "-c", help=HJ_CONFIG_HELP)] = "point_mass",
    model: ModelOption = None,
    grid: GridOption = None,
    order: OrderOption = HJOrder.maxmin,
    steps: Annotated[
        int | None, typer.Option("--steps", help="Horizon in game steps (default: the scenario's T).")
    ] = None,
    out: Annotated[
        Path | None, typer.Option("--out", "-o", help="Solution file (.npz); default: the cache (see `pecli hj list`).")
    ] = None,
    force: Annotated[
        bool, typer.Option("--force", help="Solve again even if a solution with the same key exists.")
    ] = False,
    backend: Annotated[
        HJBackend,
        typer.Option(
            "--backend",
            help="numpy (the game's discrete time) or hj-reachability (JAX, continuous "
            'time, rel4d; pip install "hj-reachability>=0.7").',
        ),
    ] = HJBackend.numpy,
    as_json: Annotated[bool, typer.Option("--json", help="Print the solution's summary as JSON.")] = False,
) -> None:
    """Solve the point mass vs point mass game on a grid and keep the value function.

    The solution is keyed by a hash of everything that decides it (the game's numbers, model, grid,
    order, horizon, backend, solver version): the same command again reuses it, any change solves anew.
    Play it with [bold]-p hj[/] / [bold]-e hj[/] (the default solution in the cache) or [bold]hj:FILE.npz[/].
    """
    from pecli.hj.cache import solve_cached

    if out is not None and out.suffix != ".npz":
        raise PecliError(f"--out must end in .npz, got '{out.name}'")
    scenario, problem = _problem(config, model, grid, order, steps, backend)
    err_console.print(f"{scenario.name}: {problem.describe()} ({problem.grid.size:,} nodes)", highlight=False)
    with WorkProgress("solving", problem.steps, err_console, unit="steps", enabled=not as_json) as progress:
        solution, path, reused = solve_cached(
            problem,
            scenario.name,
            out=out,
            force=force,
            on_step=lambda done, total: progress.update(done),
        )
    if as_json:
        typer.echo(json.dumps({**solution.summary(), "path": str(path), "reused": reused}))
        return
    if reused:
        err_console.print(f"reused {path} (nothing changed; --force solves again)", highlight=False)
    else:
        err_console.print(f"solved in {solution.meta['seconds']:.1f} s, wrote {path}", highlight=False)
    console.print(f"play it with: {_policy_string(problem, path, out, scenario.horizon)}", highlight=False)


def _policy_string(problem, path: Path, out: Path | None, horizon: int) -> str:
    from pecli.hj.grid import DEFAULT_MODEL, DEFAULT_SIZES
    from pecli.hj.problem import DEFAULT_ORDER

    default = (
        problem.sizes == DEFAULT_SIZES[problem.model]
        and problem.order == DEFAULT_ORDER
        and problem.backend == "numpy"
        and out is None
        and problem.steps == horizon
    )
    if default:
        return "hj" if problem.model == DEFAULT_MODEL else f"hj:model={problem.model}"
    return f"hj:{path}"


@app.command("show")
@user_errors
def show(
    solution: Annotated[
        Path | None, typer.Argument(help="A solution file (.npz); default: the cached default solution of --config.")
    ] = None,
    config: Annotated[str, typer.Option("--config", "-c", help=HJ_CONFIG_HELP)] = "point_mass",
    model: ModelOption = None,
) -> None:
    """Print a solution's problem, key and capture share as JSON."""
    from pecli.hj.cache import cache_path
    from pecli.hj.grid import DEFAULT_MODEL
    from pecli.hj.problem import Problem
    from pecli.hj.solution import Solution
    from pecli.scenario import load_scenario

    if solution is None:
        name = DEFAULT_MODEL if model is None else model.value
        solution = cache_path(Problem.for_scenario(load_scenario(config), name))  # type: ignore[arg-type]
        if not solution.is_file():
            flag = "" if name == DEFAULT_MODEL else f" --model {name}"
            raise PecliError(
                f"no cached {name} solution for {config}: run `pecli hj solve --config {config}{flag}` first"
            )
    console.print_json(json.dumps({**Solution.load(solution).summary(), "path": str(solution)}))


@app.command("list")
@user_errors
def list_cache(
    folder: Annotated[Path | None, typer.Argument(help="Folder of solutions (default: the cache).")] = None,
) -> None:
    """List cached solutions: scenario, model, grid, order, horizon, backend, solve time, file."""
    from pecli.hj.cache import cache_dir
    from pecli.hj.solution import Solution, SolutionError

    if folder is not None and not folder.is_dir():
        raise PecliError(f"no folder {folder}")
    folder = cache_dir() if folder is None else folder
    files = sorted(folder.glob("*.npz")) if folder.is_dir() else []
    if not files:
        console.print(f"{folder}: no HJ solutions yet (make one with `pecli hj solve`)", highlight=False)
        return
    table = Table(title=f"HJ solutions in {folder}")
    for column in ("scenario", "model", "grid", "order", "T", "backend", "seconds", "file"):
        table.add_column(
            column,
            justify="right" if column in ("T", "seconds") else "left",
            overflow="fold" if column == "file" else "ellipsis",
        )
    for path in files:
        try:
            s = Solution.load(path)
        except SolutionError as exc:
            table.add_row("", "", "", "", "", "", "", f"{escape(path.name)} [red]({escape(str(exc))})[/]")
            continue
        table.add_row(
            str(s.meta.get("scenario", "")),
            s.grid.model,
            s.grid.describe(),
            s.problem.order,
            str(s.problem.steps),
            s.problem.backend,
            f"{s.meta.get('seconds', 0):.1f}",
            path.name,
        )
    console.print(table)


@app.command("table")
@user_errors
def table(
    results: Annotated[Path, typer.Argument(help="A tournament's results.json (or its folder).")],
) -> None:
    """Print a tournament's results in the layout of the paper's Table II, next to the paper's numbers.

    Evaders are rows; for every pursuer, the normalised time-to-capture (σ) and the capture rate.
    HJ players are called "optimal control", as in the paper.
    """
    from pecli.reports import paper_table_two, table_two
    from pecli.tournament import read_results

    record = read_results(results)
    if not record.pairings:
        raise PecliError(f"{results}: a tournament's results without pairings")
    console.print(table_two(record))
    console.print(paper_table_two())
