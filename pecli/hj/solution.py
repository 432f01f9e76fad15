"""A solved value function with its problem, as one ``.npz`` file.

The file holds two arrays: ``values`` (float32, the grid's shape) and ``meta`` (a JSON string:
the :class:`~pecli.hj.solver.Problem`, its key, the scenario's name, the solve time, the
versions). Files are written atomically, so a reader never sees half of one.
"""

from __future__ import annotations

import json
import zipfile
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from pecli import __version__
from pecli.errors import ConfigError, PecliError
from pecli.hj.grid import Grid
from pecli.hj.problem import PointMassGame, Problem
from pecli.io import atomic_path
from pecli.scenario import Scenario


class SolutionError(PecliError):
    """A solution file that is missing, damaged, or made for another game."""


@dataclass
class Solution:
    """The value ``values`` (shape ``problem.grid.shape``, m) of ``problem``, and how it was made."""

    problem: Problem
    values: np.ndarray
    meta: dict[str, Any] = field(default_factory=dict)  # scenario, seconds

    @property
    def grid(self) -> Grid:
        return self.problem.grid

    @property
    def key(self) -> str:
        return self.problem.key()

    def summary(self) -> dict[str, Any]:
        """What ``pecli hj show`` prints: the problem, the key, and how the value splits."""
        captured = float(np.mean(self.values <= 0.0))
        return {
            "key": self.key,
            "model": self.grid.model,
            "grid": self.grid.describe(),
            "order": self.problem.order,
            "steps": self.problem.steps,
            "backend": self.problem.backend,
            "game": asdict(self.problem.game),
            "axes": {a.name: [a.low, a.high, a.n] for a in self.grid.axes},
            "capture_share": captured,
            **self.meta,
        }

    def save(self, path: str | Path) -> Path:
        """Write the solution to ``path`` (``.npz``) atomically."""
        path = Path(path)
        if path.suffix != ".npz":
            raise SolutionError(f"a solution file must end in .npz, not '{path.name}'")
        meta = {**self.meta, "problem": self.problem.to_dict(), "key": self.key, "pecli": __version__}
        with atomic_path(path) as tmp, tmp.open("wb") as handle:
            np.savez(handle, values=self.values, meta=np.array(json.dumps(meta)))
        return path

    @classmethod
    def load(cls, path: str | Path) -> Solution:
        """Read a solution; :class:`SolutionError` if the file is missing or damaged."""
        path = Path(path)
        if not path.is_file():
            raise SolutionError(f"no HJ solution at {path}")
        try:
            with np.load(path, allow_pickle=False) as data:
                meta = json.loads(str(data["meta"]))
                values = data["values"]
            problem = Problem.from_dict(meta.pop("problem"))
        except (OSError, ValueError, KeyError, TypeError, zipfile.BadZipFile, ConfigError) as exc:
            raise SolutionError(f"{path}: not a readable HJ solution ({type(exc).__name__}: {exc})") from None
        if values.shape != problem.grid.shape:
            raise SolutionError(f"{path}: values of shape {values.shape} do not fit the grid {problem.grid.describe()}")
        if meta.pop("key", None) != problem.key():
            raise SolutionError(f"{path}: was made by another solver version; solve again")
        meta.pop("pecli", None)
        return cls(problem=problem, values=values, meta=meta)

    def check_scenario(self, scenario: Scenario, source: str = "this solution") -> None:
        """Refuse a solution made for another game than ``scenario``'s (other limits, step, arena...)."""
        if PointMassGame.of(scenario) != self.problem.game:
            made_for = self.meta.get("scenario", "another scenario")
            raise SolutionError(
                f"{source} was solved for '{made_for}', whose game differs from '{scenario.name}' "
                "(arena, dt, capture distance, speed or acceleration limits): solve it for this scenario"
            )
