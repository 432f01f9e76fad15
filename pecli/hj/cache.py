"""The solution cache: one ``.npz`` per problem key, reused while nothing that decides the value changed.

The folder is ``$PECLI_HJ_CACHE`` if set, else ``$XDG_CACHE_HOME/pecli/hj`` (``~/.cache/pecli/hj``).
A file is named ``<model>-<key>.npz``; the key (:meth:`pecli.hj.problem.Problem.cache_key`) hashes
the game's numbers, the model, the grid solved on, the order, the horizon, the backend and the
solver's version, so any change to one of them misses the cache, and an unreadable file is solved again.
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable
from pathlib import Path

from pecli.hj.problem import Problem
from pecli.hj.solution import Solution, SolutionError
from pecli.hj.solver import solve_with_capture_steps

CACHE_VARIABLE = "PECLI_HJ_CACHE"


def cache_dir() -> Path:
    """The folder of cached solutions (not created here)."""
    if folder := os.environ.get(CACHE_VARIABLE):
        return Path(folder).expanduser()
    base = os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache"
    return Path(base) / "pecli" / "hj"


def cache_path(problem: Problem) -> Path:
    """Where the solution of ``problem`` is cached."""
    return cache_dir() / f"{problem.model}-{problem.cache_key()}.npz"


def cached(problem: Problem, path: Path | None = None) -> Solution | None:
    """The solution of ``problem`` stored at ``path`` (default: the cache), or ``None`` if there is none,
    it is damaged, or it solves another problem."""
    path = cache_path(problem) if path is None else path
    try:
        solution = Solution.load(path)
    except SolutionError:
        return None
    return solution if solution.problem.cache_key() == problem.cache_key() else None


def solve_cached(
    problem: Problem,
    scenario_name: str,
    out: Path | None = None,
    force: bool = False,
    on_step: Callable[[int, int], None] | None = None,
) -> tuple[Solution, Path, bool]:
    """The solution of ``problem``, from ``out`` (default: the cache) when it is there, else solved and written.

    Returns the solution, its file and whether it was reused. ``force`` solves again regardless.
    """
    path = cache_path(problem) if out is None else Path(out)
    if not force and (found := cached(problem, path)) is not None:
        return found, path, True
    start = time.perf_counter()
    steps = None
    if problem.backend == "hj-reachability":
        from pecli.hj.reachability import solve_with_hj_reachability

        values = solve_with_hj_reachability(problem)
    else:
        values, steps = solve_with_capture_steps(problem, on_step=on_step)
    meta = {"scenario": scenario_name, "seconds": round(time.perf_counter() - start, 3)}
    solution = Solution(problem=problem, values=values, meta=meta, capture_steps=steps)
    solution.save(path)
    return solution, path, False
