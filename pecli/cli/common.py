"""What every command shares: consoles, the user-error boundary, option types."""

from __future__ import annotations

import functools
import os
import traceback
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any, TypeVar

import typer
from rich.console import Console
from rich.errors import MarkupError
from rich.markup import escape
from rich.text import Text

from pecli.errors import PecliError
from pecli.process import interrupt, one_torch_thread, sigterm_stops  # noqa: F401 (the commands import them here)
from pecli.text import printable

if TYPE_CHECKING:
    from pecli.scenario import Scenario

PIPE_WIDTH = 200
"""Columns of output where no terminal is attached (``nohup``, cron, CI): Rich would cut it to 80, and a table of
long run names loses them. ``COLUMNS`` still sets it; a terminal on stdin, stdout or stderr gives its own width."""

TABLE_WIDTH = 120
"""Columns a table may take at most, whatever the width of the output: wider tables wrap or split."""


def _width() -> int | None:
    """``None`` (Rich's own width: the terminal's, or ``COLUMNS``) unless no terminal is attached."""
    if os.environ.get("COLUMNS", "").isdigit():
        return None
    for fd in (0, 1, 2):
        try:
            os.get_terminal_size(fd)
        except (OSError, ValueError):
            continue
        return None
    return PIPE_WIDTH


class PlainConsole(Console):
    """A console whose strings that are not valid markup (a path or a name with ``[/x]`` in it) print as they are,
    instead of raising Rich's ``MarkupError``; callers still escape the names and paths they print."""

    def render_str(self, text: str, *args: Any, **kwargs: Any) -> Any:
        try:
            return super().render_str(text, *args, **kwargs)
        except MarkupError:
            return super().render_str(text, *args, **{**kwargs, "markup": False})


_WIDTH = _width()
console = PlainConsole(width=_WIDTH)
err_console = PlainConsole(stderr=True, width=_WIDTH)


def _flags_take_no_value() -> None:
    """Show no type beside a flag in Rich's help: Typer labels ``--warm`` ``<bool>`` there, as if it took a value,
    where its plain help (and Click) show none."""
    from typer.core import TyperOption

    typed = TyperOption.display_type_rich

    def display_type_rich(self: TyperOption, ctx: Any) -> str | None:
        return None if (self.is_flag or self.count) and self.metavar is None else typed(self, ctx)

    TyperOption.display_type_rich = display_type_rich  # type: ignore[method-assign]


_flags_take_no_value()

F = TypeVar("F", bound=Callable[..., Any])

DEBUG_VARIABLE = "PECLI_DEBUG"
INTERNAL_ERROR_EXIT = 3  # a bug; 1 is a refused input, 2 a usage error (the command-line parser's)

BUILTIN_CONFIGS = "paper, tuned, league, quick, car_vs_car, point_mass, robots"
PlayersConfigOption = Annotated[
    str | None,
    typer.Option(
        "--config",
        "-c",
        help=f"Scenario YAML file or built-in name ({BUILTIN_CONFIGS}); default: the one a policy file was "
        "trained on, else paper.",
        show_default=False,
    ),
]
TrainConfigOption = Annotated[
    str | None,
    typer.Option(
        "--config",
        "-c",
        help=f"Scenario YAML file or built-in name ({BUILTIN_CONFIGS}); default: paper (a resumed run keeps its own).",
        show_default=False,
    ),
]
SeedOption = Annotated[int, typer.Option("--seed", "-s", min=0, help="Seed: the same seed plays the same games.")]


def shown(value: str, style: str = "") -> Text:
    """A stranger's text (a run's name, a checkpoint's metadata) for a table cell: as plain text, with its control
    characters written out, so that it is neither rich markup nor a terminal's escape codes."""
    return Text(printable(value), style=style)


def user_errors(command: F) -> F:
    """Turn a :class:`PecliError` or an ``OSError`` into one red line and exit code 1.

    Anything else is a bug: one line and exit code 3 (:data:`INTERNAL_ERROR_EXIT`), with the traceback only when
    ``PECLI_DEBUG`` is set.
    """

    @functools.wraps(command)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        try:
            return command(*args, **kwargs)
        except (typer.Exit, typer.Abort, KeyboardInterrupt):
            raise
        except PecliError as exc:
            err_console.print(f"[bold red]error:[/] {escape(printable(str(exc)))}", highlight=False, soft_wrap=True)
            raise typer.Exit(code=1) from None
        except OSError as exc:  # an unwritable output, a full disk, a path that is not there
            where = f"{exc.filename}: " if exc.filename else ""
            err_console.print(
                f"[bold red]error:[/] {escape(printable(f'{where}{exc.strerror or exc}'))}",
                highlight=False,
                soft_wrap=True,
            )
            raise typer.Exit(code=1) from None
        except Exception as exc:
            if os.environ.get(DEBUG_VARIABLE):
                traceback.print_exc()
                raise typer.Exit(code=INTERNAL_ERROR_EXIT) from None
            err_console.print(
                f"[bold red]internal error:[/] {type(exc).__name__}: {escape(printable(str(exc)))} "
                f"(set {DEBUG_VARIABLE}=1 to see the traceback, and please report it)",
                highlight=False,
                soft_wrap=True,
            )
            raise typer.Exit(code=INTERNAL_ERROR_EXIT) from None

    return wrapper  # type: ignore[return-value]


def require_positive(value: int, name: str) -> int:
    if value < 1:
        raise PecliError(f"{name} must be at least 1, got {value}")
    return value


def require_batch(episodes: int, hint: str) -> int:
    """``episodes`` (``--episodes``) if a positive count that fits one batched game, else one line ending
    in ``hint``, what to do instead."""
    from pecli.match import MAX_EPISODES

    require_positive(episodes, "--episodes")
    if episodes > MAX_EPISODES:
        raise PecliError(
            f"--episodes {episodes} is more than one batch can play (at most {MAX_EPISODES:,} at once, "
            f"about 1.5 KiB each): {hint}"
        )
    return episodes


def maxent_slack(slack: float | None, maxent: bool, hint: str) -> float:
    """The maxent mixture's slack that ``--slack`` sets (its default if unset); one line if it is set where no
    side is maxent (``hint`` says what to add) or outside (0, 1]."""
    from pecli.metagame import MAXENT_SLACK

    if slack is None:
        return MAXENT_SLACK
    if not maxent:
        raise PecliError(f"--slack sets the maxent mixture's slack: {hint}")
    if not 0.0 < slack <= 1.0:
        raise PecliError(f"--slack must be in (0, 1] (a capture rate the mixture may give up), not {slack:g}")
    return slack


def scenario_for(players: list[str], config: str | None, folders: bool = False) -> Scenario:
    """The ``--config`` scenario, else the one the first of ``players`` records (a checkpoint's run, an
    export's sidecar; with ``folders``, the first run found under a folder, else its first checkpoint's), else
    the paper's."""
    from pecli.policies import stored_scenario
    from pecli.scenario import load_scenario
    from pecli.zoo import CONFIG_FILE, Run

    if config is not None:
        return load_scenario(config)
    for player in players:
        if (scenario := stored_scenario(player)) is not None:
            return scenario
        path = Path(player.strip())
        if folders and path.is_dir():
            runs = [path] if (path / CONFIG_FILE).is_file() else sorted(p.parent for p in path.rglob(CONFIG_FILE))
            if runs:
                return Run(runs[0]).scenario()
            checkpoint = next(iter(sorted(path.rglob("*.zip"))), None)  # a run's role folder: its checkpoints
            if checkpoint is not None and (scenario := stored_scenario(str(checkpoint))) is not None:
                return scenario
    return load_scenario("paper")
