"""The learner's spaces: its action and the flat ``Dict`` observation of the training views.

The keys and their sizes are described with the views (:mod:`wrappers.frozen_opponent`); the space lives here,
beside the game whose layout it follows, because a checkpoint's network is rebuilt from it
(:mod:`pecli.models.checkpoint`) without any training view.
"""

from __future__ import annotations

import numpy as np
from gymnasium import spaces

from pecli.game.game import Game
from pecli.roles import Role
from pecli.scenario import Training

ACTION_SPACE = spaces.Box(-1.0, 1.0, (2,), np.float32)


def observation_space(game: Game, role: Role, training: Training, history: bool = True) -> spaces.Dict:
    """The learner's ``Dict`` observation space for ``game``'s layout: ``obs`` (the frame stack), ``history`` (the
    belief window; left out with ``history=False``), ``state`` (the privileged state and ``t/T``) and
    ``opp_action``."""
    dim = game.obs_dim[role]
    boxes: dict[str, spaces.Space] = {"obs": spaces.Box(-1.0, 1.0, (training.frame_stack * dim,), np.float32)}
    if history:
        samples = -(-training.history_length // training.history_stride)  # as HistoryWindow keeps
        boxes["history"] = spaces.Box(-1.0, 1.0, (samples * dim,), np.float32)
    boxes["state"] = spaces.Box(-1.0, 1.0, (game.state_dim + 1,), np.float32)
    boxes["opp_action"] = spaces.Box(-1.0, 1.0, (2,), np.float32)
    return spaces.Dict(boxes)
