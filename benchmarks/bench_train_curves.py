"""Learning curves of ``pecli train``: capture rate against greedy over CPU time, and their report.

    python benchmarks/bench_train_curves.py curves --minutes 10    # capture rate vs greedy over CPU time, 3 seeds
    python benchmarks/bench_train_curves.py report                 # table + plot from finished curve runs

``curves`` runs ``pecli train pursuer --cpu-minutes M`` for each seed with a budget of ``--max-steps``
transitions (the curriculum of paper.yaml spans its first 30 %) and an evaluation against the
greedy evader (200 batched episodes) every ``--eval-every`` transitions, until each run has used
``--minutes`` of CPU time or its transitions; ``--jobs 2`` runs two seeds at a time on a 2-core machine.
``--resume`` continues the runs until they have used ``--minutes`` in all. Each run
writes ``eval_pursuer.csv`` (steps, CPU seconds, capture rate) in its zoo folder. ``report``
takes each seed's best evaluation within each budget of ``--at`` (default 10 and 30 CPU-minutes),
prints their medians, and draws ``docs/learning_curves_<belief>.png`` (``learning_curves_<config>_<belief>.png``
for another config than paper). ``--belief`` picks the
actor's belief (runs are named ``<config>-<belief>-s<seed>``).
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")  # the runs inherit it

import numpy as np  # noqa: E402

from pecli.rl.evaluations import read_evaluations  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
CURVES = ROOT / "runs" / "bench_train"


def curves(args: argparse.Namespace) -> None:
    """Start the curve runs, ``--jobs`` at a time, each with ``pecli train --cpu-minutes``."""
    pending = list(args.seeds)
    running: list[tuple[int, subprocess.Popen]] = []
    CURVES.mkdir(parents=True, exist_ok=True)
    while pending or running:
        while pending and len(running) < args.jobs:
            seed = pending.pop(0)
            name = f"{args.label or args.config}-{args.belief}-s{seed}"
            command = [sys.executable, "-m", "pecli", "train", "pursuer", "--zoo", str(CURVES), "--name", name, "-q"]
            command += ["--cpu-minutes", str(args.minutes)]
            if args.resume:  # the run's own settings; its CPU time continues from its checkpoint
                command += ["--resume"]
            else:
                command += [
                    "-c",
                    args.config,
                    "--seed",
                    str(seed),
                    "--steps",
                    str(args.max_steps),
                    "--belief",
                    args.belief,
                    "--set",
                    f"eval_every={args.eval_every}",
                    *sum((["--set", s] for s in args.set), []),
                ]
            print("started:", " ".join(command[1:]), flush=True)
            running.append((seed, subprocess.Popen(command, cwd=ROOT)))
        time.sleep(5)
        for seed, process in list(running):
            if process.poll() is not None:
                print(f"seed {seed}: done (exit code {process.returncode})", flush=True)
                running.remove((seed, process))


def _read(csv_path: Path) -> tuple[np.ndarray, np.ndarray]:
    """CPU minutes and capture rate of each evaluation in a run's ``eval_pursuer.csv``."""
    rows = read_evaluations(csv_path)
    return np.array([r.cpu_seconds / 60.0 for r in rows]), np.array([r.capture_rate for r in rows])


def _trained_all_steps(run: Path) -> bool:
    """Whether the run reached its ``--max-steps`` (rather than its CPU budget): it spent less CPU than asked."""
    from pecli.zoo import FINAL, Run, read_metadata

    final = run / "pursuer" / f"{FINAL}.zip"
    return final.is_file() and read_metadata(final).steps >= Run(run).scenario().training.steps


def report(args: argparse.Namespace) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    main = args.label or args.config
    groups = {name: sorted(CURVES.glob(f"{name}-{args.belief}-s*/eval_pursuer.csv")) for name in (main, *args.compare)}
    for name, runs in groups.items():
        if not runs:
            sys.exit(f"no curve runs {name}-{args.belief}-s* in {CURVES}: run the 'curves' step first")
    fig, ax = plt.subplots(figsize=(6, 4))
    for colour, (name, runs) in zip(plt.rcParams["axes.prop_cycle"].by_key()["color"], groups.items()):
        at: dict[float, list[float]] = {float(m): [] for m in args.at}
        for i, path in enumerate(runs):
            cpu, rate = _read(path)
            ax.plot(cpu, rate, marker=".", color=colour, alpha=max(0.3, 1.0 - 0.25 * i), label=path.parent.name)
            finished = _trained_all_steps(path.parent)  # done with its transitions before its CPU budget
            for minutes in at:
                if cpu.size and (cpu <= minutes).any() and (cpu[-1] >= minutes or finished):
                    at[minutes].append(float(np.max(rate[cpu <= minutes])))  # best evaluation so far
        for minutes, values in at.items():
            shown = ", ".join(f"{v:.2f}" for v in values) or "no run got that far"
            median = f"{statistics.median(values):.2f}" if values else "-"
            print(f"{name}: best capture rate within {minutes:g} CPU-min: median {median} ({shown})")
    ax.axhline(0.95, color="0.6", ls="--", lw=0.8)
    ax.set_xlabel("CPU minutes (one torch thread)")
    ax.set_ylabel("capture rate vs greedy (200 episodes)")
    ax.set_ylim(0, 1)
    ax.set_title(f"pecli train pursuer, {' vs '.join(groups)}, belief {args.belief}")
    ax.legend(fontsize=7)
    fig.tight_layout()
    out = args.out or ROOT / "docs" / (
        f"learning_curves_{args.belief}.png"
        if args.config == "paper" and not args.label
        else f"learning_curves_{'_vs_'.join(groups)}_{args.belief}.png"
    )
    fig.savefig(out, dpi=110)
    print(f"wrote {out}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="step", required=True)
    c = sub.add_parser("curves")
    c.add_argument("--config", default="paper")
    c.add_argument("--belief", default="none")
    c.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    c.add_argument("--minutes", type=float, default=10.0, help="CPU minutes per seed")
    c.add_argument("--jobs", type=int, default=2)
    c.add_argument("--eval-every", type=int, default=25000)
    c.add_argument(
        "--max-steps",
        type=int,
        default=600_000,
        help="the training budget; the curriculum spans its first 30 %% (paper.yaml)",
    )
    c.add_argument("--set", action="append", default=[], help="extra training settings, KEY=VALUE")
    c.add_argument("--label", help="names the runs instead of --config (for a variant made with --set)")
    c.add_argument(
        "--resume",
        action="store_true",
        help="continue the runs (pecli train --resume) until --minutes of their CPU time in all",
    )
    r = sub.add_parser("report")
    r.add_argument("--config", default="paper")
    r.add_argument("--belief", default="none")
    r.add_argument("--at", type=float, nargs="+", default=[10.0, 30.0], help="CPU budgets to report (minutes)")
    r.add_argument("--out", type=Path, default=None, help="the plot (default: docs/learning_curves_...png)")
    r.add_argument("--label", help="the --label the curves were run with")
    r.add_argument(
        "--compare",
        nargs="+",
        default=[],
        metavar="LABEL",
        help="other curves to draw on the same plot, each in its colour (their --label or --config)",
    )
    args = parser.parse_args()
    {"curves": curves, "report": report}[args.step](args)


if __name__ == "__main__":
    main()
