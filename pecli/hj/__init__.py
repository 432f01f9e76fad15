"""The Hamilton–Jacobi baseline: optimal point mass vs point mass play from a dynamic-programming value.

``problem`` (what a value depends on), ``grid`` (the state grid, interpolation), ``filters``
(the best input along one velocity axis), ``solver`` (the iteration), ``oracle`` (the closed form
for equal accelerations), ``solution`` (the ``.npz`` file) and ``cache`` (reuse by key). The
policies that play from a solution are in :mod:`pecli.policies.hj`. See ``docs/hj.md``.
"""

from pecli.hj.cache import cache_dir, cache_path, cached, solve_cached
from pecli.hj.grid import DEFAULT_SIZES, MODELS, Grid
from pecli.hj.problem import ORDERS, PointMassGame, Problem
from pecli.hj.solution import Solution, SolutionError
from pecli.hj.solver import solve

__all__ = [
    "DEFAULT_SIZES",
    "MODELS",
    "ORDERS",
    "Grid",
    "PointMassGame",
    "Problem",
    "Solution",
    "SolutionError",
    "cache_dir",
    "cache_path",
    "cached",
    "solve",
    "solve_cached",
]
