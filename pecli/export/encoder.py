"""Unit conversions inside the exported graph, as torch modules that trace to ONNX.

:class:`SIEncoder` is :meth:`pecli.game.si.SILayout.from_si` (SI rows to normalised observations),
with the game's own float32 rounding steps (:class:`~pecli.game.observation.ObservationCodec`), so
that an exported graph fed the true state sees the observation the game would have given.
:class:`WindowGeometry` is :class:`pecli.belief.window.WindowDecoder` (normalised windows back to
positions) for the beliefs that reason about geometry. Both compute in float64.
"""

from __future__ import annotations

import math

import torch as th
from torch import nn

from pecli.game.si import SILayout

PI = math.pi
TWO_PI = 2.0 * math.pi


def _f64(values) -> th.Tensor:
    return th.tensor(values, dtype=th.float64)


class SIEncoder(nn.Module):
    """SI rows ``(..., dim)`` float64 to normalised observations ``(..., dim)`` float32 (see :mod:`pecli.game.si`).

    Written with few, whole-row operations (the graph runs at every decision of a robot, and ONNX
    Runtime's cost at batch 1 is mostly per operator), in the same floating-point steps as the
    game's codec: SI products in float64, cast to float32, the relative block scaled in float32.
    """

    def __init__(self, layout: SILayout) -> None:
        super().__init__()
        codec = layout.codec
        self.k, self.m = layout.k, layout.m
        k = self.k
        self.own_car, self.opp_car = layout.own.has_heading, layout.opp.has_heading
        self.world = codec.frame == "world"
        half = (codec.half_x, codec.half_y)
        scale = [*layout.own.scale(*half), *layout.opp.scale(*half), 1.0, layout.horizon_s]
        # headings (a car's psi) wrap to [-pi, pi): x - 2 pi floor((x + pi) / 2 pi), a no-op in range
        angle = [0.0] * layout.dim
        for offset, car in ((0, self.own_car), (k, self.opp_car)):
            if car:
                angle[offset + 4] = -TWO_PI
        self.register_buffer("angle", _f64(angle), persistent=False)
        self.register_buffer("inverse_scale", 1.0 / _f64(scale), persistent=False)
        # the codec scales the relative block in float32: positions by the range, velocities by the speed sum
        relative = [1.0 / codec.sensing_range] * 2 + [1.0 / codec.velocity_scale] * 2
        self.register_buffer("relative_scale", th.tensor(relative, dtype=th.float32), persistent=False)
        self.register_buffer("swap", th.tensor([1, 0, 3, 2]), persistent=False)
        self.register_buffer("swap_sign", _f64([1.0, -1.0, 1.0, -1.0]), persistent=False)

    def forward(self, si: th.Tensor) -> th.Tensor:
        k, m = self.k, self.m
        si = si + self.angle * th.floor((si + PI) / TWO_PI)
        normalised = (si * self.inverse_scale).float()  # own state, world-frame opponent, flag, t/T
        flag = si[..., k + m : k + m + 1]
        block = normalised[..., k : k + m] if self.world else self._relative(si)
        block = th.where(flag > 0, block, 0.0)
        out = th.cat([normalised[..., :k], block, th.sign(flag).float(), normalised[..., k + m + 1 :]], dim=-1)
        return th.clamp(out, -1.0, 1.0)

    def _velocity(self, state: th.Tensor, car: bool) -> th.Tensor:
        """World-frame velocity ``(..., 2)`` of an SI state block, m/s."""
        if car:
            heading = state[..., 4:5]
            return state[..., 3:4] * th.cat([th.cos(heading), th.sin(heading)], dim=-1)
        return state[..., 2:4]

    def _relative(self, si: th.Tensor) -> th.Tensor:
        """The own-frame opponent block, in ``ObservationCodec._relative``'s arithmetic."""
        k, m = self.k, self.m
        own, opp = si[..., :k], si[..., k : k + m]
        delta = th.cat(
            [opp[..., 0:2] - own[..., 0:2], self._velocity(opp, self.opp_car) - self._velocity(own, self.own_car)],
            dim=-1,
        )  # (dx, dy, dvx, dvy)
        if self.own_car:  # rotate both pairs into the body frame: (c x + s y, c y - s x)
            c, s = th.cos(own[..., 4:5]), th.sin(own[..., 4:5])
            delta = c * delta + s * (delta[..., self.swap] * self.swap_sign)
        block = delta.float() * self.relative_scale
        if self.opp_car:
            relative = opp[..., 4:5] if not self.own_car else opp[..., 4:5] - own[..., 4:5]
            relative = relative - TWO_PI * th.floor((relative + PI) / TWO_PI)  # wrap_near for headings in range
            block = th.cat([block, (relative * (1.0 / PI)).float()], dim=-1)
        return th.clamp(block, -1.0, 1.0)


class WindowGeometry(nn.Module):
    """Normalised windows ``(B, T, dim)`` float32 to positions: the torch twin of ``WindowDecoder``.

    Returns ``own_pos (B, T, 2)``, ``own_heading (B, T)`` rad, ``opp_pos (B, T, 2)`` (positions in the
    world frame divided by the arena's half-extents, float64), ``seen (B, T)`` and ``valid (B, T)`` bools.
    """

    def __init__(self, layout: SILayout) -> None:
        super().__init__()
        codec = layout.codec
        self.k, self.m = layout.k, layout.m
        self.own_car = layout.own.has_heading
        self.world = codec.frame == "world"
        self.sensing_range = codec.sensing_range
        self.register_buffer("arena_half", _f64([codec.half_x, codec.half_y]), persistent=False)

    def forward(self, window: th.Tensor) -> tuple[th.Tensor, th.Tensor, th.Tensor, th.Tensor, th.Tensor]:
        rows = window.double()
        k = self.k
        own_pos = rows[..., 0:2] * self.arena_half
        heading = rows[..., 4] * PI if self.own_car else th.zeros_like(rows[..., 0])
        block = rows[..., k : k + self.m]
        if self.world:
            opp_pos = block[..., 0:2] * self.arena_half
        else:
            rel = block[..., 0:2] * self.sensing_range
            if self.own_car:
                c, s = th.cos(heading), th.sin(heading)
                x, y = rel[..., 0], rel[..., 1]
                rel = th.stack([c * x - s * y, s * x + c * y], dim=-1)
            opp_pos = own_pos + rel
        flag = rows[..., k + self.m]
        return own_pos / self.arena_half, heading, opp_pos / self.arena_half, flag > 0, flag != 0
