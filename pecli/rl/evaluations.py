"""A run's evaluation log, ``RUN/eval_<role>.csv``: one row per evaluation of the learner against its evaluation
opponent (``steps, cpu_seconds, wall_seconds, capture_rate``), appended by :class:`pecli.rl.callbacks.Evaluation`
and read for learning curves (``pecli exploit``'s plot, the training benchmarks).

A log is read row by row; a row that is not four finite numbers (a kill can leave half of one, a stranger's file
anything) is passed over, and a log past :data:`MAX_LOG_BYTES` is not read at all.
"""

from __future__ import annotations

import csv
import math
from dataclasses import dataclass
from pathlib import Path

from pecli.io import atomic_write_text
from pecli.roles import Role

COLUMNS = ("steps", "cpu_seconds", "wall_seconds", "capture_rate")
MAX_LOG_BYTES = 1 << 26  # a row is about 30 bytes: two million evaluations


@dataclass(frozen=True)
class Evaluated:
    """One evaluation: after ``steps`` learner transitions and ``cpu_seconds`` of the run's CPU time."""

    steps: int
    cpu_seconds: float
    wall_seconds: float
    capture_rate: float


def evaluation_log(run: Path, role: Role) -> Path:
    """Where the run folder ``run`` logs its ``role`` learner's evaluations."""
    return run / f"eval_{role}.csv"


def start_log(path: Path) -> None:
    """A new, empty log at ``path`` (its header row)."""
    with path.open("w", newline="") as handle:
        csv.writer(handle).writerow(COLUMNS)


def append_evaluation(path: Path, steps: int, cpu_seconds: float, wall_seconds: float, rate: float) -> None:
    """One row at the end of the log at ``path``."""
    with path.open("a", newline="") as handle:
        csv.writer(handle).writerow([steps, f"{cpu_seconds:.2f}", f"{wall_seconds:.2f}", f"{rate:.4f}"])


def read_evaluations(path: Path) -> list[Evaluated]:
    """The whole rows of the log at ``path``, in order; none if there is no log or it is too large to be one."""
    if path.is_symlink() or not path.is_file() or path.stat().st_size > MAX_LOG_BYTES:
        return []
    rows: list[Evaluated] = []
    try:
        handle = path.open(newline="", errors="replace")
    except OSError:  # not ours to read
        return rows
    with handle:
        try:
            for row in csv.DictReader(handle):
                try:
                    steps = int(row["steps"])
                    numbers = [float(row[column]) for column in COLUMNS[1:]]
                except (KeyError, TypeError, ValueError):
                    continue
                if steps >= 0 and all(math.isfinite(x) and x >= 0 for x in numbers) and numbers[2] <= 1:
                    rows.append(Evaluated(steps, *numbers))
        except csv.Error:  # a field past the csv module's limit, or a NUL: no log pecli writes
            return rows
    return rows


def forget_evaluations_after(path: Path, steps: int) -> None:
    """Drop the rows of the log at ``path`` past ``steps``: a run stopped after them resumes from before."""
    if not path.is_file():
        return
    lines = path.read_text().splitlines(keepends=True)

    def before(line: str) -> bool:  # a whole row (a kill can leave half of one) written at most at ``steps``
        first = line.split(",", 1)[0]
        return line.endswith("\n") and first.isdigit() and int(first) <= steps

    kept = lines[:1] + [line for line in lines[1:] if before(line)]
    if len(kept) < len(lines):
        atomic_write_text(path, "".join(kept))
