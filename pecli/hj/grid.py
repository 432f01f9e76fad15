"""The state grid of the relative point-mass game, and multilinear interpolation on it.

Both models split into an x half and a y half, because a point mass moves along x and y
independently; only the capture disk couples them. A value array has the shape of the x
half's axes followed by the y half's, velocities first and the position last in each half
(the longest axis innermost, which keeps NumPy's inner loops long):

``rel4d``  ``(w_x, r_x, w_y, r_y)``: the evader's velocity and position relative to the pursuer's,
           ``w = v_e - v_p`` (m/s) and ``r = e - p`` (m).
``rel6d``  ``(vp_x, ve_x, r_x, vp_y, ve_y, r_y)``: both players' own velocities (m/s), so that each
           player's speed limit applies to its own velocity, and the relative position.

Positions span ``±width`` and ``±height`` of the arena (every relative position a game can reach);
velocities span ``±(v_p + v_e)`` per axis in ``rel4d`` and each player's ``±v_max`` in ``rel6d``.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass
from typing import Literal

import numpy as np

from pecli.errors import ConfigError

Model = Literal["rel4d", "rel6d"]
MODELS: tuple[Model, ...] = ("rel4d", "rel6d")

DEFAULT_SIZES: dict[Model, tuple[int, int]] = {"rel4d": (81, 21), "rel6d": (41, 11)}
"""Nodes per position axis and per velocity axis of each model's default grid."""


@dataclass(frozen=True)
class Axis:
    """``n`` uniform nodes from ``low`` to ``high`` (inclusive)."""

    name: str
    low: float
    high: float
    n: int

    @property
    def spacing(self) -> float:
        return (self.high - self.low) / (self.n - 1)

    def nodes(self) -> np.ndarray:
        """The node coordinates ``(n,)``."""
        return np.linspace(self.low, self.high, self.n)


