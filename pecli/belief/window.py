"""Decoding a history window back into positions, for the beliefs that reason about geometry (UKF, image)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pecli.game.observation import ObservationCodec
from pecli.roles import Role
from pecli.scenario import Scenario


@dataclass(frozen=True)
class DecodedWindow:
    """A batch of windows in the world frame, positions normalised by the arena's half-extents.

    Shapes ``(B, T, ...)``, oldest first; ``valid`` is false for the zero padding before a game's start.
    """

    own_pos: np.ndarray  # (B, T, 2)
    own_heading: np.ndarray  # (B, T) rad, 0 for a point mass
    opp_pos: np.ndarray  # (B, T, 2), meaningful where seen
    seen: np.ndarray  # (B, T) bool
    valid: np.ndarray  # (B, T) bool


class WindowDecoder:
    """Turns flattened windows ``(B, T * dim)`` of one role's observations into a :class:`DecodedWindow`."""

    def __init__(self, scenario: Scenario, role: Role) -> None:
        self.scenario = scenario
        self.role = role
        self.codec = ObservationCodec(scenario, role)
        self.half = np.array(scenario.arena.half)
        self.sensor = scenario.agent(role).sensor
        self.has_heading = self.codec.own.has_heading
        # sample spacing of the window in seconds (history_stride game steps)
        self.dt = scenario.training.history_stride * scenario.dt

    def __call__(self, history: np.ndarray) -> DecodedWindow:
        dim = self.codec.dim
        batch = history.shape[0]
        rows = np.asarray(history, dtype=np.float64).reshape(-1, dim)
        view = self.codec.decode(rows)
        shape = (batch, -1)
        return DecodedWindow(
            own_pos=(view.own_pos / self.half).reshape(batch, -1, 2),
            own_heading=view.own_heading.reshape(shape),
            opp_pos=(view.opp_pos / self.half).reshape(batch, -1, 2),
            seen=view.seen.reshape(shape),
            valid=(rows[:, self.codec.seen_index] != 0).reshape(shape),
        )
