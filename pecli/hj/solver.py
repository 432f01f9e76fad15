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
constant as in the continuous-time game, and agrees with the closed form (:mod:`pecli.hj.oracle`).

Each step has two parts, both free of Python loops over nodes:

1. **Inputs.** Every input in each player's box ``[-a_max, a_max]^2`` counts: the box is a product,
   so the extreme over it separates into one window per velocity axis
   (:func:`~pecli.hj.filters.window_extreme`), the answering player's inside the other's.
2. **Positions.** The position moves by the *old* velocity: along ``r_x`` by an amount that depends
   only on the x velocities, and likewise for y. That is a 1-D interpolation per half with
   indices and weights precomputed once, applied to the value array seen as a matrix
   ``(x half, y half)``: a sparse matrix product on each side. The interpolation is cubic
   (Catmull–Rom): it smears the narrow "tubes" of states that pass through the capture disk far
   less than linear interpolation, which under-estimates the capture set by a quarter at the
   default grid (cubic: by 7 %).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from scipy import sparse

from pecli.errors import ConfigError
from pecli.hj.filters import window_extreme
from pecli.hj.grid import Grid
from pecli.hj.problem import Problem


def _moves(grid: Grid, axes: tuple, dt: float) -> tuple[list[tuple[int, np.ndarray]], np.ndarray, np.ndarray]:
    """How one half's positions move in one step, for every node of the half (C order).

    Returns ``moves``, a list of ``(position axis in the half, its coordinate one step later)``,
    and the relative position ``e - p`` now and one step later (m), all flat over the half's nodes.
    A relative position moves by ``(v_e - v_p) dt``; an absolute one by its own velocity, and stops
    at the walls (the arena's edges, which are the axis's ends) as in the game.
    """
    nodes = [node.ravel() for node in np.meshgrid(*(a.nodes() for a in axes), indexing="ij")]
    if grid.model == "abs8d":
        vp, ve, p, e = nodes
        p_next = np.clip(p + vp * dt, axes[2].low, axes[2].high)
        e_next = np.clip(e + ve * dt, axes[3].low, axes[3].high)
        return [(2, p_next), (3, e_next)], e - p, e_next - p_next
    speed = nodes[0] if grid.model == "rel4d" else nodes[1] - nodes[0]  # w, or v_e - v_p
    r = nodes[-1]
    return [(len(axes) - 1, r + speed * dt)], r, r + speed * dt


def capture_target(grid: Grid, capture_distance: float, dt: float | None = None) -> np.ndarray:
    """``l = ‖r‖ - 2c`` on every node, float32, shape ``grid.shape``.

    With ``dt``, the smaller of ``l`` now and ``l`` one step later: the next position follows from
    the current velocities alone, so no input changes it, and using it exactly (instead of through
    interpolation) keeps the capture disk sharp.
    """
    (_, x_now, x_next), (_, y_now, y_next) = (_moves(grid, axes, dt or 0.0) for axes in (grid.x_axes, grid.y_axes))
    # the value array is (x half, y half) flattened: every x node against every y node
    values = np.hypot(x_now[:, None], y_now[None, :])
    if dt is not None:
        np.minimum(values, np.hypot(x_next[:, None], y_next[None, :]), out=values)
    values -= capture_distance
    return values.astype(np.float32).reshape(grid.shape)


def catmull_rom(t: np.ndarray) -> np.ndarray:
    """Weights ``(4, n)`` of the nodes ``i-1, i, i+1, i+2`` for a point at ``i + t``, ``t`` in [0, 1]."""
    t2, t3 = t * t, t * t * t
    return np.stack(
        [-0.5 * t + t2 - 0.5 * t3, 1.0 - 2.5 * t2 + 1.5 * t3, 0.5 * t + 2.0 * t2 - 1.5 * t3, 0.5 * (t3 - t2)]
    )