@dataclass(frozen=True)
class Grid:
    """A product grid: the x half's axes, then the y half's (velocities first, the position last in each half)."""

    model: Model
    x_axes: tuple[Axis, ...]
    y_axes: tuple[Axis, ...]

    @property
    def axes(self) -> tuple[Axis, ...]:
        return self.x_axes + self.y_axes

    @property
    def shape(self) -> tuple[int, ...]:
        return tuple(axis.n for axis in self.axes)

    @property
    def half_sizes(self) -> tuple[int, int]:
        """Nodes of the x half and of the y half: the value array is ``(X, Y)`` when flattened by halves."""
        return int(np.prod([a.n for a in self.x_axes])), int(np.prod([a.n for a in self.y_axes]))

    @property
    def size(self) -> int:
        return int(np.prod(self.shape))

    def describe(self) -> str:
        """``23x81x23x81`` style."""
        return "x".join(str(n) for n in self.shape)

    # ------------------------------------------------------------------ states
    def points(self, pursuer_pos: np.ndarray, pursuer_vel: np.ndarray, evader_pos: np.ndarray,
               evader_vel: np.ndarray) -> np.ndarray:
        """Grid coordinates ``(n, d)`` of states given as world positions (m) and velocities (m/s), each ``(n, 2)``."""
        r = evader_pos - pursuer_pos
        if self.model == "rel4d":
            w = evader_vel - pursuer_vel
            columns = (w[:, 0], r[:, 0], w[:, 1], r[:, 1])
        else:
            columns = (pursuer_vel[:, 0], evader_vel[:, 0], r[:, 0], pursuer_vel[:, 1], evader_vel[:, 1], r[:, 1])
        return np.stack(columns, axis=1)

    def velocity_axes(self, role: str) -> tuple[tuple[int, int], float]:
        """The axes (x, y) that ``role``'s acceleration moves, and the sign of its effect on them."""
        if self.model == "rel4d":
            return (0, 2), (-1.0 if role == "pursuer" else 1.0)
        return ((0, 3), 1.0) if role == "pursuer" else ((1, 4), 1.0)

    def position_axes(self) -> tuple[int, int]:
        """The axes of the relative position ``r = e - p`` (x, y)."""
        return len(self.x_axes) - 1, len(self.axes) - 1

    # ------------------------------------------------------------------ interpolation
    def interpolate(self, values: np.ndarray, points: np.ndarray) -> np.ndarray:
        """Multilinear interpolation of ``values`` (shape :attr:`shape`) at ``points`` ``(n, d)``, clamped to the grid."""
        lower, weight = self._cells(points)
        out = np.zeros(points.shape[0])
        for corner in itertools.product((0, 1), repeat=len(self.axes)):
            index = tuple(lower[:, k] + c for k, c in enumerate(corner))
            w = np.prod([weight[:, k] if c else 1.0 - weight[:, k] for k, c in enumerate(corner)], axis=0)
            out += w * values[index]
        return out

    def gradient(self, values: np.ndarray, points: np.ndarray, axes: tuple[int, ...]) -> np.ndarray:
        """Central differences ``(n, len(axes))`` of the interpolated value along ``axes``, one node spacing wide
        (one-sided at the grid's edges; points outside are moved onto it); units: value per unit of each axis."""
        out = np.empty((points.shape[0], len(axes)))
        points = np.clip(points, [a.low for a in self.axes], [a.high for a in self.axes])
        for j, k in enumerate(axes):
            axis = self.axes[k]
            ahead, behind = points.copy(), points.copy()
            ahead[:, k] = np.minimum(points[:, k] + axis.spacing, axis.high)
            behind[:, k] = np.maximum(points[:, k] - axis.spacing, axis.low)
            width = ahead[:, k] - behind[:, k]
            out[:, j] = (self.interpolate(values, ahead) - self.interpolate(values, behind)) / width
        return out

    def _cells(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Lower node index ``(n, d)`` of each point's cell and its fractional position in it ``(n, d)``."""
        lower = np.empty(points.shape, dtype=np.int64)
        weight = np.empty(points.shape)
        for k, axis in enumerate(self.axes):
            u = (np.clip(points[:, k], axis.low, axis.high) - axis.low) / axis.spacing
            lower[:, k] = np.minimum(np.floor(u), axis.n - 2)
            weight[:, k] = u - lower[:, k]
        return lower, weight


def make_grid(
    model: Model,
    sizes: tuple[int, int],
    extents: tuple[float, float],
    speed_limits: tuple[float, float],
    evader_step: float,
) -> Grid:
    """The grid of ``model`` with ``sizes = (position nodes, velocity nodes)`` per axis.

    ``extents`` are the arena's width and height (m), ``speed_limits`` the pursuer's and the
    evader's ``v_max`` per axis (m/s), ``evader_step`` the evader's ``a_max * dt`` (m/s).
    """
    if model not in MODELS:
        raise ConfigError(f"unknown HJ model '{model}' (known: {', '.join(MODELS)})")
    n_pos, n_vel = sizes
    if n_pos < 3 or n_vel < 3:
        raise ConfigError(f"an HJ grid needs at least 3 nodes per axis, got {n_pos},{n_vel}")
    vp, ve = speed_limits
    halves = []
    for label, extent in zip("xy", extents):
        if model == "rel4d":
            axes = [_relative_velocity_axis(f"w_{label}", vp + ve, n_vel, evader_step)]
        else:
            axes = [Axis(f"vp_{label}", -vp, vp, n_vel), Axis(f"ve_{label}", -ve, ve, n_vel)]
        axes.append(Axis(f"r_{label}", -extent, extent, n_pos))
        halves.append(tuple(axes))
    return Grid(model=model, x_axes=halves[0], y_axes=halves[1])


def _relative_velocity_axis(name: str, bound: float, n: int, step: float) -> Axis:
    """A relative-velocity axis whose spacing divides the evader's velocity change per step ``step`` (m/s).

    Then each player's input window spans whole cells (both, when the bounds are equal), so that
    "the pursuer copies the evader's input" keeps the relative velocity on its node, as it does in
    the game; with windows between nodes the min and max filters would smear the value along ``w``.
    The axis keeps about ``n`` nodes and covers at least ``±bound``.
    """
    cells = max(1, round(step / (2.0 * bound / (n - 1))))
    spacing = step / cells
    half = math.ceil(bound / spacing - 1e-9)
    return Axis(name, -half * spacing, half * spacing, 2 * half + 1)


def parse_sizes(text: str) -> tuple[int, int]:
    """``"81,21"`` (or ``81x21``) → ``(81, 21)``: nodes per position axis and per velocity axis."""
    parts = text.replace("x", ",").split(",")
    try:
        sizes = tuple(int(part) for part in parts)
    except ValueError:
        raise ConfigError(f"--grid takes two whole numbers, POSITIONS,VELOCITIES (e.g. 81,21), not '{text}'") from None
    if len(sizes) != 2:
        raise ConfigError(f"--grid takes two numbers, POSITIONS,VELOCITIES (e.g. 81,21), not '{text}'")
    if min(sizes) < 3:
        raise ConfigError(f"an HJ grid needs at least 3 nodes per axis, got '{text}'")
    return sizes  # type: ignore[return-value]
