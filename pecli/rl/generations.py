"""A self-play run's generations against each other: does it make progress, or go round in circles?

Every round of self-play leaves one checkpoint per main learner (``<role>/round-NNN.zip``, generation NNN). The
round robin plays every pursuer generation against every evader generation, with the reference baselines as
generation 0 (pure pursuit, the greedy evader), all pairings from the same start states (a tournament cached in
``<run>/generations``). Two numbers summarise the matrix:

* **pursuer progress**: against the evader of generation j, of two pursuers trained after it (j < i < i'), how
  often the later one captures more, ties counted half, over every ordered pair and every j;
* **evader progress**: the same with escapes, against the pursuer of generation i and evaders trained after it
  (i <= j < j': in a round the pursuer trains first).

Above 0.5, later generations beat older opponents more often than earlier generations did: the run improves on
what it has met. Near 0.5 with a matrix of bands is cycling: each generation beats the last and loses to older
ones (non-transitive play, what league and PSRO opponent selection are meant to break).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from itertools import combinations, count
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from pecli.errors import PecliError
from pecli.roles import ROLES, Role
from pecli.scenario import Scenario

if TYPE_CHECKING:
    from pecli.tournament import PairingResult

REFERENCE: dict[Role, str] = {"pursuer": "pure-pursuit", "evader": "greedy"}  # generation 0
GENERATIONS_DIR = "generations"


@dataclass
class Generations:
    """Capture rates of pursuer generations (rows) against evader generations (columns), index 0 the reference."""

    labels: dict[Role, list[str]]  # "pure-pursuit", "g1", "g2", ... and "greedy", "g1", ...
    rates: np.ndarray  # (pursuers, evaders) capture rates
    episodes: int

    def progress(self) -> tuple[float, float]:
        """(pursuer progress, evader progress) over the learned generations; ``nan`` with too few of them."""
        learned = self.rates[1:, 1:]  # generation g at index g - 1
        rows, columns = learned.shape
        pursuer = [progress_share(np.r_[np.nan, learned[:, j]], later_than=j + 1) for j in range(columns)]
        evader = [progress_share(np.r_[np.nan, 1 - learned[i, :]], later_than=i) for i in range(rows)]
        return _mean(pursuer), _mean(evader)


def _mean(values: list[float]) -> float:
    kept = [v for v in values if not np.isnan(v)]
    return float(np.mean(kept)) if kept else float("nan")


def progress_share(values: np.ndarray, later_than: int) -> float:
    """The share of ordered pairs of generations ``a < b``, both after ``later_than``, with ``values[b] >
    values[a]`` (ties half); ``nan`` without such a pair. ``values`` is indexed by generation."""
    pairs = list(combinations([g for g in range(len(values)) if g > later_than], 2))
    if not pairs:
        return float("nan")
    return float(np.mean([1.0 if values[b] > values[a] else 0.5 if values[b] == values[a] else 0.0 for a, b in pairs]))


def generation_checkpoints(run: Path, every: int = 1) -> dict[Role, list[Path]]:
    """Each main learner's round checkpoints, oldest first: every ``every``-th round (counted from the last, which
    is always kept); :class:`PecliError` if the run has none."""
    if every < 1:
        raise PecliError(f"--every must be at least 1, not {every}")
    found = {role: sorted((run / role).glob("round-*.zip"), key=lambda p: _generation(p.stem)) for role in ROLES}
    for role, paths in found.items():
        if not paths:
            raise PecliError(f"{run} has no {role} round checkpoints ({role}/round-NNN.zip): is it a self-play run?")
        found[role] = paths[::-1][::every][::-1]
    return found


def _generation(stem: str) -> int:
    """``round-003`` → 3."""
    try:
        return int(stem.rsplit("-", 1)[1])
    except (IndexError, ValueError):
        return 0


def round_robin(
    run: Path,
    scenario: Scenario,
    episodes: int,
    seeds: list[int] | None = None,
    workers: int = 1,
    on_result: Callable[[str], None] | None = None,
    every: int = 1,
) -> Generations:
    """Every pursuer generation of ``run`` (and the reference) against every evader generation (every ``every``-th
    round of a long run), ``episodes`` games per seed and pairing, cached in ``run/generations``; ``on_result``
    hears a line per pairing (``k/N pursuer vs evader: rate``)."""
    from pecli.tournament import find_players, run_tournament

    checkpoints = generation_checkpoints(run, every)
    paths = [str(path) for role in ROLES for path in checkpoints[role]]
    found = find_players([*paths, *REFERENCE.values()], scenario).players
    by_spec = {role: {Path(p.spec).resolve(): p for p in found[role] if p.spec.endswith(".zip")} for role in ROLES}
    # a round whose file repeats an earlier one's bytes is that player already: it plays once, as the first
    checkpoints = {role: [path for path in checkpoints[role] if path.resolve() in by_spec[role]] for role in ROLES}
    players = {
        role: [next(p for p in found[role] if p.spec == REFERENCE[role])]
        + [by_spec[role][path.resolve()] for path in checkpoints[role]]
        for role in ROLES
    }
    pairings = [(p, e) for p in players["pursuer"] for e in players["evader"]]
    done = count(1)

    def report(result: PairingResult, cached: bool) -> None:
        k = next(done)
        if on_result is not None:
            on_result(f"{k}/{len(pairings)} {result.pursuer} vs {result.evader}: {result.capture_rate:.2f}")

    results = run_tournament(
        scenario, players, pairings, episodes, seeds or [0], run / GENERATIONS_DIR, workers=workers, on_result=report
    )
    grid = results.grid()
    rates = np.array([[grid[(p.name, e.name)].capture_rate for e in players["evader"]] for p in players["pursuer"]])
    labels = {role: [REFERENCE[role]] + [f"g{_generation(path.stem)}" for path in checkpoints[role]] for role in ROLES}
    return Generations(labels=labels, rates=rates, episodes=episodes)


def draw_heatmap(generations: Generations, path: Path, title: str) -> Path:
    """The capture-rate matrix as a heatmap PNG at ``path`` (written atomically)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from pecli.io import atomic_path

    rates = generations.rates
    fig, ax = plt.subplots(figsize=(1.0 + 0.6 * rates.shape[1], 1.0 + 0.5 * rates.shape[0]))
    image = ax.imshow(rates, vmin=0, vmax=1, cmap="viridis")
    ax.set_xticks(range(rates.shape[1]), generations.labels["evader"], rotation=45, ha="right")
    ax.set_yticks(range(rates.shape[0]), generations.labels["pursuer"])
    ax.set_xlabel("evader generation")
    ax.set_ylabel("pursuer generation")
    for (i, j), value in np.ndenumerate(rates):
        ax.text(j, i, f"{value:.2f}", ha="center", va="center", color="white" if value < 0.6 else "black", fontsize=7)
    fig.colorbar(image, ax=ax, label="capture rate")
    ax.set_title(title, fontsize=9)
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=120, format="png")
    plt.close(fig)
    return path