class PositionShift:
    """``F ↦ F(positions one step later, v)``: each half's positions moved by that half's velocities.

    Along ``r_x`` (or ``p_x`` and ``e_x``) the move depends only on the x half's velocities, so it is
    one sparse matrix ``S_x`` (x half × x half) with Catmull–Rom weights (four per moved position
    axis, their products for two), and likewise ``S_y``; with the value seen as a matrix ``V``
    (x half × y half) the shift is ``S_x V S_yᵀ``. Nodes past the grid's edge repeat the edge node.
    """

    def __init__(self, grid: Grid, dt: float) -> None:
        self.sizes = grid.half_sizes
        self.x, self.y = (self._matrix(grid, axes, dt) for axes in (grid.x_axes, grid.y_axes))

    @staticmethod
    def _matrix(grid: Grid, axes: tuple, dt: float) -> sparse.csr_matrix:
        moves, _, _ = _moves(grid, axes, dt)
        shape = tuple(a.n for a in axes)
        strides = np.array([int(np.prod(shape[k + 1 :])) for k in range(len(shape))])
        rows = np.arange(int(np.prod(shape)))
        columns, weights = rows[None, :], np.ones((1, rows.size), np.float32)
        for k, moved in moves:  # the tensor product of one Catmull–Rom stencil per moved axis
            position = axes[k]
            u = (np.clip(moved, position.low, position.high) - position.low) / position.spacing
            lower = np.minimum(np.floor(u).astype(np.int64), position.n - 2)
            own = rows // strides[k] % position.n  # this node's index along the axis
            nodes = np.clip(lower + np.arange(-1, 3)[:, None], 0, position.n - 1)  # (4, nodes)
            columns = (columns[:, None, :] + ((nodes - own) * strides[k])[None]).reshape(-1, rows.size)
            weights = (weights[:, None, :] * catmull_rom(u - lower).astype(np.float32)[None]).reshape(-1, rows.size)
        rows = np.broadcast_to(rows, columns.shape)
        return sparse.csr_matrix((weights.ravel(), (rows.ravel(), columns.ravel())), shape=(rows.shape[1],) * 2)

    def __call__(self, values: np.ndarray, out: np.ndarray, work: np.ndarray) -> None:
        """Write the shifted ``values`` into ``out``; ``work`` is overwritten (all of the grid's shape, distinct)."""
        x_size, y_size = self.sizes
        moved_x = self.x @ values.reshape(x_size, y_size)
        transposed = work.reshape(y_size, x_size)
        _transpose(moved_x, transposed)
        _transpose(self.y @ transposed, out.reshape(x_size, y_size))


def _transpose(source: np.ndarray, out: np.ndarray, stripe: int = 256) -> None:
    """``out[...] = source.T`` for 2-D arrays, a stripe of rows at a time (kinder to the cache than one copy)."""
    for start in range(0, source.shape[0], stripe):
        out[:, start : start + stripe] = source[start : start + stripe].T


def _reaches(problem: Problem) -> dict[str, list[tuple[int, float]]]:
    """Per player, ``(axis, window in cells)`` for each velocity axis its acceleration moves."""
    grid = problem.grid
    out = {}
    for role, accel in (("pursuer", problem.game.pursuer_a_max), ("evader", problem.game.evader_a_max)):
        axes = grid.velocity_axes(role)
        out[role] = [(k, accel * problem.dt / grid.axes[k].spacing) for k in axes]
    return out


