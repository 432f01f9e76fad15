"""Diagonal Gaussian mixtures over the plane: the BiMDN's output, its likelihood and its summaries."""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch as th
import torch.nn.functional as F

_LOG_2PI = math.log(2.0 * math.pi)


@dataclass
class Mixture:
    """``K`` axis-aligned Gaussians per batch row: weights (as logits), means and standard deviations.

    Shapes: ``logits (B, K)``, ``means (B, K, 2)``, ``stds (B, K, 2)``.
    """

    logits: th.Tensor
    means: th.Tensor
    stds: th.Tensor

    @property
    def weights(self) -> th.Tensor:
        """Mixture weights ``(B, K)``, summing to 1 (the softmax of the logits)."""
        return F.softmax(self.logits, dim=-1)

    def log_prob(self, target: th.Tensor) -> th.Tensor:
        """Log density ``(B,)`` of ``target`` ``(B, 2)``, computed stably with log-sum-exp."""
        z = (target[:, None, :] - self.means) / self.stds
        component = -0.5 * (z * z).sum(-1) - th.log(self.stds).sum(-1) - _LOG_2PI  # (B, K), 2-D Gaussians
        return th.logsumexp(F.log_softmax(self.logits, dim=-1) + component, dim=-1)

    def nll(self, target: th.Tensor) -> th.Tensor:
        """Mean negative log-likelihood of ``target`` ``(B, 2)``: the BiMDN's loss."""
        return -self.log_prob(target).mean()

    def mean(self) -> th.Tensor:
        """The mixture's mean ``(B, 2)``: the weighted mean of its components (the paper's "pure" belief)."""
        return (self.weights[..., None] * self.means).sum(1)

    def sample(self, count: int, generator: th.Generator | None = None) -> th.Tensor:
        """``count`` draws per row, ``(B, count, 2)`` (the paper's "mixed" belief uses 16)."""
        batch = self.logits.shape[0]
        uniform = th.rand((batch, count), generator=generator, dtype=self.means.dtype)
        normal = th.randn((batch, count, 2), generator=generator, dtype=self.means.dtype)
        return self.sample_with(uniform, normal)

    def sample_with(self, uniform: th.Tensor, normal: th.Tensor) -> th.Tensor:
        """Draws ``(B, count, 2)`` from given randomness: a component per draw by inverse CDF of
        ``uniform`` ``(B, count)`` in [0, 1), then its mean plus its std times ``normal`` ``(B, count, 2)``.

        Deterministic given its inputs, so a policy can own its random numbers (and an exported
        graph can take them as inputs).
        """
        cumulative = th.cumsum(self.weights, dim=-1)[:, :-1]  # (B, K-1): the last bound is 1
        component = (uniform.unsqueeze(-1) >= cumulative.unsqueeze(1)).sum(-1)  # (B, count) in [0, K-1]
        index = component.unsqueeze(-1).expand(-1, -1, 2)
        return th.gather(self.means, 1, index) + th.gather(self.stds, 1, index) * normal

    def detach(self) -> Mixture:
        return Mixture(self.logits.detach(), self.means.detach(), self.stds.detach())
