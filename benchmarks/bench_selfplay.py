"""Self-play progress: a self-play run within a fixed budget, then every generation against every other.

    python benchmarks/bench_selfplay.py --rounds 6 --steps-per-round 50000      # train, then the round robin
    python benchmarks/bench_selfplay.py --skip-train --name paper-s0           # only the round robin

The run is ``pecli selfplay`` itself (resumed when it exists, so an interrupted benchmark continues).
The round robin (:mod:`pecli.rl.generations`, as ``pecli zoo generations RUN``) plays every pursuer generation
(plus pure pursuit) against every evader generation (plus the greedy evader) with the same seeds (cached in
``<run>/generations``), and prints the capture-rate matrix, draws it as a heatmap, and checks the claim that
later generations are stronger:

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
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")

from pecli.rl.generations import draw_heatmap, round_robin  # noqa: E402
from pecli.zoo import Run  # noqa: E402


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
    result = round_robin(run, scenario, args.episodes, [0], args.workers)
    rates, labels = result.rates, result.labels
    print(f"round robin: {rates.size} pairings x {args.episodes} episodes in {time.perf_counter() - start:.0f} s\n")
    width = max(len(x) for x in labels["pursuer"]) + 2
    print(" " * width + "".join(f"{x:>9}" for x in labels["evader"]))
    for label, row in zip(labels["pursuer"], rates):
        print(f"{label:<{width}}" + "".join(f"{v:9.2f}" for v in row))
    pursuer, evader = result.progress()
    print(
        f"\nlater pursuers beat older evaders more often than earlier pursuers did: {pursuer:.2f} of pairs (> 0.5: yes)"
    )
    print(
        f"later evaders escape older pursuers more often than earlier evaders did: {evader:.2f} of pairs (> 0.5: yes)"
    )
    steps = scenario.training.selfplay.steps_per_round
    draw_heatmap(
        result,
        args.out,
        f"{run.name}: capture rate, generation vs generation\n"
        f"{steps:,} steps per side per round, {args.episodes} episodes per cell",
    )
    print(f"heatmap: {args.out}")


if __name__ == "__main__":
    main()
