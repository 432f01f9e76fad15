"""MkDocs hooks: the reference pages that are generated from the code, so that they cannot drift from it.

A page asks for generated content with a marker on a line of its own; :func:`on_page_markdown` replaces it:

    <!-- pecli:cli -->                   every ``pecli`` command's ``--help``, as the CLI prints it
    <!-- pecli:scenario-fields -->       every key of a scenario file, from the pydantic models in pecli.scenario
    <!-- pecli:builtin-scenarios -->     the built-in scenarios (name, game, description)
    <!-- pecli:experiment-fields -->     every key of an experiment file, from pecli.experiment.spec
    <!-- pecli:builtin-experiments -->   the built-in experiments (name, grid, budget, description)

An unknown marker fails the build. :func:`on_page_content` turns the Sphinx roles of docstrings
(``:class:`Game```) into plain code in the API reference.
"""

from __future__ import annotations

import re
import sys
import types
import typing
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))  # document this checkout's pecli, whatever else is installed

MARKER = re.compile(r"^<!-- pecli:([a-z-]+) -->$", re.MULTILINE)
HELP_WIDTH = 100


# --------------------------------------------------------------------------------------------- the CLI


def cli_commands() -> list[tuple[list[str], Any]]:
    """Every command of the ``pecli`` app as ``(path, click command)``, groups included, in the app's order."""
    import typer

    from pecli.cli import app

    found: list[tuple[list[str], Any]] = []

    def walk(command: Any, path: list[str]) -> None:
        found.append((path, command))
        for name, sub in (getattr(command, "commands", None) or {}).items():
            walk(sub, [*path, name])

    walk(typer.main.get_command(app), [])
    return found


def cli_help(path: list[str]) -> str:
    """``pecli PATH --help`` as the terminal shows it at :data:`HELP_WIDTH` columns, without colour."""
    from typer.testing import CliRunner

    from pecli.cli import app

    env = {"COLUMNS": str(HELP_WIDTH), "NO_COLOR": "1", "TERM": "dumb"}
    result = CliRunner().invoke(app, [*path, "--help"], prog_name="pecli", env=env)
    if result.exit_code != 0:
        raise RuntimeError(f"`pecli {' '.join(path)} --help` failed ({result.exit_code}): {result.output}")
    lines = [line.rstrip() for line in result.output.splitlines()]
    while lines and not lines[0]:
        lines.pop(0)
    return "\n".join(lines).rstrip()


def cli_reference() -> str:
    parts = []
    for path, command in cli_commands():
        name = " ".join(["pecli", *path])
        depth = min(2 + len(path), 4) if path else 2
        summary = (command.short_help or (command.help or "").strip().split("\n")[0]).strip() if path else ""
        parts.append(f"{'#' * depth} `{name}`\n")
        if summary:
            parts.append(f"{summary}\n")
        parts.append(f"```text\n{cli_help(path)}\n```\n")
    return "\n".join(parts)


# --------------------------------------------------------------------------------- pydantic models


def _constraints(metadata: list[Any]) -> list[str]:
    words = []
    for item in metadata:
        for attribute, symbol in (("gt", ">"), ("ge", "≥"), ("lt", "<"), ("le", "≤")):
            value = getattr(item, attribute, None)
            if value is not None and type(item).__name__.lower() == attribute:
                words.append(f"{symbol} {value:g}" if isinstance(value, float) else f"{symbol} {value:,}")
        if type(item).__name__ == "MinLen":
            words.append(f"at least {item.min_length}")
        if type(item).__name__ == "MaxLen":
            words.append(f"at most {item.max_length}")
        if type(item).__name__ == "_PydanticGeneralMetadata" and getattr(item, "pattern", None):
            words.append(f"pattern `{item.pattern}`")
    return words


def _validator_names(metadata: list[Any]) -> set[str]:
    return {getattr(getattr(item, "func", None), "__name__", "") for item in metadata}


def _type_name(annotation: Any, metadata: list[Any] = ()) -> str:
    """A YAML reader's name for a field's type."""
    from pydantic import BaseModel

    validators = _validator_names(list(metadata))
    origin = typing.get_origin(annotation)
    args = typing.get_args(annotation)
    if origin is typing.Annotated:
        return _type_name(args[0], [*metadata, *args[1:]])
    if "parse_angle" in validators:
        return "angle (rad; or `2pi/3`, `120deg`)"
    if origin is typing.Literal:
        return "one of " + ", ".join(f"`{a}`" for a in args)
    if origin in (typing.Union, types.UnionType):
        if all(_models_in(a) for a in args):
            return "section"
        names = [_type_name(a) for a in args if a is not type(None)]
        suffix = " or `null`" if type(None) in args else ""
        return " or ".join(names) + suffix
    if origin is list:
        inner = args[0] if args else Any
        return f"list of {_type_name(inner)}"
    if origin is dict:
        return "mapping"
    if isinstance(annotation, type) and issubclass(annotation, BaseModel):
        return "section"
    return {bool: "boolean", int: "integer", float: "number", str: "string"}.get(annotation, str(annotation))


