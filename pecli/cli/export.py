"""``pecli export onnx|check``: a checkpoint as an ONNX graph for a robot, and its parity check."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Annotated

import typer
from rich.table import Table

from pecli.cli.common import (
    console,
    err_console,
    one_torch_thread,
    require_positive,
    user_errors,
)
from pecli.errors import PecliError

app = typer.Typer(
    help="Export a checkpoint to ONNX for a robot (SI units in and out) and check it against the checkpoint.",
    no_args_is_help=True,
)

EpisodesOption = Annotated[int, typer.Option("--episodes", "-n", help="Recorded games the parity check replays.")]
SeedOption = Annotated[int, typer.Option("--seed", "-s", min=0, help="Seed of the recorded games.")]
JsonOption = Annotated[bool, typer.Option("--json", help="Print the result as one JSON object.")]


def _report_table(title: str, parity: dict) -> Table:
    table = Table(title=title)
    for column in ("episodes", "steps", "opponent", "max Δ action", "max Δ command", "tolerance", "parity"):
        table.add_column(column, justify="left" if column == "opponent" else "right")
    verdict = "[green]ok[/]" if parity["passed"] else "[red]FAILED[/]"
    if parity["non_finite"]:
        verdict += f" ({parity['non_finite']} NaN/inf)"
    table.add_row(
        str(parity["episodes"]),
        str(parity["steps"]),
        parity["opponent"],
        f"{parity['max_action_difference']:.2e}",
        f"{parity['max_command_difference']:.2e}",
        f"{parity['tolerance']:g}",
        verdict,
    )
    return table


@app.command("onnx")
@user_errors
def export_onnx(
    checkpoint: Annotated[Path, typer.Argument(help="A zoo checkpoint (.zip with its metadata).", show_default=False)],
    out: Annotated[
        Path | None, typer.Option("--out", "-o", help="The model file (default: beside the checkpoint, .onnx).")
    ] = None,
    opset: Annotated[
        int, typer.Option("--opset", help="ONNX opset version (13 to the newest the installed torch writes).")
    ] = 17,  # graph.DEFAULT_OPSET
    config: Annotated[
        str | None,
        typer.Option("--config", "-c", help="The scenario it was trained on (default: its run's config.yaml)."),
    ] = None,
    episodes: EpisodesOption = 8,
    seed: SeedOption = 0,
    as_json: JsonOption = False,
) -> None:
    """Export CHECKPOINT to one ONNX graph (normalisation, belief, actor, action scaling) and a sidecar JSON.

    The graph takes the state estimates in SI units and returns the command in SI units; the sidecar
    ([bold]MODEL.onnx.json[/]) holds the layout, units, control rate and scenario. The export is
    validated with onnx.checker and replays recorded games against the checkpoint: nothing is
    written unless the actions agree to 1e-5.
    """
    require_positive(episodes, "--episodes")
    from pecli.export import export_checkpoint
    from pecli.scenario import load_scenario

    scenario = load_scenario(config) if config is not None else None
    one_torch_thread()
    result = export_checkpoint(checkpoint, out, scenario=scenario, opset=opset, episodes=episodes, seed=seed)
    parity = result.parity.to_dict()
    if as_json:
        typer.echo(
            json.dumps(
                {"model": str(result.model), "sidecar": str(result.sidecar), "bytes": result.size, "parity": parity}
            )
        )
        return
    console.print(_report_table(f"parity of {result.model.name} against {checkpoint.name}", parity))
    err_console.print(f"wrote {result.model} ({result.size / 1024:.0f} KiB) and {result.sidecar.name}", highlight=False)


@app.command("check")
@user_errors
def check(
    model: Annotated[Path, typer.Argument(help="An exported model (.onnx with its .onnx.json).", show_default=False)],
    checkpoint: Annotated[Path, typer.Argument(help="The checkpoint it was exported from.", show_default=False)],
    episodes: EpisodesOption = 8,
    seed: SeedOption = 0,
    opponent: Annotated[
        str | None, typer.Option("--opponent", help="Who the recorded games are played against (default: a heuristic).")
    ] = None,
    as_json: JsonOption = False,
) -> None:
    """Replay recorded games through MODEL and CHECKPOINT and report the largest action difference.

    Exits with code 1 when it exceeds the tolerance (1e-5).
    """
    require_positive(episodes, "--episodes")
    from pecli.export import check_export

    one_torch_thread()
    report = check_export(model, checkpoint, episodes=episodes, seed=seed, opponent=opponent)
    parity = report.to_dict()
    if as_json:
        typer.echo(json.dumps(parity))
    else:
        console.print(_report_table(f"parity of {model.name} against {checkpoint.name}", parity))
    if not report.passed:
        raise PecliError(f"parity check failed: {report.failure()}")
