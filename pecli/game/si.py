"""Observations in SI units, as a robot's state estimator gives them: the exported models' input.

One SI row per control tick, ``dim = k + m + 2`` numbers (the same size as the normalised
observation of :mod:`pecli.game.observation`)::

    [ own state (k, SI, world frame) | opponent state (m, SI, world frame) | seen | time ]

A car's state is ``(s_x m, s_y m, delta rad, v m/s, psi rad)``, a point mass's
``(s_x m, s_y m, v_x m/s, v_y m/s)``. ``seen`` is +1 when the opponent is seen and -1 when not
(the opponent block is then ignored); ``time`` is the time since the episode started, in seconds.
An all-zero row (``seen`` 0) stands for "no observation yet": the history window's padding;
it normalises to zeros, as the window pads.

:meth:`SILayout.to_si` turns the game's normalised observations into SI rows and
:meth:`SILayout.from_si` is its inverse, the normalisation an exported graph performs inside:
headings are wrapped to [-pi, pi), every normalised value is clipped to [-1, 1] (the training
range; a no-op for the game's own observations).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from pecli.game.dynamics import wrap_angle
from pecli.game.observation import ObservationCodec
from pecli.roles import Role
from pecli.scenario import Scenario

UNITS = {"s_x": "m", "s_y": "m", "delta": "rad", "v": "m/s", "psi": "rad", "v_x": "m/s", "v_y": "m/s"}


@dataclass(frozen=True)
class Field:
    """One column of an SI row."""

    name: str
    unit: str
    meaning: str

    def to_dict(self) -> dict[str, str]:
        return {"name": self.name, "unit": self.unit, "meaning": self.meaning}


def wrap_heading(angle: np.ndarray) -> np.ndarray:
    """Angles (rad) wrapped to [-pi, pi); values already in range are returned unchanged, bit for bit."""
    angle = np.asarray(angle, dtype=np.float64)
    return np.where((angle >= -math.pi) & (angle < math.pi), angle, wrap_angle(angle))


class SILayout:
    """The SI row layout of one role in one scenario, and the conversions to and from observations."""

    def __init__(self, scenario: Scenario, role: Role) -> None:
        self.codec = ObservationCodec(scenario, role)
        self.own, self.opp = self.codec.own, self.codec.opp
        self.k, self.m = self.own.state_dim, self.opp.state_dim
        self.dim = self.codec.dim
        self.seen_index, self.time_index = self.codec.seen_index, self.codec.time_index
        self.horizon_s = scenario.horizon * scenario.dt  # the time that normalises to 1

    def fields(self) -> list[Field]:
        """The columns of one row, with units."""
        own = [Field(f"own.{label}", UNITS[label], "own state, world frame") for label in self.own.labels]
        opp = [
            Field(f"opponent.{label}", UNITS[label], "opponent state, world frame; ignored unless seen")
            for label in self.opp.labels
        ]
        return [
            *own,
            *opp,
            Field(
                "seen",
                "1",
                "+1 the opponent is seen, -1 not (only the sign counts); 0 only in the history window's padding",
            ),
            Field("time", "s", "time since the episode started"),
        ]

    def to_si(self, obs: np.ndarray) -> np.ndarray:
        """SI rows ``(n, dim)`` float64 from normalised observations ``(n, dim)``; zero rows stay zero.

        In the own frame a car opponent's steering angle is not observed and comes back as 0
        (the normalisation ignores it).
        """
        obs = np.asarray(obs)
        view = self.codec.decode(obs)
        n = obs.shape[0]
        si = np.zeros((n, self.dim))
        if self.own.has_heading:
            si[:, : self.k] = np.column_stack([view.own_pos, view.own_steer, view.own_speed, view.own_heading])
        else:
            si[:, : self.k] = np.column_stack([view.own_pos, view.own_vel])
        block = np.asarray(obs[:, self.codec.opp_slice], dtype=np.float64)
        if self.codec.frame == "world":
            opp = block * self.opp.scale(self.codec.half_x, self.codec.half_y)
        elif self.opp.has_heading:
            heading = block[:, 4] * math.pi
            if self.own.has_heading:
                heading = wrap_heading(view.own_heading + heading)
            speed = view.opp_vel[:, 0] * np.cos(heading) + view.opp_vel[:, 1] * np.sin(heading)
            opp = np.column_stack([view.opp_pos, np.zeros(n), speed, heading])
        else:
            opp = np.column_stack([view.opp_pos, view.opp_vel])
        si[:, self.k : self.k + self.m] = np.where(view.seen[:, None], opp, 0.0)
        si[:, self.seen_index] = obs[:, self.seen_index]
        si[:, self.time_index] = np.asarray(obs[:, self.time_index], dtype=np.float64) * self.horizon_s
        return si

    def from_si(self, si: np.ndarray) -> np.ndarray:
        """Normalised observations ``(n, dim)`` float32 from SI rows ``(n, dim)``: what the exported graph computes."""
        si = np.asarray(si, dtype=np.float64)
        own = si[:, : self.k].T.copy()
        opp = si[:, self.k : self.k + self.m].T.copy()
        for state, dynamics in ((own, self.own), (opp, self.opp)):
            if dynamics.has_heading:
                state[4] = wrap_heading(state[4])
        own_rows, opp_rows = self.own.from_state(own), self.opp.from_state(opp)
        flag = si[:, self.seen_index]
        obs = np.array(
            self.codec.encode(
                own_rows,
                opp_rows,
                opp[0] - own[0],
                opp[1] - own[1],
                flag > 0,
                si[:, self.time_index] * (1.0 / self.horizon_s),
            ),
            dtype=np.float32,
        )
        obs[:, self.seen_index] = np.sign(flag)
        return np.clip(obs, -1.0, 1.0, out=obs)
