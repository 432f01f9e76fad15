"""Scenarios: the typed, validated description of one pursuit-evasion game.

A scenario is read from YAML with a safe loader that refuses duplicate keys, and validated by
pydantic strictly: every number finite, no boolean where a number belongs (nor a number where a
boolean belongs), and the sizes that decide a run's memory and time within plausible bounds, checked
before anything is allocated (:func:`memory_estimate`). Every quantity is in SI units (metres,
seconds, radians). Angles (a sensor's ``fov``, a car's steering limits) may be written as numbers or
as expressions such as ``2pi/3``, ``pi``, ``-20deg``.

    >>> scenario = load_scenario("configs/paper.yaml")   # or a built-in name: "paper"
    >>> scenario.pursuer.kind, scenario.capture_distance
    ('car', 0.5)
"""

from __future__ import annotations

from pecli.scenario.loader import (
    BUILTIN_EXPERIMENTS,
    BUILTIN_SCENARIOS,
    MAX_FILE_BYTES,
    StrictLoader,
    builtin_config_dir,
    builtin_experiment_dir,
    builtin_experiments,
    builtin_names,
    load_scenario,
    read_yaml,
    resolve_config_path,
    scenario_from_dict,
    validation_message,
)
from pecli.scenario.resources import MEMORY_LIMIT, check_resources, memory_estimate
from pecli.scenario.schema import Agent, Arena, CarAgent, PointMassAgent, Reward, Scenario, Sensor
from pecli.scenario.training import ALGOS, BeliefSettings, Curriculum, SelfPlay, Training
from pecli.scenario.values import (
    MAX_BATCH,
    MAX_BUFFER,
    MAX_COUNT,
    MAX_DEPTH,
    MAX_DT,
    MAX_GAMES,
    MAX_HISTORY,
    MAX_HORIZON,
    MAX_METRES,
    MAX_RATE,
    MAX_STEPS,
    MAX_WIDTH,
    TWO_PI,
    Angle,
    Count,
    Real,
    dotted,
    parse_angle,
    parse_number,
)

__all__ = [
    "Angle",
    "Count",
    "MAX_BATCH",
    "MAX_BUFFER",
    "MAX_COUNT",
    "MAX_DEPTH",
    "MAX_DT",
    "MAX_GAMES",
    "MAX_HISTORY",
    "MAX_HORIZON",
    "MAX_METRES",
    "MAX_RATE",
    "MAX_STEPS",
    "MAX_WIDTH",
    "Real",
    "TWO_PI",
    "parse_angle",
    "parse_number",
    "ALGOS",
    "BeliefSettings",
    "Curriculum",
    "SelfPlay",
    "Training",
    "Agent",
    "Arena",
    "CarAgent",
    "PointMassAgent",
    "Reward",
    "Scenario",
    "Sensor",
    "MEMORY_LIMIT",
    "check_resources",
    "memory_estimate",
    "BUILTIN_EXPERIMENTS",
    "BUILTIN_SCENARIOS",
    "MAX_FILE_BYTES",
    "StrictLoader",
    "builtin_config_dir",
    "builtin_experiment_dir",
    "builtin_experiments",
    "builtin_names",
    "dotted",
    "load_scenario",
    "read_yaml",
    "resolve_config_path",
    "scenario_from_dict",
    "validation_message",
]
