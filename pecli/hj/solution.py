"""A solved value function with its problem, as one ``.npz`` file.

The file holds ``values`` (float32, the grid's shape), ``capture_steps`` (unsigned integers, the
grid's shape; absent from ``hj-reachability`` solutions) and ``meta`` (a JSON string: the
:class:`~pecli.hj.solver.Problem`, its key, the scenario's name, the solve time, the versions).
Files are written atomically, so a reader never sees half of one; a file that cannot be read,
does not fit its grid or holds values that are not finite is refused with one line.
"""

from __future__ import annotations

import json
import math
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

MAX_META_BYTES = 1 << 20  # the solution's description: a problem and a few numbers, as JSON
NPY_HEADER_BYTES = 1 << 12  # an .npy file's header before its array


class SolutionError(PecliError):
    """A solution file that is missing, damaged, or made for another game."""


@dataclass
class Solution:
    """The value ``values`` (shape ``problem.grid.shape``, m) of ``problem``, and how it was made.

    ``capture_steps`` (same shape, or ``None``) holds, per node, the fewest steps in which the pursuer
    forces a capture, ``problem.steps + 1`` where it cannot within the horizon
    (:func:`pecli.hj.solver.solve_with_capture_steps`).
    """

    problem: Problem
    values: np.ndarray
    meta: dict[str, Any] = field(default_factory=dict)  # scenario, seconds
    capture_steps: np.ndarray | None = None
    _scores: np.ndarray | None = field(default=None, init=False, repr=False, compare=False)

    @property
    def grid(self) -> Grid:
        return self.problem.grid

    def scores(self) -> np.ndarray:
        """The score the players read, float32, the grid's shape (computed once).

        Where the pursuer forces a capture within the horizon, the steps it takes; elsewhere the
        horizon plus one plus the closest approach it can force (``V``, m). Lower is better for
        the pursuer, and every capturable state scores below every other. Without capture steps
        (``hj-reachability`` solutions) the score is ``V`` itself.
        """
        if self._scores is None:
            if self.capture_steps is None:
                self._scores = self.values
            else:
                self._scores = self.capture_steps.astype(np.float32)
                self._scores += np.maximum(self.values, 0.0)
        return self._scores

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
        arrays = {"values": self.values, "meta": np.array(json.dumps(meta))}
        if self.capture_steps is not None:
            arrays["capture_steps"] = self.capture_steps
        with atomic_path(path) as tmp, tmp.open("wb") as handle:
            np.savez(handle, **arrays)
        return path

    @classmethod
    def load(cls, path: str | Path) -> Solution:
        """Read a solution; :class:`SolutionError` if the file is missing or damaged."""
        path = Path(path)
        if not path.is_file():
            raise SolutionError(f"no HJ solution at {path}")
        if path.stat().st_size == 0:
            raise SolutionError(f"{path}: an empty file, not an HJ solution (an interrupted copy?); solve again")
        if not zipfile.is_zipfile(path):  # else NumPy reads it as a pickle and says to trust it
            raise SolutionError(f"{path}: not an HJ solution (not a .npz archive, or a truncated one)")
        try:
            with zipfile.ZipFile(path) as archive:
                sizes = {info.filename: info.file_size for info in archive.infolist()}
            if sizes.get("meta.npy", 0) > MAX_META_BYTES:
                raise ValueError(f"its meta unpacks to {sizes['meta.npy']:,} bytes")
            with np.load(path, allow_pickle=False) as data:
                meta = json.loads(str(data["meta"]))
                problem = Problem.from_dict(meta.pop("problem"))
                most = 8 * math.prod(problem.grid.shape) + NPY_HEADER_BYTES  # float64 values, uint steps
                for name in ("values.npy", "capture_steps.npy"):  # checked before a few megabytes unpack to gigabytes
                    if sizes.get(name, 0) > most:
                        raise ValueError(
                            f"{name} unpacks to {sizes[name]:,} bytes, more than its grid holds ({most:,})"
                        )
                values = data["values"]
                steps = data["capture_steps"] if "capture_steps" in data.files else None
        except (
            OSError,
            EOFError,
            ValueError,
            KeyError,
            TypeError,
            AttributeError,
            RecursionError,
            MemoryError,
            zipfile.BadZipFile,
            ConfigError,
        ) as exc:
            raise SolutionError(f"{path}: not a readable HJ solution ({type(exc).__name__}: {exc})") from None
        if meta.pop("key", None) != problem.key():
            raise SolutionError(f"{path}: was made by another solver version; solve again")
        for name, array in (("values", values), ("capture steps", steps)):
            if array is not None and array.shape != problem.grid.shape:
                raise SolutionError(
                    f"{path}: {name} of shape {array.shape} do not fit the grid {problem.grid.describe()}"
                )
        if values.dtype.kind != "f" or not np.isfinite(values).all():
            raise SolutionError(
                f"{path}: the values are not all finite numbers (NaN or infinite): the file is damaged; solve again"
            )
        if steps is not None and (steps.dtype.kind != "u" or steps.max(initial=0) > problem.steps + 1):
            raise SolutionError(
                f"{path}: the capture steps do not fit the horizon of {problem.steps}: the file is damaged; solve again"
            )
        meta.pop("pecli", None)
        return cls(problem=problem, values=values, meta=meta, capture_steps=steps)

    def check_scenario(self, scenario: Scenario, source: str = "this solution") -> None:
        """Refuse a solution made for another game than ``scenario``'s (other limits, step, arena...)."""
        if PointMassGame.of(scenario) != self.problem.game:
            made_for = self.meta.get("scenario", "another scenario")
            raise SolutionError(
                f"{source} was solved for '{made_for}', whose game differs from '{scenario.name}' "
                "(arena, dt, capture distance, speed or acceleration limits): solve it for this scenario"
            )
