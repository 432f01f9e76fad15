"""``pecli config``: list, show and check scenario files."""

from __future__ import annotations

from typing import Annotated

import typer
import yaml
from rich.markup import escape
from rich.table import Table

from pecli.cli.common import TABLE_WIDTH, console, err_console, user_errors
from pecli.errors import ConfigError
from pecli.scenario import builtin_config_dir, builtin_names, load_scenario

app = typer.Typer(help="List, show and check scenario files.", no_args_is_help=True)


@app.command("list")
@user_errors
def list_configs() -> None:
    """List the built-in scenarios."""
    table = Table(title=f"built-in scenarios ({builtin_config_dir()})")
    for column in ("name", "pursuer", "evader", "arena", "T"):
        table.add_column(column, no_wrap=True, justify="right" if column == "T" else "left")
    table.add_column("description", ratio=1, overflow="fold")  # the one column that wraps
    for name in builtin_names():
        s = load_scenario(name)
        table.add_row(
            name,
            s.pursuer.kind,
            s.evader.kind,
            f"{s.arena.width:g} x {s.arena.height:g} m",
            str(s.horizon),
            s.description,
        )
    console.print(table, width=min(console.width, TABLE_WIDTH))


@app.command("show")
@user_errors
def show(config: Annotated[str, typer.Argument(help="A YAML file or a built-in name.")]) -> None:
    """Print a scenario with every default filled in, as YAML."""
    scenario = load_scenario(config)
    console.print(yaml.safe_dump(scenario.model_dump(mode="json"), sort_keys=False).rstrip(), highlight=False)
    console.print(f"# fingerprint: {scenario.fingerprint()}", style="dim")


@app.command("check")
@user_errors
def check(configs: Annotated[list[str], typer.Argument(help="YAML files or built-in names.")]) -> None:
    """Validate scenario files; at the first one that is wrong, list each of its problems and exit 1."""
    for config in configs:
        try:
            scenario = load_scenario(config)
        except ConfigError as exc:
            for problem in exc.problems:
                err_console.print(f"[bold red]error:[/] {escape(problem)}", highlight=False, soft_wrap=True)
            raise typer.Exit(code=1) from None
        console.print(f"[green]ok[/] {config}: {scenario.name} ({scenario.fingerprint()})", highlight=False)
