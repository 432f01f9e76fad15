"""Each belief as a traceable torch module: normalised window ``(B, T, dim)`` → mixture tensors.

The BiMDN is torch already. The UKF and the image belief compute in NumPy at play time
(:mod:`pecli.belief.ukf`, :mod:`pecli.belief.image`); here are their twins in torch, float64,
so that they become part of the ONNX graph:

* **UKF.** The window UKF has a linear model (constant velocity, position measurements). For a
  linear model the unscented transform is exact: its sigma points give back ``F x`` and
  ``F P F^T + Q``, and the update's cross-covariances ``P H^T`` and ``H P H^T + R``. So the UKF *is*
  the Kalman filter, and the graph runs that (no Cholesky factor, a closed-form 2 x 2 inverse).
  The two agree to rounding (about 1e-12); ``tests/test_export.py`` checks it.
* **Image.** The rasteriser's cell indices and per-cell maxima become comparisons, a one-hot
  and a max-reduction over the window, then the belief's own CNN and mixture head.
"""

from __future__ import annotations

import math

import numpy as np
import torch as th
from torch import nn

from pecli.belief.model import BeliefModel
from pecli.belief.ukf import NOISE
from pecli.belief.window import WindowDecoder
from pecli.export.encoder import WindowGeometry
from pecli.game.si import SILayout

Tensors = tuple[th.Tensor, th.Tensor, th.Tensor]  # logits (B, K), means (B, K, 2), stds (B, K, 2)


class LearnedMixture(nn.Module):
    """The BiMDN (or any belief network returning a :class:`~pecli.belief.mixture.Mixture`)."""

    def __init__(self, net: nn.Module) -> None:
        super().__init__()
        self.net = net

    def forward(self, window: th.Tensor) -> Tensors:
        mixture = self.net(window)
        return mixture.logits, mixture.means, mixture.stds


class KalmanWindow(nn.Module):
    """The UKF belief run as the Kalman filter it equals; one component.

    Args:
        geometry: decodes windows into positions.
        dt: spacing of the window's samples, s.
        noise: process and measurement noise and initial covariance (times the identity).
    """

    def __init__(self, geometry: WindowGeometry, dt: float, noise: float = NOISE) -> None:
        super().__init__()
        self.geometry = geometry
        f = np.eye(4)
        f[0, 2] = f[1, 3] = dt
        self.register_buffer("f", th.tensor(f), persistent=False)
        self.register_buffer("q", th.eye(4, dtype=th.float64) * noise, persistent=False)
        self.noise = noise

    def forward(self, window: th.Tensor) -> Tensors:
        _, _, opp_pos, seen, valid = self.geometry(window)
        batch, steps = window.shape[0], window.shape[1]
        x = th.zeros_like(opp_pos[:, 0, :]).repeat(1, 2)  # (B, 4)
        p = self.q.expand(batch, 4, 4)
        for t in range(steps):
            predict = valid[:, t]
            x = th.where(predict.unsqueeze(-1), x @ self.f.T, x)
            p = th.where(predict.view(-1, 1, 1), self.f @ p @ self.f.T + self.q, p)
            x, p = self._update(x, p, opp_pos[:, t], predict & seen[:, t])
        std = th.sqrt(th.clamp(th.stack([p[:, 0, 0], p[:, 1, 1]], dim=-1), min=1e-9))  # (B, 2)
        logits = th.zeros_like(std[:, :1]).float()
        return logits, th.clamp(x[:, None, :2], -1.0, 1.0).float(), std[:, None, :].float()  # mean inside the arena

    def _update(self, x: th.Tensor, p: th.Tensor, z: th.Tensor, rows: th.Tensor) -> tuple[th.Tensor, th.Tensor]:
        s = p[:, :2, :2] + self.noise * th.eye(2, dtype=th.float64)  # (B, 2, 2) innovation covariance
        a, b, c, d = s[:, 0, 0], s[:, 0, 1], s[:, 1, 0], s[:, 1, 1]
        inverse = th.stack([th.stack([d, -b], -1), th.stack([-c, a], -1)], -2) / (a * d - b * c).view(-1, 1, 1)
        gain = p[:, :, :2] @ inverse  # (B, 4, 2)
        x_new = x + (gain @ (z - x[:, :2]).unsqueeze(-1)).squeeze(-1)
        p_new = p - gain @ s @ gain.transpose(1, 2)
        return th.where(rows.unsqueeze(-1), x_new, x), th.where(rows.view(-1, 1, 1), p_new, p)


