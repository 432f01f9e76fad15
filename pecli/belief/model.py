"""One belief of any kind: history window → mixture over the opponent's position → the actor's features.

Kinds:

``bimdn``        the BiMDN; features: the mixture's weighted mean (2 numbers, the paper's "Ours")
``bimdn-mixed``  the BiMDN; features: ``samples`` draws from the mixture (the paper's "Ours-Mixed")
``ukf``          an unscented Kalman filter run over the window; features: its mean
``image``        the window rasterised into a top-down image, a small CNN, the BiMDN's mixture head

The mixture is over positions in the world frame, normalised by the arena's half-extents; the
actor's features are its points moved into the frame of the actor's observation
(:class:`~pecli.belief.frame.BeliefFrame`).
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch as th
from torch import nn

from pecli.belief import BELIEF_KINDS
from pecli.belief.bimdn import BiMDN
from pecli.belief.frame import BeliefFrame
from pecli.belief.mixture import Mixture
from pecli.belief.window import WindowDecoder
from pecli.roles import Role
from pecli.scenario import scenario_from_dict

LEARNED_KINDS = ("bimdn", "bimdn-mixed", "image")


def features_dim(kind: str, samples: int) -> int:
    """How many numbers a belief of ``kind`` adds to the actor's input."""
    return 2 * samples if kind == "bimdn-mixed" else 2


class BeliefModel(nn.Module):
    """The belief of one player.

    Args:
        kind: ``bimdn``, ``bimdn-mixed``, ``ukf`` or ``image``.
        window: ``(samples, dim)`` of the history window.
        scenario: the scenario as a dict (``Scenario.model_dump(mode="json")``), for decoding windows.
        role: the player holding the belief.
        hidden, fc, components: BiMDN sizes (paper: 128, 32, 3).
        samples: draws for ``bimdn-mixed`` (paper: 16).
        frame: the frame of the actor's features, the scenario's ``observation_frame`` (``world`` for
            checkpoints written before the option existed).
    """

    def __init__(
        self,
        kind: str,
        window: tuple[int, int],
        scenario: dict[str, Any],
        role: Role,
        hidden: int = 128,
        fc: int = 32,
        components: int = 3,
        samples: int = 16,
        frame: str = "world",
    ) -> None:
        super().__init__()
        if kind not in BELIEF_KINDS or kind == "none":
            raise ValueError(f"unknown belief kind {kind!r}")
        self.kind, self.window, self.samples = kind, tuple(window), samples
        self.decoder = WindowDecoder(scenario_from_dict(scenario), role)
        self.frame = BeliefFrame(self.decoder.codec, frame)
        self.net: nn.Module | None
        if kind in ("bimdn", "bimdn-mixed"):
            self.net = BiMDN(window[1], hidden, fc, components)
        elif kind == "image":
            from pecli.belief.image import ImageBelief

            self.net = ImageBelief(self.decoder, fc=fc, components=components)
        else:
            from pecli.belief.ukf import WindowUKF

            self.net = None
            self.ukf = WindowUKF(self.decoder)

    @property
    def learned(self) -> bool:
        return self.net is not None

    @property
    def features_dim(self) -> int:
        return features_dim(self.kind, self.samples)

    def mixture(self, history: th.Tensor) -> Mixture:
        """The belief for flattened windows ``(B, samples * dim)``."""
        if self.net is None:
            mixture = self.ukf(history.detach().cpu().numpy())
            return Mixture(*(part.to(history.device) for part in (mixture.logits, mixture.means, mixture.stds)))
        return self.net(history.reshape(history.shape[0], *self.window))

    @th.no_grad()
    def features(self, history: th.Tensor, draws: tuple[th.Tensor, th.Tensor] | None = None) -> th.Tensor:
        """What the actor reads: ``(B, features_dim)``, without gradients (the belief learns on its own loss).

        ``draws`` are the random numbers of a ``bimdn-mixed`` belief, ``uniform (B, samples)`` and
        ``normal (B, samples, 2)`` (see :meth:`Mixture.sample_with`); without them it draws from torch's RNG.
        """
        return self.features_of(self.mixture(history), history.reshape(history.shape[0], *self.window)[:, -1], draws)

    def features_of(
        self, mixture: Mixture, newest: th.Tensor, draws: tuple[th.Tensor, th.Tensor] | None = None
    ) -> th.Tensor:
        """The actor's features from a mixture and the window's newest row ``(B, dim)`` (the observer's pose)."""
        if self.kind == "bimdn-mixed":
            points = mixture.sample_with(*draws) if draws is not None else mixture.sample(self.samples)
        else:
            points = mixture.mean()
        return self.frame(points, newest).flatten(1)

    @property
    def device(self) -> th.device:
        """Where the belief's network is (the CPU for one without parameters)."""
        return next((p.device for p in self.parameters()), th.device("cpu"))

    def features_numpy(self, history: np.ndarray) -> np.ndarray:
        return self.features(th.as_tensor(history, dtype=th.float32, device=self.device)).cpu().numpy()
