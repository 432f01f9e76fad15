"""Self-play progress: a self-play run within a fixed budget, then every generation against every other.

    python benchmarks/bench_selfplay.py --rounds 6 --steps-per-round 50000      # train, then the round robin
    python benchmarks/bench_selfplay.py --skip-train --name paper-s0           # only the round robin

The run is ``pecli selfplay`` itself (resumed when it exists, so an interrupted benchmark continues).
The round robin plays every pursuer generation (plus pure pursuit) against every evader generation
(plus the greedy evader) with the same seeds (a ``pecli tournament`` over the run's checkpoints,
cached in ``<run>/generations``), and prints the capture-rate matrix, draws it as a heatmap, and
checks the claim that later generations are stronger:

* pursuers: against the evader of generation j, of two pursuers trained after it (generations
  j < i < i'), the later one captures more often. Reported as the share of such ordered pairs
  where the later pursuer does better, ties counted half, over all j: above 0.5 means later
  pursuers beat older evaders more often than earlier pursuers did;
* evaders: the same with escapes, against pursuers of generation i and evaders trained after it
  (i <= j < j'; in a round the pursuer trains first).
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import time
from itertools import combinations
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from pecli.tournament import find_players, run_tournament  # noqa: E402
from pecli.zoo import Run  # noqa: E402

REFERENCE = {"pursuer": "pure-pursuit", "evader": "greedy"}


def train(args: argparse.Namespace, run: Path) -> float:
    """Run (or resume) the self-play; returns the CPU seconds the command used."""
    command = [
        sys.executable,
        "-m",
        "pecli",
        "selfplay",
        "--config",
        args.config,
        "--rounds",
        str(args.rounds),
        "--steps-per-round",
        str(args.steps_per_round),
        "--opponents",
        args.opponents,
        "--seed",
        str(args.seed),
        "--zoo",
        str(run.parent),
        "--name",
        run.name,
        "--quiet",
    ]
    if args.belief:
        command += ["--belief", args.belief]
    if (run / "selfplay.json").exists():  # resume: the run keeps its own settings
        command = [
            sys.executable,
            "-m",
            "pecli",
            "selfplay",
            "--rounds",
            str(args.rounds),
            "--zoo",
            str(run.parent),
            "--name",
            run.name,
            "--resume",
            "--quiet",
        ]
    print("$", " ".join(command[2:]), flush=True)
    before = os.times()
    subprocess.run(command, check=True)
    after = os.times()
    return (after.children_user - before.children_user) + (after.children_system - before.children_system)


def generation(name: str) -> int:
    """``round-003`` → 3; the reference baselines are generation 0."""
    return int(name.rsplit("-", 1)[1]) if name.startswith("round-") else 0


def round_robin(run: Path, scenario, episodes: int, workers: int):
    """Capture rates ``(pursuers, evaders)`` with row/column labels, generation 0 the reference baselines."""
    found = find_players([str(run)], scenario)
    players = {role: [p for p in found.players[role]] for role in found.players}
    extra = find_players([], scenario, baselines=True).players
    for role in players:
        players[role] = [p for p in extra[role] if p.spec == REFERENCE[role]] + sorted(
            players[role], key=lambda p: generation(Path(p.spec).stem)
        )
    pairings = [(p, e) for p in players["pursuer"] for e in players["evader"]]
    results = run_tournament(scenario, players, pairings, episodes, [0], run / "generations", workers=workers)
    grid = results.grid()
    labels = {role: [_label(p) for p in players[role]] for role in players}
    rates = np.array([[grid[(p.name, e.name)].capture_rate for e in players["evader"]] for p in players["pursuer"]])
    return rates, labels


def _label(player) -> str:
    stem = Path(player.spec).stem
    return f"g{generation(stem)}" if stem.startswith("round-") else player.spec


def progress_share(values: np.ndarray, later_than: int) -> float:
    """Share of ordered pairs (i < i', both > ``later_than``) with values[i'] > values[i], ties half."""
    gens = [g for g in range(len(values)) if g > later_than]
    pairs = list(combinations(gens, 2))
    if not pairs:
        return float("nan")
    return float(np.mean([1.0 if values[b] > values[a] else 0.5 if values[b] == values[a] else 0.0 for a, b in pairs]))


def claims(rates: np.ndarray) -> tuple[float, float]:
    """(pursuer progress, evader progress) over the learned generations (index = generation, 0 = reference)."""
    learned = rates[1:, 1:]  # generation g at index g - 1
    n = learned.shape[0]
    pursuer = [progress_share(np.r_[np.nan, learned[:, j]], later_than=j + 1) for j in range(n)]
    evader = [progress_share(np.r_[np.nan, 1 - learned[i, :]], later_than=i) for i in range(n)]  # same round too
    return float(np.nanmean(pursuer)), float(np.nanmean(evader))


def heatmap(rates: np.ndarray, labels: dict[str, list[str]], out: Path, title: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(1.0 + 0.6 * rates.shape[1], 1.0 + 0.5 * rates.shape[0]))
    image = ax.imshow(rates, vmin=0, vmax=1, cmap="viridis")
    ax.set_xticks(range(rates.shape[1]), labels["evader"], rotation=45, ha="right")
    ax.set_yticks(range(rates.shape[0]), labels["pursuer"])
    ax.set_xlabel("evader generation")
    ax.set_ylabel("pursuer generation")
    for (i, j), value in np.ndenumerate(rates):
        ax.text(j, i, f"{value:.2f}", ha="center", va="center", color="white" if value < 0.6 else "black", fontsize=7)
    fig.colorbar(image, ax=ax, label="capture rate")
    ax.set_title(title, fontsize=9)
    fig.tight_layout()
    fig.savefig(out, dpi=120)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--config", default="paper")
    parser.add_argument("--rounds", type=int, default=6)
    parser.add_argument("--steps-per-round", type=int, default=50_000)
    parser.add_argument("--opponents", default="pfsp", choices=["latest", "uniform", "pfsp"])
    parser.add_argument("--belief", default=None)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--zoo", type=Path, default=Path("runs/bench_selfplay"))
    parser.add_argument("--name", default=None, help="run name (default: <config>-<opponents>-s<seed>)")
    parser.add_argument("--episodes", type=int, default=500, help="episodes per pairing of the round robin")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--skip-train", action="store_true")
    parser.add_argument("--out", type=Path, default=Path("docs/selfplay_generations.png"))
    args = parser.parse_args()

    run = args.zoo / (args.name or f"{args.config}-{args.opponents}-s{args.seed}")
    if not args.skip_train:
        cpu = train(args, run)
        print(f"self-play: {cpu / 60:.1f} CPU-minutes", flush=True)
    scenario = Run(run).scenario()
    start = time.perf_counter()
    rates, labels = round_robin(run, scenario, args.episodes, args.workers)
    print(f"round robin: {rates.size} pairings x {args.episodes} episodes in {time.perf_counter() - start:.0f} s\n")
    width = max(len(x) for x in labels["pursuer"]) + 2
    print(" " * width + "".join(f"{x:>9}" for x in labels["evader"]))
    for label, row in zip(labels["pursuer"], rates):
        print(f"{label:<{width}}" + "".join(f"{v:9.2f}" for v in row))
    pursuer, evader = claims(rates)
    print(
        f"\nlater pursuers beat older evaders more often than earlier pursuers did: {pursuer:.2f} of pairs (> 0.5: yes)"
    )
    print(
        f"later evaders escape older pursuers more often than earlier evaders did: {evader:.2f} of pairs (> 0.5: yes)"
    )
    steps = scenario.training.selfplay.steps_per_round
    heatmap(
        rates,
        labels,
        args.out,
        f"{run.name}: capture rate, generation vs generation\n"
        f"{steps:,} steps per side per round, {args.episodes} episodes per cell",
    )
    print(f"heatmap: {args.out}")


if __name__ == "__main__":
    main()
