"""The image-based belief baseline, after Engin et al. (IROS 2021): the history as a top-down picture.

The window is rasterised into a ``grid x grid`` image of the arena with three channels, each
weighted by recency (the newest sample 1, the oldest ``1/T``): the area the player's own sensor
covered (where the opponent was not, unless seen), the cells where the opponent was seen, and the
player's own positions. A small CNN reads the image and the BiMDN's mixture head predicts the
opponent's position; it learns by the same negative log-likelihood.
"""

from __future__ import annotations

import math

import numpy as np
import torch as th
from torch import nn

from pecli.belief.bimdn import MixtureHead
from pecli.belief.mixture import Mixture
from pecli.belief.window import DecodedWindow, WindowDecoder

GRID = 16  # cells per side


def rasterise(window: DecodedWindow, decoder: WindowDecoder, grid: int = GRID) -> np.ndarray:
    """Images ``(B, 3, grid, grid)`` float32 from decoded windows (row index = y, column = x).

    A cell's value in a channel is the recency of the newest sample that marks it (0 if none): recency
    grows with the sample's index, so the newest marking sample is the largest of them.
    """
    batch, steps = window.seen.shape
    centres = (np.arange(grid) + 0.5) / grid * 2.0 - 1.0  # normalised cell centres
    half_x, half_y = decoder.half
    recency = (np.arange(steps) + 1) / steps  # (T,)
    # own sensor coverage: cells within range (and the wedge, for a car) at each sample; a cell's offset
    # is its column's x offset and its row's y offset, so those are computed per column and per row
    dx = ((centres - window.own_pos[..., :1]) * half_x)[..., None, :]  # (B, T, 1, grid) metres, by column
    dy = ((centres - window.own_pos[..., 1:]) * half_y)[..., :, None]  # (B, T, grid, 1) metres, by row
    distance = np.sqrt(dx * dx + dy * dy)  # (B, T, grid, grid)
    covered = distance <= decoder.sensor.range
    if decoder.has_heading and decoder.sensor.fov < 2 * math.pi:
        heading = window.own_heading[..., None, None]
        distance *= math.cos(0.5 * decoder.sensor.fov)
        covered &= np.cos(heading) * dx + np.sin(heading) * dy >= distance
    covered &= window.valid[..., None, None]
    covered = covered.reshape(batch, steps, grid * grid)  # cell = row * grid + column
    image = np.zeros((batch, 3, grid * grid), dtype=np.float32)
    newest = steps - 1 - np.argmax(covered[:, ::-1], axis=1)  # (B, cells): the newest covering sample
    image[:, 0] = np.where(covered.any(axis=1), recency[newest], 0.0)
    games = np.arange(batch)
    for channel, positions, present in (
        (1, window.opp_pos, window.seen & window.valid),
        (2, window.own_pos, window.valid),
    ):
        col = np.clip(((positions[..., 0] + 1.0) / 2.0 * grid).astype(np.int64), 0, grid - 1)
        row = np.clip(((positions[..., 1] + 1.0) / 2.0 * grid).astype(np.int64), 0, grid - 1)
        cells = row * grid + col  # (B, T)
        target = image[:, channel]
        for t in np.flatnonzero(present.any(axis=0)):  # oldest first: a newer sample overwrites an older one
            marked = present[:, t]
            target[games[marked], cells[marked, t]] = recency[t]
    return image.reshape(batch, 3, grid, grid)


class ImageBelief(nn.Module):
    """Rasteriser, CNN and mixture head: history window → :class:`Mixture`."""

    def __init__(self, decoder: WindowDecoder, fc: int = 32, components: int = 3, grid: int = GRID) -> None:
        super().__init__()
        self.decoder = decoder
        self.grid = grid
        self.cnn = nn.Sequential(
            nn.Conv2d(3, 16, 3, padding=1),
            nn.ReLU(),
            nn.MaxPool2d(2),
            nn.Conv2d(16, 32, 3, padding=1),
            nn.ReLU(),
            nn.MaxPool2d(2),
            nn.Flatten(),
            nn.Linear(32 * (grid // 4) ** 2, fc),
            nn.ReLU(),
        )
        self.head = MixtureHead(fc, components)

    def forward(self, history: th.Tensor) -> Mixture:
        """The belief for windows ``(B, T, d)``; the rasterising step is not differentiable (nor needs to be)."""
        flat = history.detach().reshape(history.shape[0], -1).cpu().numpy()
        image = th.as_tensor(rasterise(self.decoder(flat), self.decoder, self.grid))
        return self.head(self.cnn(image))