def _default(field: Any) -> str:
    from pydantic import BaseModel

    if field.is_required():
        return "required"
    value = field.get_default(call_default_factory=True)
    if isinstance(value, BaseModel):
        return "(section)"
    if value is None:
        return "`null`"
    if isinstance(value, bool):
        return f"`{str(value).lower()}`"
    if isinstance(value, float):
        return "`2pi`" if abs(value - 6.283185307179586) < 1e-12 else f"`{value:g}`"
    if isinstance(value, int):
        return f"`{value:,}`".replace(",", " ") if abs(value) >= 10_000 else f"`{value}`"
    if isinstance(value, str):
        return f"`{value}`" if value else '`""`'
    return f"`{value}`"


def _cell(text: str) -> str:
    return text.replace("|", "\\|").replace("\n", " ")


def _models_in(annotation: Any) -> list[type]:
    from pydantic import BaseModel

    if isinstance(annotation, type) and issubclass(annotation, BaseModel):
        return [annotation]
    return [m for arg in typing.get_args(annotation) for m in _models_in(arg)]


def model_tables(
    model: type, prefix: str, title: str, anchor: str, level: int, notes: dict[str, str], documented: dict[type, str]
) -> str:
    """A table of ``model``'s fields, then a section for each nested model not documented yet (recursively).

    Fields that hold the same models (``pursuer`` and ``evader``) share one section, their keys written
    ``<role>.KEY``; a model met again (a player's ``sensor``) links to its first section."""
    documented[model] = anchor
    rows = ["| key | type | default | constraints | meaning |", "| --- | --- | --- | --- | --- |"]
    groups: dict[tuple[type, ...], list[str]] = {}
    for name, field in model.model_fields.items():
        models = tuple(_models_in(field.annotation))
        if models:
            groups.setdefault(models, []).append(name)
    sections: list[tuple[str, str, type, str]] = []  # (row prefix, title, model, anchor)
    for models, names in groups.items():
        shown = "<role>" if set(names) == {"pursuer", "evader"} else f"{prefix}{names[0]}"
        for m in models:
            kind = m.model_fields.get("kind")
            suffix = f"-{str(kind.default).replace('_', '-')}" if len(models) > 1 and kind is not None else ""
            label = f"`{shown}`" + (f" (`kind: {kind.default}`)" if suffix else "")
            sections.append((f"{shown}.", label, m, _slug(shown) + suffix))
    for name, field in model.model_fields.items():
        key = f"{prefix}{name}"
        models = tuple(_models_in(field.annotation))
        description = field.description or notes.get(key, "")
        if models:
            links = ", ".join(f"[{label}](#{documented.get(m, a)})" for _, label, m, a in sections if m in models)
            description = (description + "; " if description else "") + f"see {links}"
        rows.append(
            "| "
            + " | ".join(
                _cell(c)
                for c in (
                    f"`{key}`",
                    _type_name(field.annotation, field.metadata),
                    _default(field),
                    ", ".join(_constraints(field.metadata)),
                    description,
                )
            )
            + " |"
        )
    doc = " ".join((model.__doc__ or "").split())
    doc = re.sub(r"``([^`]+)``", r"`\1`", doc) if doc and not doc.startswith("!!!") else ""
    out = [f"{'#' * level} {title} {{#{anchor}}}\n", f"{doc}\n" if doc else "", "\n".join(rows), ""]
    for row_prefix, label, sub, sub_anchor in sections:
        if sub not in documented:
            out.append(model_tables(sub, row_prefix, label, sub_anchor, min(level + 1, 4), notes, documented))
    return "\n".join(out)


def _slug(key: str) -> str:
    return re.sub(r"[^a-z0-9]+", "-", key.lower()).strip("-")


