"""The Hamilton–Jacobi baseline: solver cost and accuracy, Table II.

    python benchmarks/bench_hj.py solve            # solve time, CPU, peak memory, accuracy of every model
    python benchmarks/bench_hj.py table2 --pursuer P.zip --evader E.zip    # Table II by the documented commands
    python benchmarks/bench_hj.py solve --quick    # small grids and horizons, a smoke run

``solve``: every solve runs in a fresh process on one thread (OMP_NUM_THREADS=1, XLA on one
thread). Peak memory is the largest total of live NumPy/SciPy allocations during the solve
(``tracemalloc``); for hj-reachability, whose XLA buffers the tracer does not see, the growth of
the process's maximum resident set during the solve. Times are the median of ``--repeats``
solves for rel4d (one solve for the larger models); "CPU" is the process's CPU time. Accuracy is
measured on 20 000 random states (relative positions in the arena's middle, |r_i| ≤ 7 m; relative
velocities within the limits) against the closed form of the equal-acceleration game: the discrete-time one for the
NumPy solver, which plays the game's dt, and the continuous-time one for hj-reachability, which
solves the PDE. rel6d and abs8d have no closed form (they clip each player's speed; abs8d has
walls), so they get no accuracy columns.

``table2`` runs the command sequence of docs/hj.md
(``pecli hj solve``, ``pecli tournament``, ``pecli hj table``) and prints the table beside the paper's.

The HJ players against every other player: ``bench_hj_matrix.py``; what made the first HJ players weak, and
how the hj evader rates its inputs: ``bench_hj_ablations.py``.
"""

from __future__ import annotations

import argparse
import itertools
import json
import os
import platform
import resource
import statistics
import subprocess
import sys
import time
import tracemalloc
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("XLA_FLAGS", "--xla_cpu_multi_thread_eigen=false intra_op_parallelism_threads=1")

import numpy as np  # noqa: E402

from pecli.hj import Problem  # noqa: E402
from pecli.hj.oracle import solution_accuracy  # noqa: E402
from pecli.hj.reachability import available, solve_with_hj_reachability  # noqa: E402
from pecli.hj.solver import solve  # noqa: E402
from pecli.records import TournamentRecord  # noqa: E402
from pecli.reports import PAPER_TABLE_II  # noqa: E402
from pecli.scenario import load_scenario  # noqa: E402
from pecli.tournament import read_results  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
EPISODES = 500


# ---------------------------------------------------------------------- solve
def one(config: str, model: str, sizes: tuple[int, int], steps: int | None, backend: str) -> dict:
    """Solve once in this process; seconds, CPU seconds, peak memory growth and accuracy."""
    scenario = load_scenario(config)
    problem = Problem.for_scenario(scenario, model, sizes, steps=steps, backend=backend)  # type: ignore[arg-type]
    problem.grid  # noqa: B018
    before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    if backend == "numpy":
        tracemalloc.start()
    start, cpu = time.perf_counter(), time.process_time()
    values = solve_with_hj_reachability(problem) if backend == "hj-reachability" else solve(problem)
    seconds, cpu_seconds = time.perf_counter() - start, time.process_time() - cpu
    if backend == "numpy":
        peak = tracemalloc.get_traced_memory()[1] / 2**20
        tracemalloc.stop()
    else:
        peak = (resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - before) / 1024  # KiB -> MiB
    result = {
        "backend": backend,
        "model": model,
        "grid": problem.grid.describe(),
        "nodes": problem.grid.size,
        "steps": problem.steps,
        "seconds": seconds,
        "cpu": cpu_seconds,
        "peak_mb": peak,
        "capture_share": float(np.mean(values <= 0)),
    }
    if model == "rel4d":
        result |= solution_accuracy(problem, values)
    return result


def measure(config: str, model: str, sizes: tuple[int, int], steps: int | None, backend: str, repeats: int) -> dict:
    """Median over ``repeats`` fresh processes."""
    runs = []
    for _ in range(repeats):
        command = [sys.executable, __file__, "--one", config, model, f"{sizes[0]},{sizes[1]}", str(steps or 0), backend]
        done = subprocess.run(command, capture_output=True, text=True, check=True)
        runs.append(json.loads(done.stdout.strip().splitlines()[-1]))
    best = dict(runs[0])
    for key in ("seconds", "cpu", "peak_mb"):
        best[key] = statistics.median(run[key] for run in runs)
    best["runs"] = repeats
    return best


