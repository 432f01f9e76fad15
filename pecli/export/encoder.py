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


def wrap_heading(angle: th.Tensor) -> th.Tensor:
    """Angles (rad) wrapped to [-pi, pi); values already in range pass unchanged."""
    inside = (angle >= -PI) & (angle < PI)
    return th.where(inside, angle, angle - TWO_PI * th.floor((angle + PI) / TWO_PI))


def wrap_near(angle: th.Tensor) -> th.Tensor:
    """:func:`pecli.game.dynamics.wrap_near` for angles in [-3 pi, 3 pi)."""
    angle = th.where(angle >= PI, angle - TWO_PI, angle)
    return th.where(angle < -PI, angle + TWO_PI, angle)


def _f64(values) -> th.Tensor:
    return th.tensor(values, dtype=th.float64)


class SIEncoder(nn.Module):
    """SI rows ``(..., dim)`` float64 to normalised observations ``(..., dim)`` float32 (see :mod:`pecli.game.si`)."""

    def __init__(self, layout: SILayout) -> None:
        super().__init__()
        codec = layout.codec
        self.k, self.m = layout.k, layout.m
        self.own_car, self.opp_car = layout.own.has_heading, layout.opp.has_heading
        self.world = codec.frame == "world"
        half = (codec.half_x, codec.half_y)
        self.register_buffer("own_inverse_scale", 1.0 / _f64(layout.own.scale(*half)), persistent=False)
        self.register_buffer("opp_inverse_scale", 1.0 / _f64(layout.opp.scale(*half)), persistent=False)
        # the codec scales the relative block in float32
        self.register_buffer("inverse_range", th.tensor(1.0 / codec.sensing_range, dtype=th.float32), persistent=False)
        self.register_buffer("inverse_velocity", th.tensor(1.0 / codec.velocity_scale, dtype=th.float32), persistent=False)
        self.inverse_horizon = 1.0 / layout.horizon_s

    def forward(self, si: th.Tensor) -> th.Tensor:
        k, m = self.k, self.m
        own, opp = si[..., :k], si[..., k : k + m]
        flag, time = si[..., k + m], si[..., k + m + 1]
        if self.own_car:
            own = th.cat([own[..., :4], wrap_heading(own[..., 4:5])], dim=-1)
        if self.opp_car:
            opp = th.cat([opp[..., :4], wrap_heading(opp[..., 4:5])], dim=-1)
        own_n = (own * self.own_inverse_scale).float()
        block = (opp * self.opp_inverse_scale).float() if self.world else self._relative(own, opp)
        block = th.where((flag > 0).unsqueeze(-1), block, th.zeros_like(block))
        time_n = (time * self.inverse_horizon).float()
        out = th.cat([own_n, block, th.sign(flag).float().unsqueeze(-1), time_n.unsqueeze(-1)], dim=-1)
        out = th.clamp(out, -1.0, 1.0)
        return th.where((flag != 0).unsqueeze(-1), out, th.zeros_like(out))

    def _velocity(self, state: th.Tensor, car: bool) -> tuple[th.Tensor, th.Tensor]:
        if car:
            return state[..., 3] * th.cos(state[..., 4]), state[..., 3] * th.sin(state[..., 4])
        return state[..., 2], state[..., 3]

    def _relative(self, own: th.Tensor, opp: th.Tensor) -> th.Tensor:
        """The own-frame opponent block, as ``ObservationCodec._relative`` computes it."""
        own_vx, own_vy = self._velocity(own, self.own_car)
        opp_vx, opp_vy = self._velocity(opp, self.opp_car)
        dx, dy = opp[..., 0] - own[..., 0], opp[..., 1] - own[..., 1]
        dvx, dvy = opp_vx - own_vx, opp_vy - own_vy
        if self.own_car:
            c, s = th.cos(own[..., 4]), th.sin(own[..., 4])
            rows = [c * dx + s * dy, c * dy - s * dx, c * dvx + s * dvy, c * dvy - s * dvx]
        else:
            rows = [dx, dy, dvx, dvy]
        rows = [row.float() for row in rows]
        rows = [rows[0] * self.inverse_range, rows[1] * self.inverse_range,
                rows[2] * self.inverse_velocity, rows[3] * self.inverse_velocity]
        if self.opp_car:
            relative = opp[..., 4] if not self.own_car else wrap_near(opp[..., 4] - own[..., 4])
            rows.append((relative * (1.0 / PI)).float())
        return th.clamp(th.stack(rows, dim=-1), -1.0, 1.0)


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