class Iteration:
    """One step of the dynamic programme, ``V ← min(l, shift(inputs(V)))``, in place.

    Works on three buffers of the grid's shape allocated once: fresh large arrays cost page faults.
    """

    def __init__(self, problem: Problem) -> None:
        self.target = capture_target(problem.grid, problem.game.capture_distance, problem.dt)
        self.shift = PositionShift(problem.grid, problem.dt)
        reaches = _reaches(problem)
        if problem.order == "minmax":  # the pursuer commits first: the evader's max is inside
            stages = [("max", reaches["evader"]), ("min", reaches["pursuer"])]
        else:
            stages = [("min", reaches["pursuer"]), ("max", reaches["evader"])]
        self.filters = [(kind, axis, reach) for kind, axes in stages for axis, reach in axes]
        self.walls = _wall_slices(problem.grid)
        self.buffers = [np.empty(self.target.shape, np.float32) for _ in range(3)]

    def __call__(self, values: np.ndarray) -> None:
        first, second, scratch = self.buffers
        source, into = values, first
        for kind, axis, reach in self.filters:  # the inputs: each player's window along each velocity axis
            window_extreme(source, axis, reach, kind, out=into, scratch=scratch)  # type: ignore[arg-type]
            source, into = into, (second if into is first else first)
        self.shift(source, out=values, work=into)  # then the positions move
        np.minimum(values, self.target, out=values)
        for into_wall, at_rest in self.walls:  # a player at a wall has lost its velocity into it
            values[into_wall] = values[at_rest]


def _wall_slices(grid: Grid) -> list[tuple[tuple, tuple]]:
    """``abs8d``: ``(states at a wall moving into it, the same states at rest)`` index pairs, one per wall,
    player and half; nothing for the relative models, which know no walls.

    The game zeroes the velocity component into a wall when a step ends there, so a value at a wall
    node with a velocity into the wall is the value of the same node at rest (such states occur only
    as the landing point of a step, which the shift reads at the grid's edge).
    """
    if grid.model != "abs8d":
        return []
    pairs = []
    half = len(grid.x_axes)
    for offset in (0, half):
        for velocity, position in ((offset, offset + 2), (offset + 1, offset + 3)):
            zero = grid.axes[velocity].n // 2  # v = 0 (the velocity axis is symmetric with an odd count)
            for edge, into in ((0, slice(0, zero)), (grid.axes[position].n - 1, slice(zero + 1, None))):
                into_wall, at_rest = [slice(None)] * len(grid.axes), [slice(None)] * len(grid.axes)
                into_wall[position] = at_rest[position] = edge
                into_wall[velocity], at_rest[velocity] = into, slice(zero, zero + 1)
                pairs.append((tuple(into_wall), tuple(at_rest)))
    return pairs


MAX_NODES = 400_000_000  # (ours) about 5 float32 copies of the grid fit in 8 GB


def solve(problem: Problem, on_step: Callable[[int, int], None] | None = None) -> np.ndarray:
    """The value after ``problem.steps`` iterations, float32, shape ``problem.grid.shape``.

    ``on_step(done, total)`` is called after every iteration (for progress bars).
    """
    return solve_with_capture_steps(problem, on_step)[0]


def capture_steps_dtype(steps: int) -> type:
    """The smallest unsigned integer type that holds ``0 .. steps + 1``."""
    return np.uint8 if steps < 255 else np.uint16


def solve_with_capture_steps(
    problem: Problem, on_step: Callable[[int, int], None] | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """The value (as :func:`solve`) and the steps to capture of every node.

    ``steps[x]`` is the fewest steps in which the pursuer forces a capture from ``x``, the first
    ``k`` with ``V_k(x) ≤ 0`` (``V_k`` only falls with ``k``), or ``problem.steps + 1`` where it cannot
    within the horizon; unsigned integers of the grid's shape.
    """
    nodes = problem.grid.size
    if nodes > MAX_NODES:
        raise ConfigError(
            f"the grid {problem.grid.describe()} has {nodes:,} nodes; the solver keeps several "
            f"float32 copies, so at most {MAX_NODES:,} (about 8 GB) are allowed: use a coarser --grid"
        )
    step = Iteration(problem)
    values = capture_target(problem.grid, problem.game.capture_distance)
    steps = np.zeros(values.shape, capture_steps_dtype(problem.steps))
    for k in range(problem.steps):
        steps += values > 0.0
        step(values)
        if on_step is not None:
            on_step(k + 1, problem.steps)
    steps += values > 0.0
    return values, steps
