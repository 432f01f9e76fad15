"""The closed-form value of the 4D relative game with equal acceleration bounds : a free test oracle.

With equal bounds the pursuer can copy the evader's acceleration, and the evader can copy the
pursuer's, so under optimal play the relative velocity ``w`` stays constant and the value is the
closest approach along a straight line:

    V(r, w) = min over s in [0, T] of ‖r + w s‖ - 2c                    (continuous time)
    V(r, w) = min over k in {0, ..., K} of ‖r + w k dt‖ - 2c            (the game, checked every dt)

The discrete form is what the game plays (capture is checked after each step, so a fast pass
between two steps can miss the disk); the solver is compared with it.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from pecli.hj.problem import Problem


def continuous_value(r: np.ndarray, w: np.ndarray, horizon: float, capture_distance: float) -> np.ndarray:
    """``min_{s∈[0,T]} ‖r + w s‖ - 2c`` for ``r, w`` ``(n, 2)`` (m, m/s) and ``T`` in s; returns ``(n,)`` m."""
    speed_sq = np.sum(w * w, axis=1)
    s = np.divide(-np.sum(r * w, axis=1), speed_sq, out=np.zeros_like(speed_sq), where=speed_sq > 0)
    s = np.clip(s, 0.0, horizon)
    return np.linalg.norm(r + w * s[:, None], axis=1) - capture_distance


def discrete_value(r: np.ndarray, w: np.ndarray, steps: int, dt: float, capture_distance: float) -> np.ndarray:
    """``min_{k=0..K} ‖r + w k dt‖ - 2c`` for ``r, w`` ``(n, 2)``; returns ``(n,)`` m.

    The distance along the line is convex in ``k``, so the minimum is at one of the two whole steps
    around the continuous minimiser.
    """
    speed_sq = np.sum(w * w, axis=1) * dt * dt
    k = np.divide(-np.sum(r * w, axis=1) * dt, speed_sq, out=np.zeros_like(speed_sq), where=speed_sq > 0)
    k = np.clip(k, 0.0, steps)
    best = np.full(r.shape[0], np.inf)
    for step in (np.floor(k), np.minimum(np.floor(k) + 1, steps)):
        best = np.minimum(best, np.linalg.norm(r + w * (step * dt)[:, None], axis=1))
    return best - capture_distance


def solution_accuracy(problem: Problem, values: np.ndarray, states: int = 20_000, seed: int = 1) -> dict[str, float]:
    """How well a rel4d value matches both closed forms on ``states`` random states.

    The states have relative positions in the arena's middle (``|r_i| <= 7`` m) and relative velocities
    within the limits (``|w_i| <= 5`` m/s), drawn with ``seed``. ``values`` is the solved value on
    ``problem.grid`` (shape ``problem.grid.shape``, m). Returns ``sign_discrete`` and ``sign_continuous``
    (the share of states on the same side of capture as the closed form) and ``error_discrete`` and
    ``error_continuous`` (mean absolute difference, m). Equal acceleration bounds only: other games
    have no closed form.
    """
    rng = np.random.default_rng(seed)
    r, w = rng.uniform(-7.0, 7.0, (states, 2)), rng.uniform(-5.0, 5.0, (states, 2))
    zeros = np.zeros_like(r)
    solved = problem.grid.interpolate(values, problem.grid.points(zeros, zeros, r, w))
    game = problem.game
    out = {}
    for name, exact in (
        ("discrete", discrete_value(r, w, problem.steps, game.dt, game.capture_distance)),
        ("continuous", continuous_value(r, w, problem.steps * game.dt, game.capture_distance)),
    ):
        out[f"sign_{name}"] = float(np.mean((solved <= 0) == (exact <= 0)))
        out[f"error_{name}"] = float(np.mean(np.abs(solved - exact)))
    return out