class RasterImage(nn.Module):
    """:func:`pecli.belief.image.rasterise` in torch: windows ``(B, T, dim)`` → images ``(B, 3, grid, grid)``."""

    def __init__(self, geometry: WindowGeometry, decoder: WindowDecoder, grid: int) -> None:
        super().__init__()
        self.geometry, self.grid = geometry, grid
        centres = (np.arange(grid) + 0.5) / grid * 2.0 - 1.0
        cx, cy = np.meshgrid(centres, centres)  # row index = y, column = x
        self.register_buffer("cx", th.tensor(cx.reshape(-1)), persistent=False)
        self.register_buffer("cy", th.tensor(cy.reshape(-1)), persistent=False)
        self.register_buffer("cells", th.arange(grid * grid), persistent=False)
        self.half_x, self.half_y = (float(h) for h in decoder.half)
        self.sensing_range = decoder.sensor.range
        self.wedge = decoder.has_heading and decoder.sensor.fov < 2 * math.pi
        self.cos_half_fov = math.cos(0.5 * decoder.sensor.fov)

    def forward(self, window: th.Tensor) -> th.Tensor:
        own_pos, heading, opp_pos, seen, valid = self.geometry(window)
        batch, steps = window.shape[0], window.shape[1]
        recency = ((th.arange(steps, dtype=th.float64) + 1) / steps).view(1, steps, 1)
        dx = (self.cx.view(1, 1, -1) - own_pos[..., :1]) * self.half_x  # (B, T, cells) m
        dy = (self.cy.view(1, 1, -1) - own_pos[..., 1:]) * self.half_y
        distance = th.sqrt(dx * dx + dy * dy)
        covered = distance <= self.sensing_range
        if self.wedge:
            h = heading.unsqueeze(-1)
            covered = covered & (th.cos(h) * dx + th.sin(h) * dy >= self.cos_half_fov * distance)
        covered = covered & valid.unsqueeze(-1)
        coverage = th.amax(covered.double() * recency, dim=1)
        marks = [self._marks(opp_pos, seen & valid, recency), self._marks(own_pos, valid, recency)]
        return th.stack([coverage, *marks], dim=1).float().view(batch, 3, self.grid, self.grid)

    def _marks(self, positions: th.Tensor, present: th.Tensor, recency: th.Tensor) -> th.Tensor:
        """Per cell, the largest recency of the samples at it: ``(B, cells)``."""
        g = self.grid
        col = th.clamp(th.floor((positions[..., 0] + 1.0) / 2.0 * g), 0, g - 1)  # floor = truncation after the clip
        row = th.clamp(th.floor((positions[..., 1] + 1.0) / 2.0 * g), 0, g - 1)
        cells = (row * g + col).long()  # (B, T)
        weights = th.where(present, recency[..., 0], th.zeros_like(recency[..., 0]))
        hit = cells.unsqueeze(-1) == self.cells.view(1, 1, -1)  # (B, T, cells)
        return th.amax(th.where(hit, weights.unsqueeze(-1), th.zeros_like(weights.unsqueeze(-1))), dim=1)


class ImageMixture(nn.Module):
    """The image belief: :class:`RasterImage`, then the belief's CNN and mixture head."""

    def __init__(self, raster: RasterImage, cnn: nn.Module, head: nn.Module) -> None:
        super().__init__()
        self.raster, self.cnn, self.head = raster, cnn, head

    def forward(self, window: th.Tensor) -> Tensors:
        mixture = self.head(self.cnn(self.raster(window)))
        return mixture.logits, mixture.means, mixture.stds


def belief_module(model: BeliefModel) -> nn.Module:
    """The traceable twin of ``model``'s mixture: normalised windows ``(B, T, dim)`` → logits, means, stds."""
    decoder = model.decoder
    geometry = WindowGeometry(SILayout(decoder.scenario, decoder.role))
    if model.kind in ("bimdn", "bimdn-mixed"):
        return LearnedMixture(model.net)
    if model.kind == "image":
        return ImageMixture(RasterImage(geometry, decoder, model.net.grid), model.net.cnn, model.net.head)
    if model.kind == "ukf":
        return KalmanWindow(geometry, decoder.dt)
    raise ValueError(f"no export for belief kind {model.kind!r}")
