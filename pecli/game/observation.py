"""Observations: what one player sees, normalised to [-1, 1], and the way back to SI units.

Layout for a player with a ``k``-dimensional state facing an ``m``-dimensional opponent
(``k + m + 2`` numbers; 11 for the paper's car vs point mass)::

    [ own state (k) | opponent block (m, zeros when unseen) | seen flag (+1/-1) | time t/T ]

The own state is always in the world frame: position / arena half-extent, steering / its
limit, speed / its limit, yaw / pi. The opponent block depends on the scenario's
``observation_frame``:

``world`` (the paper)
    the opponent's state normalised like the own state.
``own`` (the default)
    the opponent's position relative to the observer and the relative velocity, both rotated
    into the observer's body frame (a point mass uses the world axes), positions divided by the
    sensing range and velocities by the sum of both speed limits; a car opponent adds its
    heading relative to the observer's (/ pi). It keeps the block's size.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from pecli.game.dynamics import Dynamics, make_dynamics, wrap_near
from pecli.roles import Role, opponent_of
from pecli.scenario import Scenario


@dataclass(frozen=True)
class Decoded:
    """An observation turned back into SI quantities in the world frame; all arrays have ``n`` rows."""

    own_pos: np.ndarray  # (n, 2) m
    own_vel: np.ndarray  # (n, 2) m/s
    own_heading: np.ndarray  # (n,) rad; zeros for a point mass
    own_steer: np.ndarray  # (n,) rad; zeros for a point mass
    own_speed: np.ndarray  # (n,) m/s, signed for a car
    opp_pos: np.ndarray  # (n, 2) m, meaningful only where seen
    opp_vel: np.ndarray  # (n, 2) m/s, meaningful only where seen
    seen: np.ndarray  # (n,) bool
    time: np.ndarray  # (n,) fraction of the horizon elapsed


class ObservationCodec:
    """Encodes the game's state into one role's observation and decodes observations back."""

    def __init__(self, scenario: Scenario, role: Role) -> None:
        self.role = role
        self.frame = scenario.observation_frame
        self.own: Dynamics = make_dynamics(scenario.agent(role))
        self.opp: Dynamics = make_dynamics(scenario.agent(opponent_of(role)))
        self.half_x, self.half_y = scenario.arena.half
        self.sensing_range = scenario.agent(role).sensor.range
        self.velocity_scale = self.own.speed_max + self.opp.speed_max
        self._own_scale = self.own.scale(self.half_x, self.half_y)
        self._opp_scale = self.opp.scale(self.half_x, self.half_y)
        self._own_inverse_scale = (1.0 / self._own_scale)[:, None]
        self._opp_inverse_scale = (1.0 / self._opp_scale)[:, None]
        k, m = self.own.state_dim, self.opp.state_dim
        self.dim = k + m + 2
        self.opp_slice = slice(k, k + m)
        self.seen_index = k + m
        self.time_index = k + m + 1

    def encode(
        self,
        own: np.ndarray,
        opp: np.ndarray,
        dx: np.ndarray,
        dy: np.ndarray,
        seen: np.ndarray,
        time_fraction: np.ndarray,
    ) -> np.ndarray:
        """Observations ``(n, dim)`` float32 from the internal rows of both players' states.

        ``dx, dy`` are the opponent's position minus the observer's (m), ``seen`` the sensor's verdict.
        The result is a transposed view of a row-major ``(dim, n)`` array.
        """
        out = np.empty((self.dim, own.shape[1]), dtype=np.float32)
        k, m = self.own.state_dim, self.opp.state_dim
        np.multiply(own[:k], self._own_inverse_scale, out=out[:k])
        block = out[self.opp_slice]
        if self.frame == "world":
            np.multiply(opp[:m], self._opp_inverse_scale, out=block)
        else:
            self._relative(own, opp, dx, dy, block)
        block *= seen
        np.subtract(2.0 * seen, 1.0, out=out[self.seen_index])
        out[self.time_index] = time_fraction
        return out.T

    def _relative(self, own: np.ndarray, opp: np.ndarray, dx: np.ndarray, dy: np.ndarray, block: np.ndarray) -> None:
        own_vx, own_vy = self.own.velocity(own)
        opp_vx, opp_vy = self.opp.velocity(opp)
        dvx, dvy = opp_vx - own_vx, opp_vy - own_vy
        rotation = self.own.heading_cos_sin(own)
        if rotation is None:
            block[0], block[1], block[2], block[3] = dx, dy, dvx, dvy
        else:
            c, s = rotation
            block[0] = c * dx + s * dy
            block[1] = c * dy - s * dx
            block[2] = c * dvx + s * dvy
            block[3] = c * dvy - s * dvx
        block[0:2] *= 1.0 / self.sensing_range
        block[2:4] *= 1.0 / self.velocity_scale
        opp_heading = self.opp.heading(opp)
        if opp_heading is not None:
            own_heading = self.own.heading(own)
            relative = opp_heading if own_heading is None else wrap_near(opp_heading - own_heading)
            block[4] = relative * (1.0 / math.pi)
        np.clip(block, -1.0, 1.0, out=block)

    def decode(self, obs: np.ndarray) -> Decoded:
        """SI world-frame quantities from observations ``(n, dim)``; the inverse of :meth:`encode`."""
        obs = np.asarray(obs, dtype=np.float64)
        k = self.own.state_dim
        own = self.own.from_state((obs[:, :k] * self._own_scale).T)
        own_vx, own_vy = self.own.velocity(own)
        own_pos = own[0:2].T
        own_vel = np.stack([own_vx, own_vy], axis=1)
        heading = self.own.heading(own)
        block = obs[:, self.opp_slice]
        if self.frame == "world":
            opp = self.opp.from_state((block * self._opp_scale).T)
            opp_pos = opp[0:2].T
            opp_vel = np.stack(self.opp.velocity(opp), axis=1)
        else:
            rel = block[:, 0:2] * self.sensing_range
            rel_vel = block[:, 2:4] * self.velocity_scale
            if heading is not None:
                rel, rel_vel = _rotate(rel, heading), _rotate(rel_vel, heading)
            opp_pos = own_pos + rel
            opp_vel = own_vel + rel_vel
        zeros = np.zeros(obs.shape[0])
        return Decoded(
            own_pos=own_pos,
            own_vel=own_vel,
            own_heading=zeros if heading is None else heading,
            own_steer=own[2] if heading is not None else zeros,
            own_speed=own[3] if heading is not None else np.hypot(own_vx, own_vy),
            opp_pos=opp_pos,
            opp_vel=opp_vel,
            seen=obs[:, self.seen_index] > 0,
            time=obs[:, self.time_index],
        )


def _rotate(vectors: np.ndarray, angle: np.ndarray) -> np.ndarray:
    """Rotate ``(n, 2)`` vectors by ``angle`` (rad, ``(n,)``) counter-clockwise."""
    c, s = np.cos(angle), np.sin(angle)
    x, y = vectors[:, 0], vectors[:, 1]
    return np.stack([c * x - s * y, s * x + c * y], axis=1)
