"""The ``pecli`` typer application."""

from __future__ import annotations

import inspect
import os
from typing import Annotated

import click
import typer
import typer.rich_utils

from pecli import __version__
from pecli.cli import (
    config,
    demo,
    experiment,
    exploit,
    export,
    hj,
    play,
    psro,
    selfplay,
    tournament,
    train,
    tune,
    zoo,
)
from pecli.cli.common import err_console
from pecli.trust import TRUST_VARIABLE

app = typer.Typer(
    name="pecli",
    help="Pursuit-evasion between car-like robots with limited sensors: play, train, rank and export policies.",
    rich_markup_mode="rich",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
    context_settings={"help_option_names": ["-h", "--help"]},
)


def _version(value: bool) -> None:
    if value:
        typer.echo(f"pecli {__version__}")
        raise typer.Exit()


@app.callback()
def _root(
    version: Annotated[
        bool, typer.Option("--version", "-V", callback=_version, is_eager=True, help="Print the version and exit.")
    ] = False,
    trust: Annotated[
        bool,
        typer.Option(
            "--trust",
            help="Allow what a file could use to run code: unpickling files that need it (checkpoints of an "
            "older pecli) and importing a module:Class that a record or a mixture names. Only for files from a "
            "source you trust. Same as PECLI_TRUST=1.",
        ),
    ] = False,
) -> None:
    """Pursuit-evasion between car-like robots with limited sensors (Gonultas & Isler).

    Every command takes a scenario with [bold]--config[/] (a YAML file or a built-in name).
    pecli reads checkpoints as data: loading one never runs code from it (see README, "Safety").
    """
    if trust:
        os.environ[TRUST_VARIABLE] = "1"  # read where files load, worker processes included


app.command(name="demo", rich_help_panel="Start here")(demo.demo)
app.command(name="play", rich_help_panel="Play and evaluate")(play.play)
app.command(name="tournament", rich_help_panel="Play and evaluate")(tournament.tournament)
app.command(name="train", rich_help_panel="Learn")(train.train)
app.command(name="selfplay", rich_help_panel="Learn")(selfplay.selfplay)
app.command(name="exploit", rich_help_panel="Play and evaluate")(exploit.exploit)
app.command(name="psro", rich_help_panel="Learn")(psro.psro)
app.add_typer(tune.app, name="tune", rich_help_panel="Learn")
app.add_typer(experiment.app, name="experiment", rich_help_panel="Learn")
app.add_typer(zoo.app, name="zoo", rich_help_panel="Checkpoints")
app.add_typer(export.app, name="export", rich_help_panel="Checkpoints")
app.add_typer(config.app, name="config", rich_help_panel="Scenarios")
app.add_typer(hj.app, name="hj", rich_help_panel="Baselines")


def _usage_error(error: click.ClickException) -> None:
    """A usage error (a misspelt role, a missing option) as one line, like every other refusal: ``error: ...`` with
    where the help is, instead of Typer's boxed panel (its exit code stays click's, 2)."""
    ctx = getattr(error, "ctx", None)
    where = f" (see `{ctx.command_path} --help`)" if ctx is not None else ""
    err_console.print(
        f"error: {_one_line(error.format_message())}{where}", markup=False, highlight=False, soft_wrap=True
    )


def _one_line(message: str) -> str:
    """Click's message on one line: a missing choice's list joined, the validator's ``Value error,`` prefix dropped."""
    return " ".join(message.replace("Value error, ", "").split())


typer.rich_utils.rich_format_error = _usage_error  # typer.core calls it through the module: one place to change


def reflow(doc: str) -> str:
    """A docstring with each paragraph's lines joined (paragraphs stay apart): typer's rich help keeps line
    breaks, so text wrapped for the source would come out ragged at the terminal's width."""
    paragraphs = inspect.cleandoc(doc).split("\n\n")
    return "\n\n".join(
        paragraph
        if paragraph.startswith("\b")
        # click's mark: keep this one's lines
        else " ".join(line.strip() for line in paragraph.splitlines())
        for paragraph in paragraphs
    )


def _reflow_help(typer_app: typer.Typer) -> None:
    """:func:`reflow` every command's and callback's docstring, sub-apps included."""
    callbacks = [command.callback for command in typer_app.registered_commands]
    if typer_app.registered_callback is not None:
        callbacks.append(typer_app.registered_callback.callback)
    for callback in callbacks:
        if callback is not None and callback.__doc__:
            callback.__doc__ = reflow(callback.__doc__)
    for group in typer_app.registered_groups:
        if group.typer_instance is not None:
            _reflow_help(group.typer_instance)


_reflow_help(app)


def main() -> None:
    """Console-script entry point."""
    app()
