"""`pecli experiment` on Ray: wall time with 1 and 2 workers, and Ray's overhead against a plain loop.

    python benchmarks/bench_experiment.py                    # 4 runs of 2 x 3000 transitions per side
    python benchmarks/bench_experiment.py --runs 4 --steps-per-round 6000 --out runs/bench_experiment

One small experiment (quick.yaml, belief none, ``--runs`` seeds of self-play, a small ranking and
tournament) is run three times from scratch in one process, in this order:

1. **loop**: the same runs trained one after the other in this process by the function each Ray task
   calls (:func:`pecli.experiment.runs.execute_run`): no Ray at all;
2. **ray-1**: the whole experiment on embedded Ray with 1 worker (``--cpus 1``);
3. **ray-2**: the whole experiment on embedded Ray with 2 workers (``--cpus 2``).

It reports the wall time of each stage, the speed-up of 2 workers over 1 (target >= 1.8) and Ray's
overhead: the training stage on 1 worker against the loop (target <= 5 %), plus the start of Ray and the
round trip of an empty task. Wall times on a shared machine count what the other processes take too;
the script prints the load average before and after.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import time
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")

from pecli.experiment import ExperimentRunner, RayCluster  # noqa: E402
from pecli.experiment.runs import execute_run  # noqa: E402
from pecli.experiment.spec import experiment_from_dict  # noqa: E402
from pecli.io import atomic_write_json  # noqa: E402


def experiment(runs: int, rounds: int, steps_per_round: int):
    return experiment_from_dict(
        {
            "name": "bench",
            "scenario": "quick",
            "training": {"learning_starts": 500, "checkpoint_every": 20},
            "runs": {
                "kinds": ["none"],
                "seeds": list(range(runs)),
                "rounds": rounds,
                "steps_per_round": steps_per_round,
            },
            "ranking": {"sample": 4, "episodes": 50},
            "tournament": {"episodes": 100, "baselines": True},
        },
        "bench",
    )


def timed_experiment(loaded, out: Path, cpus: int) -> dict[str, float]:
    """Seconds of Ray's start and of each stage of the experiment on ``cpus`` embedded workers."""
    marks: list[tuple[str, float]] = []

    def update(rows, stage: str) -> None:
        name = stage.split(" ")[0]
        if not marks or marks[-1][0] != name:
            marks.append((name, time.perf_counter()))

    start = time.perf_counter()
    with RayCluster(cpus=cpus) as cluster:
        ready = time.perf_counter()
        marks.append(("training", ready))
        ExperimentRunner(loaded, out, on_update=update).run(cluster)
        end = time.perf_counter()
    times = {"ray_start": ready - start}
    for (name, at), (_, until) in zip(marks, [*marks[1:], ("end", end)]):
        times[name] = times.get(name, 0.0) + until - at
    times["experiment"] = end - ready
    return times


def empty_task_seconds(tasks: int = 200) -> float:
    """Mean seconds of an empty Ray task's round trip (submitted one at a time) on embedded Ray."""
    import ray

    @ray.remote(num_cpus=1)
    def nothing() -> None:
        return None

    with RayCluster(cpus=1):
        ray.get(nothing.remote())  # a warm worker
        start = time.perf_counter()
        for _ in range(tasks):
            ray.get(nothing.remote())
        return (time.perf_counter() - start) / tasks


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--runs", type=int, default=4)
    parser.add_argument("--rounds", type=int, default=2)
    parser.add_argument("--steps-per-round", type=int, default=3000)
    parser.add_argument("--out", type=Path, default=Path("runs/bench_experiment"))
    args = parser.parse_args()
    loaded = experiment(args.runs, args.rounds, args.steps_per_round)
    shutil.rmtree(args.out, ignore_errors=True)
    load_before = os.getloadavg()

    start = time.perf_counter()
    for run in loaded.runs():
        execute_run(run, args.out / "loop" / "zoo")
    loop = time.perf_counter() - start
    ray1 = timed_experiment(loaded, args.out / "ray-1", cpus=1)
    ray2 = timed_experiment(loaded, args.out / "ray-2", cpus=2)
    empty = empty_task_seconds()

    result = {
        "runs": args.runs,
        "rounds": args.rounds,
        "steps_per_round": args.steps_per_round,
        "loop_training_s": round(loop, 2),
        "ray_1": {k: round(v, 2) for k, v in ray1.items()},
        "ray_2": {k: round(v, 2) for k, v in ray2.items()},
        "speedup_2_over_1": round(ray1["experiment"] / ray2["experiment"], 3),
        "speedup_2_over_1_training": round(ray1["training"] / ray2["training"], 3),
        "ray_overhead_training": round(ray1["training"] / loop - 1, 4),
        "empty_task_ms": round(empty * 1000, 3),
        "load_average_before_after": [round(load_before[0], 2), round(os.getloadavg()[0], 2)],
    }
    atomic_write_json(args.out / "results.json", result)
    print(f"{args.runs} runs x {args.rounds} rounds x {args.steps_per_round} transitions per side (quick, none)")
    print(f"{'':>12} {'ray start':>10} {'training':>9} {'ranking':>8} {'tournament':>11} {'experiment':>11}")
    for name, t in (("ray, 1 cpu", ray1), ("ray, 2 cpus", ray2)):
        print(
            f"{name:>12} {t['ray_start']:>10.1f} {t['training']:>9.1f} {t.get('ranking', 0):>8.1f} "
            f"{t.get('tournament', 0):>11.1f} {t['experiment']:>11.1f}"
        )
    print(f"{'plain loop':>12} {'':>10} {loop:>9.1f}")
    print(
        f"speed-up with 2 workers: {result['speedup_2_over_1']:.2f}x whole experiment, "
        f"{result['speedup_2_over_1_training']:.2f}x training (target >= 1.8)"
    )
    print(
        f"Ray's overhead on training, 1 worker vs the loop: {100 * result['ray_overhead_training']:+.1f} % "
        f"(target <= 5 %); an empty task's round trip {result['empty_task_ms']:.2f} ms"
    )
    print(f"load average before/after: {result['load_average_before_after']}")
    print(json.dumps(result))


if __name__ == "__main__":
    main()
