"""Discrete-time dynamic programming for the point-mass pursuit-evasion game, on the game's own ``dt``.

The value ``V(x)`` of a state is the smallest ``‖r‖ - 2c`` (distance minus the capture distance,
m) that the pursuer can force within the horizon against the best evader, so ``V ≤ 0`` is
exactly the set of states the pursuer captures from. One step of the game (``pecli.game``'s
explicit Euler) is ``r' = r + (v_e - v_p) dt`` and ``v' = clip(v + a dt)``, and the iteration is

    V_0 = l,   V_{k+1}(x) = min(l(x), max over a_e of min over a_p of V_k(x'))        (order "maxmin")

or with ``min over a_p of max over a_e`` (order "minmax": the evader answers the pursuer), where
``l(x) = ‖r‖ - 2c``. The order matters at this ``dt``: one step of acceleration (``a_max dt``,
0.98 m/s in ``point_mass.yaml``) is large next to the speeds, and the player who answers gets it
for free. ``maxmin`` lets the pursuer copy the evader's input, which keeps the relative velocity
constant as in the continuous-time game, and agrees with the closed form (:mod:`pecli.hj.oracle`). Every input in each player's box ``[-a_max, a_max]^2`` counts, through
:func:`~pecli.hj.filters.window_extreme` along each velocity axis (the box is a product, so the
extreme separates by axis). The position then moves by the *old* velocity, a translation along
``r_x`` that depends only on the x velocities (and likewise for y): a linear interpolation with
precomputed indices and weights, applied to the value array seen as a matrix ``(x half, y half)``.
No Python loop runs over grid nodes; one iteration costs a few dozen passes over the array.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from pecli.hj.filters import window_extreme
from pecli.hj.grid import Grid
from pecli.hj.problem import Problem


def capture_target(grid: Grid, capture_distance: float) -> np.ndarray:
    """``l = ‖r‖ - 2c`` on every node, float32, shape ``grid.shape``."""
    x_axis, y_axis = grid.position_axes()
    x_shape, y_shape = [1] * len(grid.axes), [1] * len(grid.axes)
    x_shape[x_axis], y_shape[y_axis] = grid.shape[x_axis], grid.shape[y_axis]
    rx = grid.axes[x_axis].nodes().reshape(x_shape)
    ry = grid.axes[y_axis].nodes().reshape(y_shape)
    distance = np.sqrt(rx**2 + ry**2) - capture_distance
    return np.broadcast_to(distance, grid.shape).astype(np.float32)


class PositionShift:
    """``F ↦ F(r + (v_e - v_p) dt, v)``: one half's position moved by that half's velocity, linearly interpolated.

    Precomputes, for every node of each half, the flat index of the node below the moved position
    along ``r`` (the one above is the next index: ``r`` is the half's last axis) and the weight of
    the one above. Positions past the grid take the edge value.
    """

    def __init__(self, grid: Grid, dt: float) -> None:
        self.halves = [self._half(grid, axes, dt) for axes in (grid.x_axes, grid.y_axes)]
        self.sizes = grid.half_sizes

    @staticmethod
    def _half(grid: Grid, axes: tuple, dt: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        position = axes[-1]
        nodes = np.meshgrid(*(a.nodes() for a in axes), indexing="ij")
        speed = nodes[0] if grid.model == "rel4d" else nodes[1] - nodes[0]  # w, or v_e - v_p
        u = (np.clip(nodes[-1] + speed * dt, position.low, position.high) - position.low) / position.spacing
        lower = np.minimum(np.floor(u).astype(np.int64), position.n - 2)
        weight = (u - lower).astype(np.float32).ravel()
        start_of_line = np.arange(lower.size).reshape(lower.shape) - np.arange(position.n)  # flat index of r's node 0
        low_index = (start_of_line + lower).ravel()
        return low_index, low_index + 1, weight

    def __call__(self, values: np.ndarray) -> np.ndarray:
        matrix = values.reshape(self.sizes)
        low, high, weight = self.halves[0]
        below = np.take(matrix, low, axis=0)
        above = np.take(matrix, high, axis=0)
        above -= below
        above *= weight[:, None]
        below += above
        low, high, weight = self.halves[1]
        out = np.take(below, low, axis=1)
        above = np.take(below, high, axis=1)
        above -= out
        above *= weight
        out += above
        return out.reshape(values.shape)


def _reaches(problem: Problem) -> dict[str, list[tuple[int, float]]]:
    """Per player, ``(axis, window in cells)`` for each velocity axis its acceleration moves."""
    grid = problem.grid
    out = {}
    for role, accel in (("pursuer", problem.game.pursuer_a_max), ("evader", problem.game.evader_a_max)):
        axes, _ = grid.velocity_axes(role)
        out[role] = [(k, accel * problem.dt / grid.axes[k].spacing) for k in axes]
    return out


def input_extreme(values: np.ndarray, problem: Problem) -> np.ndarray:
    """``min over a_p of max over a_e`` (or the other order) of ``values`` at the changed velocities."""
    reaches = _reaches(problem)
    if problem.order == "minmax":  # the pursuer commits first: the evader's max is inside
        inner, outer = ("evader", "max"), ("pursuer", "min")
    else:
        inner, outer = ("pursuer", "min"), ("evader", "max")
    out = values
    for role, kind in (inner, outer):
        for axis, reach in reaches[role]:
            out = window_extreme(out, axis, reach, kind)  # type: ignore[arg-type]
    return out


def solve(problem: Problem, on_step: Callable[[int, int], None] | None = None) -> np.ndarray:
    """The value after ``problem.steps`` iterations, float32, shape ``problem.grid.shape``.

    ``on_step(done, total)`` is called after every iteration (for progress bars).
    """
    target = capture_target(problem.grid, problem.game.capture_distance)
    shift = PositionShift(problem.grid, problem.dt)
    values = target.copy()
    for k in range(problem.steps):
        np.minimum(shift(input_extreme(values, problem)), target, out=values)
        if on_step is not None:
            on_step(k + 1, problem.steps)
    return values
