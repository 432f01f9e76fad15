"""Scenario and experiment files: YAML read strictly (no duplicate keys, a page at most), validated, by name or path."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

import yaml
from pydantic import ValidationError

from pecli.errors import ConfigError, PecliError
from pecli.io import read_bounded
from pecli.scenario.resources import check_resources
from pecli.scenario.schema import Scenario


def builtin_config_dir() -> Path:
    """The folder holding the built-in ``configs/*.yaml`` (source checkout or installed data files)."""
    for candidate in (
        Path(__file__).resolve().parents[2] / "configs",
        Path(sys.prefix) / "share" / "pecli" / "configs",
    ):
        if candidate.is_dir():
            return candidate
    return Path("configs")


BUILTIN_SCENARIOS = ("car_vs_car", "league", "paper", "point_mass", "quick", "robots", "tuned")


BUILTIN_EXPERIMENTS = (
    "exploitability",
    "exploitability-exploiters",
    "schedules",
    "smoke",
    "strength",
    "strength-exploiters",
    "strength-floor",
    "strength-joingames",
    "strength-lite",
    "strength-share",
    "strength-small",
    "table1",
    "table1-paper-settings",
    "table1-paper-settings-full",
    "table1-small",
    "table2",
)
"""pecli's own scenarios and experiments, by name: a file a user saves beside them never becomes a built-in."""


def builtin_names() -> list[str]:
    """Names of the built-in scenarios (``paper``, ``quick``, ...)."""
    return sorted(name for name in BUILTIN_SCENARIOS if (builtin_config_dir() / f"{name}.yaml").is_file())


def builtin_experiment_dir() -> Path:
    """The folder holding the built-in experiments (``configs/experiments``)."""
    return builtin_config_dir() / "experiments"


def builtin_experiments() -> list[str]:
    """Names of the built-in experiments (``table1``, ``strength``, ...)."""
    return sorted(name for name in BUILTIN_EXPERIMENTS if (builtin_experiment_dir() / f"{name}.yaml").is_file())


def resolve_config_path(path_or_name: str | Path) -> Path:
    """A path as given, or the built-in config of that name."""
    path = Path(path_or_name)
    if path.exists() or path.suffix in (".yaml", ".yml") or len(path.parts) > 1 or str(path) not in BUILTIN_SCENARIOS:
        return path
    return builtin_config_dir() / f"{path_or_name}.yaml"


def _describe(error: dict[str, Any]) -> str:
    """One readable phrase for one pydantic error."""
    kind, msg = error["type"], error["msg"]
    if kind == "extra_forbidden":
        return "unknown key"
    if kind == "missing":
        return "missing required key"
    shown = error.get("input")
    if kind in ("int_type", "float_type") and isinstance(shown, bool):
        return f"a number is expected here, not the boolean {str(shown).lower()}"
    if kind == "bool_type":
        return f"true or false is expected here (got {shown!r})"
    if kind == "finite_number":
        return f"must be a finite number (got {shown!r})"
    if kind == "union_tag_invalid" and "ctx" in error:
        ctx = error["ctx"]
        key = str(ctx["discriminator"]).strip("'")
        return f"{key} must be one of {ctx['expected_tags']}, not '{ctx['tag']}'"
    msg = msg.removeprefix("Value error, ")
    if "input" in error and kind not in ("model_type", "union_tag_invalid"):
        if not isinstance(shown, dict | list):
            return f"{msg} (got {shown!r})"
    return msg


def _location(error: dict[str, Any]) -> str:
    # drop the discriminator tags pydantic adds to the path of a tagged union (e.g. 'car'); quote odd keys
    parts = [str(p) if str(p).isprintable() else repr(p) for p in error["loc"] if p not in ("car", "point_mass")]
    return ".".join(parts)


def scenario_from_dict(data: Any, source: str = "<dict>") -> Scenario:
    """Validate ``data`` into a :class:`Scenario`; errors become one-line :class:`ConfigError`."""
    if not isinstance(data, dict):
        found = "an empty file" if data is None else f"a {type(data).__name__}"
        raise ConfigError(f"{source}: a scenario must be a mapping of keys to values, not {found}")
    try:
        scenario = Scenario.model_validate(data)
    except ValidationError as exc:
        raise ConfigError(validation_message(exc, source), validation_problems(exc, source)) from None
    check_resources(scenario, source)
    return scenario


def validation_problems(exc: ValidationError, source: str) -> list[str]:
    """Every problem of a pydantic error, one line each: ``<source>: <key.path>: <problem>``."""
    return [f"{source}: {_location(dict(e)) or 'top level'}: {_describe(dict(e))}" for e in exc.errors()]


def validation_message(exc: ValidationError, source: str) -> str:
    """One line for a pydantic error: ``<source>: <key.path>: <problem> (and N more problems)``."""
    problems = validation_problems(exc, source)
    more = len(problems) - 1
    return problems[0] + (f" (and {more} more problem{'s' if more > 1 else ''})" if more else "")


class StrictLoader(yaml.SafeLoader):
    """``yaml.SafeLoader`` that refuses a key given twice in one mapping (YAML would keep the last silently)."""

    def construct_mapping(self, node: yaml.MappingNode, deep: bool = False) -> dict[Any, Any]:
        first_line: dict[Any, int] = {}
        for key_node, _ in node.value:
            if key_node.tag == "tag:yaml.org,2002:merge":  # '<<: *base' keys may be overridden on purpose
                continue
            key = self.construct_object(key_node, deep=True)
            try:
                seen = key in first_line
            except TypeError:  # an unhashable key: SafeLoader's own error says so
                continue
            if seen:
                raise yaml.constructor.ConstructorError(
                    "while constructing a mapping",
                    node.start_mark,
                    f"duplicate key {key!r} (first given on line {first_line[key]})",
                    key_node.start_mark,
                )
            first_line[key] = key_node.start_mark.line + 1
        return super().construct_mapping(node, deep=deep)

    def construct_document(self, node: yaml.Node) -> Any:
        if _expanded_size(node, {}) > MAX_VALUES:  # aliases repeat what they name: '&a [*b, *b]' doubles *b
            raise yaml.constructor.ConstructorError(
                None, None, f"more than {MAX_VALUES:,} values once its aliases are expanded", node.start_mark
            )
        return super().construct_document(node)


MAX_FILE_BYTES = 1 << 20  # a scenario or experiment file is a page of YAML
MAX_VALUES = 100_000  # scalars, lists and mappings a configuration holds with its aliases expanded


def _expanded_size(node: yaml.Node, sizes: dict[int, int]) -> int:
    """How many nodes ``node`` stands for with every alias expanded: each node counted once per place it is
    named, computed once per node (``sizes``), so a document of nested aliases costs its size, not its expansion."""
    known = sizes.get(id(node))
    if known is not None:
        if known < 0:
            raise yaml.constructor.ConstructorError(None, None, "an alias that contains itself", node.start_mark)
        return known
    sizes[id(node)] = -1  # being counted
    if isinstance(node, yaml.MappingNode):
        children = [child for pair in node.value for child in pair]
    elif isinstance(node, yaml.SequenceNode):
        children = list(node.value)
    else:
        children = []
    total = 1
    for child in children:
        total = min(total + _expanded_size(child, sizes), MAX_VALUES + 1)
    sizes[id(node)] = total
    return total


def read_yaml(path: Path) -> Any:
    """The content of the YAML file ``path`` (safe, duplicate keys refused); :class:`ConfigError` in one
    line (with the line number) if it cannot be read, or if it is not a regular file of at most
    :data:`MAX_FILE_BYTES` holding at most :data:`MAX_VALUES` values."""
    try:
        text = read_bounded(path, "configuration file", MAX_FILE_BYTES).decode("utf-8")
        return yaml.load(text, Loader=StrictLoader)  # noqa: S506 (a SafeLoader)
    except PecliError as exc:
        raise ConfigError(str(exc)) from None
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f" line {mark.line + 1}" if mark is not None else ""
        problem = " ".join(str(getattr(exc, "problem", None) or "not valid YAML").split())
        raise ConfigError(f"{path}:{where}: {problem}") from None
    except RecursionError:
        raise ConfigError(f"{path}: nested too deeply to be read") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise ConfigError(f"{path}: cannot read: {exc}") from None
    except ValueError as exc:  # an integer of more digits than Python converts (4300)
        raise ConfigError(f"{path}: {exc}") from None


def load_scenario(path_or_name: str | Path) -> Scenario:
    """Read and validate a scenario from a YAML file or a built-in name (see :func:`builtin_names`)."""
    path = resolve_config_path(path_or_name)
    if not path.is_file():
        known = ", ".join(builtin_names())
        raise ConfigError(f"config not found: {path_or_name} (give a YAML file or one of: {known})")
    return scenario_from_dict(read_yaml(path), source=str(path))
