"""Self-play of two configs to a CPU cap, then their final players against each other.

    python benchmarks/bench_train_selfplay.py selfplay --configs tuned paper --minutes 10

``selfplay`` runs ``pecli selfplay --cpu-hours`` for each config of ``--configs`` (default: tuned and paper) and
each seed until its finished turns have used ``--minutes`` of CPU time (or it finished its rounds; a stopped run
is resumed to the same budget), then plays each pair of configs' final checkpoints against each other,
``--episodes`` games: the first config's pursuer against the second's evader and vice versa.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")  # the runs inherit it

from pecli.records import Turn  # noqa: E402
from pecli.rl.fork import run_cpu_hours  # noqa: E402
from pecli.rl.handover import STATE_FILE  # noqa: E402
from pecli.rl.state import read_state_file  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
SELFPLAY = Path(os.environ.get("PECLI_BENCH_SELFPLAY", ROOT / "runs" / "bench_train_selfplay"))


def _turns(run: Path) -> list[Turn]:
    """The run's finished turns, as its validated ``selfplay.json`` records them (none before its first)."""
    state = run / STATE_FILE
    return read_state_file(state).turns if state.is_file() else []


def selfplay(args: argparse.Namespace) -> None:
    """Self-play per config and seed to a CPU budget, then the configs' final players against each other."""
    SELFPLAY.mkdir(parents=True, exist_ok=True)
    for seed in args.seeds:
        for config in args.configs:
            run = SELFPLAY / f"{Path(config).stem}-s{seed}"
            command = [sys.executable, "-m", "pecli", "selfplay", "--zoo", str(SELFPLAY), "--name", run.name, "-q"]
            command += ["--cpu-hours", f"{args.minutes / 60}"]
            command += ["--resume"] if (run / STATE_FILE).exists() else ["-c", config, "--seed", str(seed)]
            if run_cpu_hours(run) * 60 < args.minutes:
                print("started:", " ".join(command[1:]), flush=True)
                subprocess.run(command, cwd=ROOT, check=True)
            used = run_cpu_hours(run) * 60
            print(f"{run.name}: {len(_turns(run)) // 2} rounds in {used:.1f} CPU-minutes (turns)", flush=True)
    print(
        f"| seed | {args.configs[0]} pursuer vs {args.configs[1]} evader | {args.configs[1]} pursuer vs "
        f"{args.configs[0]} evader | rounds |"
    )
    print("| ---: | ---: | ---: | --- |")
    for seed in args.seeds:
        final = {}
        for config in args.configs[:2]:
            run = SELFPLAY / f"{Path(config).stem}-s{seed}"
            final[config] = {t.role: run / t.checkpoint for t in _turns(run)}
        if any(set(f) != {"pursuer", "evader"} for f in final.values()):
            print(f"| {seed} | - | - | a run has no finished round yet |")
            continue
        a, b = args.configs[:2]
        rates = [
            _capture_rate(final[x]["pursuer"], final[y]["evader"], args.episodes, seed) for x, y in ((a, b), (b, a))
        ]
        rounds = " / ".join(str(len(_turns(SELFPLAY / f"{Path(c).stem}-s{seed}")) // 2) for c in (a, b))
        print(f"| {seed} | {rates[0]:.3f} | {rates[1]:.3f} | {rounds} |", flush=True)


def _capture_rate(pursuer: Path, evader: Path, episodes: int, seed: int) -> float:
    command = [
        sys.executable,
        "-m",
        "pecli",
        "play",
        "--pursuer",
        str(pursuer),
        "--evader",
        str(evader),
        "--episodes",
        str(episodes),
        "--seed",
        str(10_000 + seed),
        "--json",
    ]
    output = subprocess.run(command, cwd=ROOT, check=True, capture_output=True, text=True).stdout
    return float(json.loads(output)["capture_rate"])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="step", required=True)
    p = sub.add_parser("selfplay")
    p.add_argument("--configs", nargs=2, default=["tuned", "paper"])
    p.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    p.add_argument("--minutes", type=float, default=10.0, help="CPU minutes per self-play run")
    p.add_argument("--episodes", type=int, default=500)
    selfplay(parser.parse_args())


if __name__ == "__main__":
    main()
