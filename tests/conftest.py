"""Shared fixtures: scenarios are loaded once per session."""

from __future__ import annotations

import pytest

from pecli.scenario import Scenario, builtin_names, load_scenario

BUILTINS = ["paper", "car_vs_car", "point_mass", "robots", "quick"]


@pytest.fixture(scope="session")
def paper() -> Scenario:
    return load_scenario("paper")


@pytest.fixture(scope="session")
def quick() -> Scenario:
    return load_scenario("quick")


def all_scenarios() -> list[Scenario]:
    """Every built-in scenario in both observation frames."""
    assert sorted(builtin_names()) == sorted(BUILTINS)
    out = []
    for name in BUILTINS:
        s = load_scenario(name)
        out += [s, s.model_copy(update={"observation_frame": "world" if s.observation_frame == "own" else "own"})]
    return out
