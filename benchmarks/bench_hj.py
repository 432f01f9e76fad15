"""HJ solver speed, memory and accuracy: rel4d and rel6d at two grid sizes, and hj-reachability on the same problem.

    python benchmarks/bench_hj.py                  # the full run recorded in docs/benchmarks.md
    python benchmarks/bench_hj.py --quick          # small grids and horizons, a smoke run

Every solve runs in a fresh process on one thread (OMP_NUM_THREADS=1, XLA on one thread). Peak
memory is the largest total of live NumPy/SciPy allocations during the solve (``tracemalloc``);
for hj-reachability, whose XLA buffers the tracer does not see, the growth of the process's
maximum resident set during the solve. Times are the median of ``--repeats`` solves for rel4d (one solve for rel6d, which takes a
minute); "CPU" is the process's CPU time. Accuracy is measured on 20 000 random states (relative
positions in the arena's middle, |r_i| ≤ 7 m; relative velocities within the limits) against the
closed form of SPEC §6: the discrete-time one for the NumPy solver, which plays the game's dt,
and the continuous-time one for hj-reachability, which solves the PDE (both columns are shown).
rel6d has no closed form (it clips each player's speed), so it gets no accuracy columns.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import statistics
import subprocess
import sys
import time
import tracemalloc

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("XLA_FLAGS", "--xla_cpu_multi_thread_eigen=false intra_op_parallelism_threads=1")

import numpy as np  # noqa: E402

from pecli.hj.oracle import continuous_value, discrete_value  # noqa: E402
from pecli.hj.problem import Problem  # noqa: E402
from pecli.hj.reachability import available, solve_with_hj_reachability  # noqa: E402
from pecli.hj.solver import solve  # noqa: E402
from pecli.scenario import load_scenario  # noqa: E402


def accuracy(problem: Problem, values: np.ndarray) -> dict[str, float]:
    """Sign agreement and mean |error| (m) against both closed forms, on 20 000 random rel4d states."""
    rng = np.random.default_rng(1)
    r, w = rng.uniform(-7.0, 7.0, (20_000, 2)), rng.uniform(-5.0, 5.0, (20_000, 2))
    zeros = np.zeros_like(r)
    solved = problem.grid.interpolate(values, problem.grid.points(zeros, zeros, r, w))
    game = problem.game
    out = {}
    for name, exact in (
        ("discrete", discrete_value(r, w, problem.steps, game.dt, game.capture_distance)),
        ("continuous", continuous_value(r, w, problem.steps * game.dt, game.capture_distance)),
    ):
        out[f"sign_{name}"] = float(np.mean((solved <= 0) == (exact <= 0)))
        out[f"error_{name}"] = float(np.mean(np.abs(solved - exact)))
    return out


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
    result = {"backend": backend, "model": model, "grid": problem.grid.describe(), "nodes": problem.grid.size,
              "steps": problem.steps, "seconds": seconds, "cpu": cpu_seconds, "peak_mb": peak}
    if model == "rel4d":
        result |= accuracy(problem, values)
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


def main() -> None:
    if len(sys.argv) > 1 and sys.argv[1] == "--one":
        config, model, sizes, steps, backend = sys.argv[2:7]
        grid = tuple(int(n) for n in sizes.split(","))
        print(json.dumps(one(config, model, grid, int(steps) or None, backend)))  # type: ignore[arg-type]
        return
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--config", default="point_mass")
    parser.add_argument("--repeats", type=int, default=3, help="solves per rel4d case (rel6d: one)")
    parser.add_argument("--quick", action="store_true", help="small grids and a 20-step horizon, for a smoke test")
    parser.add_argument("--json", action="store_true", help="print the results as JSON")
    args = parser.parse_args()

    steps = 20 if args.quick else None
    cases = [  # (backend, model, sizes, repeats)
        ("numpy", "rel4d", (41, 21) if not args.quick else (21, 11), args.repeats),
        ("numpy", "rel4d", (81, 21) if not args.quick else (41, 11), args.repeats),
        ("numpy", "rel6d", (21, 11) if not args.quick else (11, 5), 1),
        ("numpy", "rel6d", (41, 11) if not args.quick else (21, 5), 1),
        ("numpy", "rel4d", (21, 11), args.repeats),  # the grid hj-reachability solves below
    ]
    if available():
        cases.append(("hj-reachability", "rel4d", (21, 11), 1))
    else:
        print('hj-reachability is not installed (pip install "pecli[hj]"): its row is skipped', file=sys.stderr)
    results = []
    for backend, model, sizes, repeats in cases:
        results.append(measure(args.config, model, sizes, steps, backend, repeats))
        print(f"done: {backend} {model} {results[-1]['grid']}: {results[-1]['seconds']:.1f} s", file=sys.stderr)

    if args.json:
        print(json.dumps(results, indent=2))
        return
    print(f"scenario {args.config}, {platform.machine()}, numpy {np.__version__}, one thread per solve")
    print("| backend | model | grid | nodes | steps | solve s | CPU s | peak MB | runs "
          "| sign vs discrete | error vs discrete (m) | sign vs continuous | error vs continuous (m) |")
    print("| --- | --- | --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |")
    for r in results:
        exact = [f"{r[k]:.4f}" if k.startswith("sign") else f"{r[k]:.3f}" for k in
                 ("sign_discrete", "error_discrete", "sign_continuous", "error_continuous")] if "sign_discrete" in r \
            else ["-"] * 4
        print(f"| {r['backend']} | {r['model']} | {r['grid']} | {r['nodes']:,} | {r['steps']} | {r['seconds']:.2f} "
              f"| {r['cpu']:.2f} | {r['peak_mb']:.0f} | {r['runs']} | " + " | ".join(exact) + " |")
    if results[-1]["backend"] == "hj-reachability":
        numpy_run, jax_run = results[-2:]
        print(f"\non {numpy_run['grid']}: numpy {jax_run['seconds'] / numpy_run['seconds']:.0f}x faster than "
              f"hj-reachability (CPU {jax_run['cpu'] / numpy_run['cpu']:.0f}x); mean error "
              f"{numpy_run['error_discrete']:.3f} m (vs the discrete closed form) against "
              f"{jax_run['error_continuous']:.3f} m (hj-reachability vs the continuous one)")


if __name__ == "__main__":
    main()
