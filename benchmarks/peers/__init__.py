"""Other multi-agent libraries training pecli's game: each module's ``train`` returns a :class:`PeerRun`."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from torch import nn


@dataclass
class PeerRun:
    """What a run leaves: each role's deterministic actor (a plain torch module from observations ``(B, obs_dim)``
    to actions ``(B, 2)`` in [-1, 1]) and how it was trained."""

    actors: dict[str, nn.Module]
    steps: int  # env steps (frames)
    episodes: int
    cpu_seconds: float
    iterations: int
    settings: dict[str, Any]
    library: str  # e.g. "RLlib 2.60.0 PPO"
    curve: list[dict[str, Any]] = field(default_factory=list)  # one entry per training iteration
