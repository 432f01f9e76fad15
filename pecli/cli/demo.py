"""``pecli demo``: the main job end to end on a small scenario, in a few CPU-minutes."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer
from rich.markup import escape
from rich.table import Table

from pecli.cli.common import console, err_console, sigterm_stops, user_errors


@user_errors
def demo(
    out: Annotated[Path, typer.Option("--out", "-o", help="Where the run and the pictures go.")] = Path("runs/demo"),
    cpu_minutes: Annotated[
        float, typer.Option("--cpu-minutes", help="Training's CPU budget.", min=0.1, max=600.0)
    ] = 1.5,
    episodes: Annotated[int, typer.Option("--episodes", "-n", help="Games per match.", min=1, max=100_000)] = 500,
    seed: Annotated[int, typer.Option("--seed", "-s", min=0, max=2**32 - 1, help="Seed of everything.")] = 0,
) -> None:
    """Train a pursuer, measure it beside pure pursuit, export it to ONNX and draw it.

    A pursuer learns against the greedy evader in the small [bold]quick[/] arena (8 m × 8 m, T = 150) with the
    tuned training settings, for [bold]--cpu-minutes[/]; then it and the paper's pure-pursuit pursuer play the
    paper's scripted evaders from the same start states; the ONNX export plays greedy again; one episode is
    drawn as a GIF and eight as a PNG. Replaces an earlier demo in [bold]--out[/].
    """
    from pecli.demo import BASELINE, run_demo
    from pecli.rl.train import TrainingInterrupted

    try:
        with sigterm_stops():
            result = run_demo(
                out,
                cpu_minutes=cpu_minutes,
                episodes=episodes,
                seed=seed,
                progress=err_console.is_terminal,
                report=lambda line: err_console.print(line, markup=False, highlight=False),
            )
    except (TrainingInterrupted, KeyboardInterrupt):
        err_console.print("[yellow]interrupted[/]: the demo starts again from scratch when run again", highlight=False)
        raise typer.Exit(code=130) from None
    table = Table(title=f"capture rate over {episodes} games, the same start states in each row")
    table.add_column("evader")
    table.add_column(f"trained pursuer ({result.cpu_seconds / 60:.1f} CPU-min)", justify="right")
    table.add_column(f"{BASELINE} (the paper's baseline)", justify="right")
    for row in result.rows:
        table.add_row(row.evader, f"{row.trained:.3f}", f"{row.baseline:.3f}")
    console.print(table)
    greedy = next(row.trained for row in result.rows if row.evader == "greedy")
    exported = (
        f"the ONNX export against greedy: {result.export_capture:.3f} (the checkpoint: {greedy:.3f}), "
        f"{escape(str(result.export))}\n"
        if result.export is not None
        else ""
    )
    console.print(
        f"{exported}checkpoint {escape(str(result.checkpoint))}\n"
        f"pictures {', '.join(escape(str(p)) for p in result.pictures)}\n"
        f"play it yourself: pecli play -p {escape(str(result.checkpoint))} -e rash -c quick",
        highlight=False,
    )
