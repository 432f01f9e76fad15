"""SB3 feature extractors: pick entries of a ``Dict`` observation, and add a belief to the actor's input."""

from __future__ import annotations

from collections.abc import Sequence
from math import prod
from typing import Any

import numpy as np
import torch as th
from gymnasium import spaces
from stable_baselines3.common.torch_layers import BaseFeaturesExtractor

from pecli.belief.model import BeliefModel

ACTOR_KEYS = ("obs",)
CRITIC_KEYS = ("obs", "state", "opp_action")


class KeysExtractor(BaseFeaturesExtractor):
    """Concatenate the chosen entries of a ``Dict`` observation: ``(batch, sum of their sizes)``."""

    def __init__(self, observation_space: spaces.Dict, keys: Sequence[str] = ACTOR_KEYS) -> None:
        missing = [key for key in keys if key not in observation_space.spaces]
        if missing:
            raise KeyError(f"observation has no {', '.join(missing)}; it has {', '.join(observation_space.spaces)}")
        super().__init__(observation_space, sum(prod(observation_space[key].shape) for key in keys))
        self.keys = tuple(keys)

    def forward(self, observations: dict[str, th.Tensor]) -> th.Tensor:
        return th.cat([observations[key].flatten(1) for key in self.keys], dim=1)


class BeliefExtractor(BaseFeaturesExtractor):
    """The actor's extractor with a belief: ``[obs, belief features]``.

    It holds the :class:`BeliefModel` (so the belief is saved in the SB3 zip and exported with the
    actor). While training, the features were computed when the transition was collected and are
    read from the ``belief`` entry, so a gradient step never runs the belief network; at play
    time, when only ``history`` is given, the extractor computes them from the window.

    Args:
        belief: keyword arguments of :class:`BeliefModel`.
    """

    def __init__(self, observation_space: spaces.Dict, belief: dict[str, Any]) -> None:
        model = BeliefModel(**belief)
        super().__init__(observation_space, observation_space["obs"].shape[0] + model.features_dim)
        self.belief = model

    def forward(self, observations: dict[str, th.Tensor]) -> th.Tensor:
        if "belief" in observations:
            features = observations["belief"]
        else:
            draws = (observations["uniform"], observations["normal"]) if "uniform" in observations else None
            features = self.belief.features(observations["history"], draws)
        return th.cat([observations["obs"], features], dim=1)


def belief_observation_space(view: spaces.Dict, features_dim: int) -> spaces.Dict:
    """The view's space with its ``history`` window replaced by ``belief`` features, as the replay buffer stores it."""
    space = dict(view.spaces)
    del space["history"]
    space = {"obs": space["obs"], "belief": spaces.Box(-np.inf, np.inf, (features_dim,), np.float32), **space}
    return spaces.Dict(space)
