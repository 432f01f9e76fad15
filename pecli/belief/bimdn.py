"""BiMDN (paper section IV-C, Fig. 4): a bidirectional LSTM mixture density network.

history ``(B, T, d)`` → 1 bidirectional LSTM layer (``hidden`` per direction) → FC ``fc`` (ReLU) →
three heads, each one FC layer (ReLU) then an output layer: mixture weights (softmax), standard
deviations (ELU + 1), means (linear); ``components`` Gaussians over (x, y), diagonal covariance.
"""

from __future__ import annotations

import torch as th
import torch.nn.functional as F
from torch import nn

from pecli.belief.mixture import Mixture

MIN_STD = 1e-3  # ELU + 1 can reach 0; a floor keeps the likelihood finite


def _head(width: int, out: int) -> nn.Sequential:
    return nn.Sequential(nn.Linear(width, width), nn.ReLU(), nn.Linear(width, out))


class MixtureHead(nn.Module):
    """Three heads on a ``width`` feature: weights (softmax, as logits), stds (ELU + 1), means (linear)."""

    def __init__(self, width: int, components: int) -> None:
        super().__init__()
        self.components = components
        self.weight_head = _head(width, components)
        self.std_head = _head(width, 2 * components)
        self.mean_head = _head(width, 2 * components)

    def forward(self, z: th.Tensor) -> Mixture:
        return Mixture(
            logits=self.weight_head(z),
            means=self.mean_head(z).view(-1, self.components, 2),
            stds=(F.elu(self.std_head(z)) + 1.0 + MIN_STD).view(-1, self.components, 2),
        )


class BiMDN(nn.Module):
    """The paper's belief network.

    Args:
        input_dim: size of one observation in the window.
        hidden: LSTM units per direction (paper: 128).
        fc: width of the shared layer and of each head (paper: 32).
        components: Gaussians in the mixture (paper: 3).
    """

    def __init__(self, input_dim: int, hidden: int = 128, fc: int = 32, components: int = 3) -> None:
        super().__init__()
        self.input_dim, self.components = input_dim, components
        self.lstm = nn.LSTM(input_dim, hidden, batch_first=True, bidirectional=True)
        self.trunk = nn.Sequential(nn.Linear(2 * hidden, fc), nn.ReLU())
        self.head = MixtureHead(fc, components)

    def forward(self, history: th.Tensor) -> Mixture:
        """The belief for windows ``(B, T, d)`` (or flattened ``(B, T * d)``)."""
        if history.dim() == 2:
            history = history.view(history.shape[0], -1, self.input_dim)
        _, (h_n, _) = self.lstm(history)  # h_n: (2, B, hidden): the end of each direction's pass
        return self.head(self.trunk(th.cat([h_n[0], h_n[1]], dim=1)))