# Fields the models leave without a description: what they mean, for the reference only.
SCENARIO_NOTES = {
    "name": "the scenario's name (a run folder's default name)",
    "description": "one line about the game",
    "arena": "the obstacle-free rectangle, centred at the origin",
    "reward": "the pursuer's reward coefficients (the evader gets the negative)",
    "pursuer": "the pursuer: a car or a point mass, by `kind`",
    "evader": "the evader: a car or a point mass, by `kind`",
    "training": "how to learn in this game; not part of the game's fingerprint",
    "<role>.kind": "the player's model: a KS car or a point mass",
    "training.learning_rate": "Adam's learning rate of actor and critics",
    "training.buffer_size": "replay buffer, transitions",
    "training.batch_size": "transitions per gradient step",
    "training.gamma": "discount factor",
    "training.tau": "Polyak coefficient of the target networks (unused by crossq)",
    "training.eval_episodes": "games per evaluation",
    "training.curriculum": "the paper's curriculum (section V-A)",
    "training.curriculum.enabled": "ease the game early in training",
    "training.belief_settings": "the belief network and its fit",
    "training.belief_settings.batch_size": "windows per belief update",
    "training.belief_settings.learning_rate": "Adam's learning rate of the belief",
    "training.selfplay": "`pecli selfplay`'s settings",
}
EXPERIMENT_NOTES = {
    "name": "the experiment's name: letters, digits, `.`, `_`, `-`",
    "description": "one line about it (not inherited through `extends`)",
    "runs": "the grid of runs",
    "ranking": "the paper's checkpoint ranking (section V-B)",
    "tournament": "the final tournament",
    "report": "the report",
    "ranking.sample": "checkpoints of the other side each checkpoint plays (the paper: 32)",
    "ranking.seeds": "seeds per pairing",
    "tournament.seeds": "seeds per pairing",
}


def scenario_fields() -> str:
    from pecli.scenario import Scenario

    return model_tables(Scenario, "", "Top level", "scenario-top", 3, SCENARIO_NOTES, {})


def experiment_fields() -> str:
    from pecli.experiment.spec import Experiment

    extends = (
        "\n`extends` (string, optional): a built-in experiment's name, or a YAML file relative to this one, "
        "whose keys this file starts from; see [Variants](#variants-extends).\n"
    )
    return model_tables(Experiment, "", "Top level", "experiment-top", 3, EXPERIMENT_NOTES, {}) + extends


def builtin_scenarios() -> str:
    from pecli.scenario import builtin_names, load_scenario

    rows = ["| name | pursuer | evader | arena | T | description |", "| --- | --- | --- | --- | ---: | --- |"]
    for name in builtin_names():
        s = load_scenario(name)

        def player(agent: Any) -> str:
            fov = round(agent.sensor.fov / 3.141592653589793 * 180)
            sight = f"{agent.sensor.range:g} m" + ("" if fov >= 360 else f", {fov}°")
            return f"{agent.kind.replace('_', ' ')} (sensor {sight})"

        rows.append(
            "| "
            + " | ".join(
                _cell(c)
                for c in (
                    f"`{name}`",
                    player(s.pursuer),
                    player(s.evader),
                    f"{s.arena.width:g} m × {s.arena.height:g} m",
                    str(s.horizon),
                    s.description,
                )
            )
            + " |"
        )
    return "\n".join(rows) + "\n"


def builtin_experiments() -> str:
    from pecli.experiment.spec import builtin_experiments as names
    from pecli.experiment.spec import load_experiment

    rows = [
        "| name | scenario | grid (kinds × seeds × schedules) | budget per run | description |",
        "| --- | --- | --- | --- | --- |",
    ]
    for name in names():
        spec = load_experiment(name).spec
        runs = spec.runs
        seeds = f"{len(runs.seeds)} seed{'s' * (len(runs.seeds) > 1)}"
        grid = f"{', '.join(runs.kinds)} × {seeds} × {', '.join(runs.schedules)}"
        if runs.cpu_hours is not None:
            budget = f"{runs.cpu_hours:g} CPU-h"
        elif runs.rounds is not None:
            budget = f"{runs.rounds} rounds × {runs.steps_per_round or 'the scenario’s'} per side"
        elif runs.steps is not None:
            budget = f"{runs.steps:,} transitions".replace(",", " ")
        else:
            budget = "the scenario's"
        rows.append(
            "| "
            + " | ".join(_cell(c) for c in (f"`{name}`", f"`{spec.scenario}`", grid, budget, spec.description))
            + " |"
        )
    return "\n".join(rows) + "\n"


GENERATORS = {
    "cli": cli_reference,
    "scenario-fields": scenario_fields,
    "builtin-scenarios": builtin_scenarios,
    "experiment-fields": experiment_fields,
    "builtin-experiments": builtin_experiments,
}


# --------------------------------------------------------------------------------------------- hooks


def on_page_markdown(markdown: str, page: Any, config: Any, files: Any) -> str:
    def replace(match: re.Match) -> str:
        name = match.group(1)
        if name not in GENERATORS:
            raise ValueError(f"{page.file.src_path}: unknown generated section <!-- pecli:{name} -->")
        return GENERATORS[name]()

    return MARKER.sub(replace, markdown)


_ROLE = re.compile(r":(?:py:)?(?:func|class|meth|mod|attr|data|obj|exc|const):(<code>)")


def on_page_content(html: str, page: Any, config: Any, files: Any) -> str:
    return _ROLE.sub(r"\1", html)
