"""The off-policy algorithms pecli trains with, each paired with its centralised-critic policy class.

    spec = get_algorithm("td3")
    model = spec.cls(spec.policy, env, policy_kwargs={**policy_kwargs(training), ...}, **algorithm_kwargs(training))

Every checkpoint records :func:`policy_kwargs` in its metadata, so that its networks can be rebuilt
from pecli's own JSON and the weights alone (nothing in a checkpoint is unpickled).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
from stable_baselines3 import DDPG, TD3
from stable_baselines3.common.noise import NormalActionNoise

from pecli.errors import PolicyError
from pecli.rl.policies import CentralCriticPolicy

if TYPE_CHECKING:
    from pecli.scenario import Training


@dataclass(frozen=True)
class Algorithm:
    """One algorithm: its SB3 class, its policy class with a centralised critic, and how its actor plays.

    Args:
        name: what ``training.algo`` and ``--algo`` call it.
        cls: the SB3 algorithm class.
        policy: its policy class, whose critic reads the privileged state and the opponent's action.
        stochastic: the actor samples its actions while learning; it plays its deterministic action.
    """

    name: str
    cls: type
    policy: type
    stochastic: bool = False


ALGORITHMS: dict[str, Algorithm] = {
    "td3": Algorithm("td3", TD3, CentralCriticPolicy),
    "ddpg": Algorithm("ddpg", DDPG, CentralCriticPolicy),
}


def get_algorithm(name: str) -> Algorithm:
    """The algorithm called ``name``; :class:`PolicyError` if there is none."""
    if name not in ALGORITHMS:
        raise PolicyError(f"unknown algorithm '{name}' (known: {', '.join(ALGORITHMS)})")
    return ALGORITHMS[name]


def policy_kwargs(training: Training) -> dict[str, Any]:
    """The policy's keyword arguments that ``training`` decides, JSON-able; the feature extractor (the
    belief) is added by the caller. Recorded in every checkpoint's metadata."""
    return {"net_arch": list(training.net_arch)}


def algorithm_kwargs(training: Training) -> dict[str, Any]:
    """The algorithm's keyword arguments beyond those all of them share (learning rate, buffer, batch, ...)."""
    if get_algorithm(training.algo).stochastic:
        return {}
    return {"action_noise": NormalActionNoise(np.zeros(2), training.action_noise * np.ones(2))}
