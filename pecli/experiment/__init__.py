"""Experiments: a grid of training runs, the paper's checkpoint ranking, the final tournament and the
paper's tables, from one validated YAML file, executed on Ray (``pecli experiment``).

Only :mod:`pecli.experiment.ray_executor` imports Ray; it is imported here lazily.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from pecli.experiment.folder import open_experiment
from pecli.experiment.pipeline import ExperimentRunner
from pecli.experiment.spec import (
    Experiment,
    LoadedExperiment,
    RunSpec,
    builtin_experiments,
    load_experiment,
)

if TYPE_CHECKING:
    from pecli.experiment.ray_executor import RayCluster

__all__ = [
    "Experiment",
    "ExperimentRunner",
    "LoadedExperiment",
    "RayCluster",
    "RunSpec",
    "builtin_experiments",
    "load_experiment",
    "open_experiment",
]


def __getattr__(name: str) -> Any:
    if name == "RayCluster":
        from pecli.experiment.ray_executor import RayCluster

        return RayCluster
    raise AttributeError(name)
