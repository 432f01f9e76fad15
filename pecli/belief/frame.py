"""The frame the actor reads belief points in: the same as its observation's opponent block.

A belief locates the opponent in the world frame (positions / arena half-extents). The actor's
observation gives a *seen* opponent in the scenario's ``observation_frame``; the belief's points
are handed to the actor in that same frame, so "where I believe it is" and "where I see it" are
numbers of one kind:

``world``  the points unchanged (the paper's encoding).
``own``    the point minus the observer's position, rotated into the observer's body frame (a point
           mass keeps the world axes), divided by the sensing range: the units of
           :meth:`pecli.game.observation.ObservationCodec.encode`'s opponent block, without its clipping.

The observer's pose comes from the newest row of the history window, its current observation.
"""

from __future__ import annotations

import math

import torch as th
from torch import nn

from pecli.game.observation import ObservationCodec

FRAMES = ("world", "own")


class BeliefFrame(nn.Module):
    """Moves belief points ``(B, ..., 2)`` (normalised world frame) into the actor's frame.

    Args:
        codec: the observing role's :class:`ObservationCodec` (it knows the row layout and scales).
        frame: ``world`` or ``own``.
    """

    def __init__(self, codec: ObservationCodec, frame: str = "world") -> None:
        super().__init__()
        if frame not in FRAMES:
            raise ValueError(f"unknown belief frame {frame!r} (known: {', '.join(FRAMES)})")
        self.frame = frame
        # plain floats, so the transform traces to ONNX as constants of the input's dtype
        self.half = (float(codec.half_x), float(codec.half_y))
        self.inverse_range = 1.0 / float(codec.sensing_range)
        self.heading_index = codec.own.labels.index("psi") if codec.own.has_heading else None

    def forward(self, points: th.Tensor, newest: th.Tensor) -> th.Tensor:
        """``points`` ``(B, 2)`` or ``(B, S, 2)`` seen from the observer of ``newest`` ``(B, dim)``,
        a normalised row."""
        if self.frame == "world":
            return points
        shape = (-1,) + (1,) * (points.dim() - 2)  # broadcast a per-row number over the points
        dx = (points[..., 0] - newest[:, 0].view(shape)) * self.half[0]
        dy = (points[..., 1] - newest[:, 1].view(shape)) * self.half[1]
        if self.heading_index is not None:
            heading = newest[:, self.heading_index].view(shape) * math.pi
            c, s = th.cos(heading), th.sin(heading)
            dx, dy = c * dx + s * dy, c * dy - s * dx
        return th.stack([dx, dy], dim=-1) * self.inverse_range

    def extra_repr(self) -> str:
        return f"frame={self.frame!r}"
