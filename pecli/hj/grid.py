"""The state grid of the point-mass game, and multilinear interpolation on it.

Every model splits into an x half and a y half, because a point mass moves along x and y
independently (the walls too act per axis); only the capture disk couples them. A value array
has the shape of the x half's axes followed by the y half's, velocities first and positions
last in each half (the longest axes innermost, which keeps NumPy's inner loops long):

``rel4d``  ``(w_x, r_x, w_y, r_y)``: the evader's velocity and position relative to the pursuer's,
           ``w = v_e - v_p`` (m/s) and ``r = e - p`` (m).
``rel6d``  ``(vp_x, ve_x, r_x, vp_y, ve_y, r_y)``: both players' own velocities (m/s), so that each
           player's speed limit applies to its own velocity, and the relative position.
``abs8d``  ``(vp_x, ve_x, p_x, e_x, vp_y, ve_y, p_y, e_y)``: both players' own velocities and
           positions in the arena (m), so that the value knows the walls.

Relative positions span ``±width`` and ``±height`` of the arena (every relative position a game can
reach), absolute ones the arena itself; velocities span ``±(v_p + v_e)`` per axis in ``rel4d`` and
each player's ``±v_max`` in ``rel6d`` and ``abs8d``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import numpy as np

from pecli.errors import ConfigError

Model = Literal["rel4d", "rel6d", "abs8d"]
MODELS: tuple[Model, ...] = ("rel4d", "rel6d", "abs8d")

DEFAULT_MODEL: Model = "abs8d"
"""The model ``hj`` and ``pecli hj solve`` use unless told otherwise: the one that knows the walls."""

DEFAULT_SIZES: dict[Model, tuple[int, int]] = {"rel4d": (81, 21), "rel6d": (41, 11), "abs8d": (15, 5)}
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
    """A product grid: the x half's axes, then the y half's (velocities first, positions last in each half)."""

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
        return math.prod(a.n for a in self.x_axes), math.prod(a.n for a in self.y_axes)

    @property
    def size(self) -> int:
        return math.prod(self.shape)  # Python's integers: a huge grid's count does not wrap around

    def describe(self) -> str:
        """``23x81x23x81`` style."""
        return "x".join(str(n) for n in self.shape)

    # ------------------------------------------------------------------ states
    def points(
        self, pursuer_pos: np.ndarray, pursuer_vel: np.ndarray, evader_pos: np.ndarray, evader_vel: np.ndarray
    ) -> np.ndarray:
        """Grid coordinates ``(n, d)`` of states given as world positions (m) and velocities (m/s), each ``(n, 2)``."""
        if self.model == "abs8d":
            return np.stack(
                [
                    pursuer_vel[:, 0],
                    evader_vel[:, 0],
                    pursuer_pos[:, 0],
                    evader_pos[:, 0],
                    pursuer_vel[:, 1],
                    evader_vel[:, 1],
                    pursuer_pos[:, 1],
                    evader_pos[:, 1],
                ],
                axis=1,
            )
        r = evader_pos - pursuer_pos
        if self.model == "rel4d":
            w = evader_vel - pursuer_vel
            columns = (w[:, 0], r[:, 0], w[:, 1], r[:, 1])
        else:
            columns = (pursuer_vel[:, 0], evader_vel[:, 0], r[:, 0], pursuer_vel[:, 1], evader_vel[:, 1], r[:, 1])
        return np.stack(columns, axis=1)

    def velocity_axes(self, role: str) -> tuple[int, int]:
        """The axes (x, y) that ``role``'s acceleration moves (in ``rel4d`` both players move ``w``)."""
        first = 0 if self.model == "rel4d" or role == "pursuer" else 1
        return first, first + len(self.x_axes)

    # ------------------------------------------------------------------ interpolation
    def interpolate(self, values: np.ndarray, points: np.ndarray) -> np.ndarray:
        """Multilinear interpolation of ``values`` (shape :attr:`shape`) at ``points`` ``(n, d)``,
        clamped to the grid."""
        half = len(self.x_axes)
        return self.interpolate_pairs(values, points[:, None, :half], points[:, None, half:])[:, 0, 0]

    def interpolate_pairs(self, values: np.ndarray, x_points: np.ndarray, y_points: np.ndarray) -> np.ndarray:
        """The interpolated value at every pairing of an x half and a y half, game by game.

        ``x_points`` ``(n, a, k)`` are x-half coordinates, ``y_points`` ``(n, b, k)`` y-half ones;
        returns ``(n, a, b)``. The value array is (x half × y half), so one game's ``a × b`` states
        need one block of it: the x nodes around any of its x halves against the y nodes around any
        of its y halves. Gathered once, the block is weighted by two small matrix products.
        """
        x_nodes, x_weights = self._patch(x_points, self.x_axes)
        y_nodes, y_weights = self._patch(y_points, self.y_axes)
        flat = values.reshape(-1)
        block = flat[(x_nodes * self.half_sizes[1])[:, :, None] + y_nodes[:, None, :]]  # (n, X, Y)
        return x_weights @ block.astype(x_weights.dtype) @ y_weights.transpose(0, 2, 1)

    @staticmethod
    def _patch(points: np.ndarray, axes: tuple[Axis, ...]) -> tuple[np.ndarray, np.ndarray]:
        """The smallest box of one half's nodes that holds the cells of all ``points`` ``(n, a, k)`` of each game,
        and each point's multilinear weights on it: node indices ``(n, P)`` (flat, C order) and ``(n, a, P)``.

        Points are clamped to the grid. Along each axis the box spans the same number of nodes in
        every game, the most any game needs; past the grid's end its extra nodes repeat the last one
        and carry no weight.
        """
        n, a = points.shape[:2]
        nodes = np.zeros((n, 1), dtype=np.int64)
        weights = np.ones((n, a, 1))
        for k, axis in enumerate(axes):
            u = (np.clip(points[:, :, k], axis.low, axis.high) - axis.low) / axis.spacing
            lower = np.minimum(np.floor(u), axis.n - 2).astype(np.int64)  # (n, a)
            t = u - lower
            first = lower.min(axis=1)  # (n,)
            span = int((lower - first[:, None]).max(initial=0)) + 2
            local = np.zeros((n, a, span))
            at = lower - first[:, None]
            np.put_along_axis(local, at[:, :, None], (1.0 - t)[:, :, None], axis=2)
            np.put_along_axis(local, at[:, :, None] + 1, t[:, :, None], axis=2)
            index = np.minimum(first[:, None] + np.arange(span), axis.n - 1)  # (n, span)
            size = nodes.shape[1] * span
            nodes = (nodes[:, :, None] * axis.n + index[:, None, :]).reshape(n, size)
            weights = (weights[:, :, :, None] * local[:, :, None, :]).reshape(n, a, size)
        return nodes, weights


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
    if model == "abs8d":
        n_vel += 1 - n_vel % 2  # an odd count puts v = 0 on a node: a wall sets the velocity into it to 0
    halves = []
    for label, extent in zip("xy", extents):
        if model == "rel4d":
            axes = [_relative_velocity_axis(f"w_{label}", vp + ve, n_vel, evader_step)]
        else:
            axes = [Axis(f"vp_{label}", -vp, vp, n_vel), Axis(f"ve_{label}", -ve, ve, n_vel)]
        if model == "abs8d":
            axes += [
                Axis(f"p_{label}", -extent / 2, extent / 2, n_pos),
                Axis(f"e_{label}", -extent / 2, extent / 2, n_pos),
            ]
        else:
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
