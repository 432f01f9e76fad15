"""Property-based tests of the scenario loader: random mutations of the built-in configs either
load to a valid scenario or are refused with one line (:class:`ConfigError`), never another exception."""

from __future__ import annotations

import math
import os
from pathlib import Path
from typing import Any

import pytest
import yaml
from conftest import BUILTINS
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from pecli.errors import ConfigError
from pecli.scenario import MEMORY_LIMIT, Scenario, builtin_names, load_scenario, memory_estimate

# 120 examples keep the suite fast; PECLI_HYPOTHESIS_EXAMPLES=5000 searches harder (docs/reliability.md)
EXAMPLES = settings(
    max_examples=int(os.environ.get("PECLI_HYPOTHESIS_EXAMPLES", "120")),
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow],
)


def full_config(name: str) -> dict[str, Any]:
    """A built-in scenario with every default written out: every key a mutation may touch."""
    return load_scenario(name).model_dump(mode="json")


def leaves(data: Any, prefix: tuple = ()) -> list[tuple]:
    """Paths to every value of a nested dict (lists count as values)."""
    if isinstance(data, dict):
        return [path for key, value in data.items() for path in leaves(value, (*prefix, key))] + (
            [prefix] if prefix else []
        )
    return [prefix]


values = st.one_of(
    st.sampled_from([math.nan, math.inf, -math.inf, True, False, 10**400]),  # the mistakes the issue names
    st.floats(allow_nan=True, allow_infinity=True),
    st.integers(min_value=-(10**30), max_value=10**30),
    st.sampled_from([0, 1, -1, 2**31, 2**63, 10**400, 1e308, -0.0, 5e-324]),
    st.booleans(),
    st.none(),
    st.text(max_size=12),
    st.sampled_from(["2pi/3", "pi", "-20deg", "1e-4", "1e5", ".nan", "inf", "car", "point_mass", "td3", "bimdn"]),
    st.lists(st.one_of(st.integers(-5, 10**12), st.booleans(), st.floats()), max_size=40),
    st.dictionaries(st.text(max_size=5), st.integers(), max_size=3),
)


def check(loaded: Scenario | None, error: ConfigError | None) -> None:
    if error is not None:
        assert "\n" not in str(error) and str(error)
        return
    assert loaded is not None
    numbers = [v for v in _flatten(loaded.model_dump()) if isinstance(v, float)]
    assert all(math.isfinite(v) for v in numbers)
    assert sum(memory_estimate(loaded).values()) <= MEMORY_LIMIT


def _flatten(data: Any) -> list[Any]:
    if isinstance(data, dict):
        return [x for value in data.values() for x in _flatten(value)]
    if isinstance(data, list):
        return [x for value in data for x in _flatten(value)]
    return [data]


def load_text(folder: Path, text: str) -> tuple[Scenario | None, ConfigError | None]:
    path = folder / "mutated.yaml"
    path.write_text(text)
    try:
        return load_scenario(path), None
    except ConfigError as error:
        return None, error


@pytest.fixture(scope="module")
def folder(tmp_path_factory) -> Path:
    return tmp_path_factory.mktemp("mutations")


def test_the_builtins_are_all_covered() -> None:
    assert sorted(builtin_names()) == sorted(BUILTINS)


@EXAMPLES
@given(data=st.data(), name=st.sampled_from(BUILTINS))
def test_mutated_values_load_or_are_refused_in_one_line(folder: Path, data: st.DataObject, name: str) -> None:
    config = full_config(name)
    for _ in range(data.draw(st.integers(1, 3), label="mutations")):
        path = data.draw(st.sampled_from(leaves(config)), label="path")
        node = config
        for key in path[:-1]:
            node = node[key] if isinstance(node.get(key), dict) else node.setdefault(key, {})
        action = data.draw(st.sampled_from(["set", "delete", "add"]), label="action")
        if action == "delete":
            node.pop(path[-1], None)
        elif action == "add":
            node[data.draw(st.text(min_size=1, max_size=8), label="new key")] = data.draw(values, label="value")
        else:
            node[path[-1]] = data.draw(values, label="value")
    check(*load_text(folder, yaml.safe_dump(config, sort_keys=False)))


@EXAMPLES
@given(data=st.data(), name=st.sampled_from(BUILTINS))
def test_mutated_text_loads_or_is_refused_in_one_line(folder: Path, data: st.DataObject, name: str) -> None:
    """Edits of the file as a user makes them: a line repeated (a duplicate key), removed, or a value rewritten."""
    lines = (Path("configs") / f"{name}.yaml").read_text().splitlines() if Path("configs").is_dir() else []
    lines = lines or yaml.safe_dump(full_config(name), sort_keys=False).splitlines()
    for _ in range(data.draw(st.integers(1, 3), label="edits")):
        valued = [i for i, line in enumerate(lines) if ":" in line and line.split(":", 1)[1].strip()]
        i = data.draw(
            st.sampled_from(valued) if valued and data.draw(st.booleans()) else st.integers(0, len(lines) - 1),
            label="line",
        )
        edit = data.draw(st.sampled_from(["repeat", "remove", "rewrite"]), label="edit")
        if edit == "repeat":
            lines.insert(i, lines[i])
        elif edit == "remove" and len(lines) > 1:
            del lines[i]
        elif ":" in lines[i]:
            key = lines[i].split(":", 1)[0]
            text = data.draw(
                st.sampled_from(
                    [
                        ".nan",
                        ".inf",
                        "-.inf",
                        "true",
                        "no",
                        "1e400",
                        "1e5",
                        "~",
                        "[]",
                        "{}",
                        "1" + "0" * 40,
                        "'12'",
                        "2pi",
                        "0x10",
                        "1_000",
                        "&a 3",
                        "*a",
                        "!!str 5",
                    ]
                ),
                label="value",
            )
            lines[i] = f"{key}: {text}"
    check(*load_text(folder, "\n".join(lines) + "\n"))