def solve_table(args: argparse.Namespace) -> None:
    steps = 20 if args.quick else None
    cases = [  # (backend, model, sizes, repeats)
        ("numpy", "rel4d", (41, 21) if not args.quick else (21, 11), args.repeats),
        ("numpy", "rel4d", (81, 21) if not args.quick else (41, 11), args.repeats),
        ("numpy", "rel6d", (21, 11) if not args.quick else (11, 5), 1),
        ("numpy", "rel6d", (41, 11) if not args.quick else (21, 5), 1),
        ("numpy", "abs8d", (11, 5) if not args.quick else (7, 3), 1),
        ("numpy", "abs8d", (15, 5) if not args.quick else (9, 3), 1),
        ("numpy", "rel4d", (21, 11), args.repeats),  # the grid hj-reachability solves below
    ]
    if available():
        cases.append(("hj-reachability", "rel4d", (21, 11), 1))
    else:
        print('hj-reachability is not installed (pip install -e ".[hj]"): its row is skipped', file=sys.stderr)
    results = []
    for backend, model, sizes, repeats in cases:
        results.append(measure(args.config, model, sizes, steps, backend, repeats))
        print(f"done: {backend} {model} {results[-1]['grid']}: {results[-1]['seconds']:.1f} s", file=sys.stderr)
    if args.json:
        print(json.dumps(results, indent=2))
        return
    print(f"scenario {args.config}, {platform.machine()}, numpy {np.__version__}, one thread per solve")
    print(
        "| backend | model | grid | nodes | steps | solve s | CPU s | peak MB | capture share | runs "
        "| sign vs discrete | error vs discrete (m) | sign vs continuous | error vs continuous (m) |"
    )
    print("| --- | --- | --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |")
    for r in results:
        exact = (
            [
                f"{r[k]:.4f}" if k.startswith("sign") else f"{r[k]:.3f}"
                for k in ("sign_discrete", "error_discrete", "sign_continuous", "error_continuous")
            ]
            if "sign_discrete" in r
            else ["-"] * 4
        )
        print(
            f"| {r['backend']} | {r['model']} | {r['grid']} | {r['nodes']:,} | {r['steps']} | {r['seconds']:.2f} "
            f"| {r['cpu']:.2f} | {r['peak_mb']:.0f} | {r['capture_share']:.3f} | {r['runs']} | "
            + " | ".join(exact)
            + " |"
        )
    if results[-1]["backend"] == "hj-reachability":
        numpy_run, jax_run = results[-2:]
        print(
            f"\non {numpy_run['grid']}: numpy {jax_run['seconds'] / numpy_run['seconds']:.0f}x faster than "
            f"hj-reachability (CPU {jax_run['cpu'] / numpy_run['cpu']:.0f}x); mean error "
            f"{numpy_run['error_discrete']:.3f} m (vs the discrete closed form) against "
            f"{jax_run['error_continuous']:.3f} m (hj-reachability vs the continuous one)"
        )


# ---------------------------------------------------------------------- Table II
def table2(args: argparse.Namespace) -> None:
    """The documented command sequence (docs/hj.md), then the table beside the paper's."""
    pecli = str(Path(sys.executable).with_name("pecli"))
    out = Path(args.out)
    commands = [
        [pecli, "hj", "solve", "-c", "point_mass"],
        [
            pecli,
            "tournament",
            "-c",
            "point_mass",
            "--episodes",
            str(args.episodes),
            "--seeds",
            str(args.seeds),
            "--workers",
            "1",
            "--resume",
            "--out",
            str(out),
            args.pursuer,
            args.evader,
            f"hj:belief={args.pursuer}",
            f"hj:belief={args.evader}",
            "hj",
        ],
        [pecli, "hj", "table", str(out)],
    ]
    for command in commands:
        print(
            "$ " + " ".join(Path(command[0]).name if i == 0 else part for i, part in enumerate(command)),
            file=sys.stderr,
        )
        subprocess.run(command, check=True, stdout=None if command[1:3] == ["hj", "table"] else subprocess.DEVNULL)
    record = read_results(out)
    cells = {(p.pursuer, p.evader): p for p in record.pairings}
    names = {
        "optimal control": {
            "pursuer": _player_name(record, f"hj:belief={args.pursuer}", "pursuer"),
            "evader": _player_name(record, f"hj:belief={args.evader}", "evader"),
        },
        "ours": {
            "pursuer": _player_name(record, args.pursuer, "pursuer"),
            "evader": _player_name(record, args.evader, "evader"),
        },
    }
    print("\n| pursuer vs evader | pecli capture (time-to-capture, σ) | paper capture |")
    print("| --- | ---: | ---: |")
    for pursuer, evader in itertools.product(("optimal control", "ours"), repeat=2):
        paper = PAPER_TABLE_II[(pursuer, evader)][2]  # the capture rate
        cell = cells.get((names[pursuer]["pursuer"], names[evader]["evader"]))
        ours = (
            f"{cell.captures / cell.episodes:.3f} ({cell.time_to_capture_mean:.2f}, {cell.time_to_capture_std:.2f})"
            if cell
            else "-"
        )
        print(f"| {pursuer} vs {evader} | {ours} | {paper:.2f} |")


def _player_name(record: TournamentRecord, spec: str, role: str) -> str:
    """The tournament's name for the ``role`` player given as ``spec`` (a checkpoint's path, or a policy string)."""
    for rating in record.ratings:
        same = rating.spec == spec or (spec.endswith(".zip") and Path(rating.spec).resolve() == Path(spec).resolve())
        if same and rating.role == role:
            return rating.name
    return spec


def main() -> None:
    if len(sys.argv) > 1 and sys.argv[1] == "--one":
        config, model, sizes, steps, backend = sys.argv[2:7]
        grid = tuple(int(n) for n in sizes.split(","))
        print(json.dumps(one(config, model, grid, int(steps) or None, backend)))  # type: ignore[arg-type]
        return
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="step", required=True)
    s = sub.add_parser("solve", help="solve time, CPU, memory and accuracy of every model")
    s.add_argument("--config", default="point_mass")
    s.add_argument("--repeats", type=int, default=3, help="solves per rel4d case (the larger models: one)")
    s.add_argument("--quick", action="store_true", help="small grids and a 20-step horizon, for a smoke test")
    s.add_argument("--json", action="store_true", help="print the results as JSON")
    t = sub.add_parser("table2", help="Table II through the documented commands, beside the paper's")
    t.add_argument("--pursuer", required=True, help="the learned (BiMDN) pursuer checkpoint")
    t.add_argument("--evader", required=True, help="the learned (BiMDN) evader checkpoint")
    t.add_argument("--episodes", type=int, default=EPISODES)
    t.add_argument("--seeds", type=int, default=3)
    t.add_argument("--out", default=str(ROOT / "runs" / "table2"))
    args = parser.parse_args()
    {"solve": solve_table, "table2": table2}[args.step](args)


if __name__ == "__main__":
    main()
