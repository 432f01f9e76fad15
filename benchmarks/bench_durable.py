"""What durability costs and what it saves.

    python benchmarks/bench_durable.py save  [--belief none bimdn] [--repeats 5]
    python benchmarks/bench_durable.py kills [--kills 8] [--seed 0] [--zoo runs/bench_kills]

``save``: on the paper scenario with a full replay buffer (100 000 transitions) and, with ``bimdn``,
a full belief buffer (25 000 windows), the time and size of: SB3's pickled ``save_replay_buffer``
(what pecli wrote before), the whole buffer as plain arrays, one checkpoint interval's rows (what a
durable save adds: 250 episodes of at most 200 transitions, 50 000, an upper bound), the model zip
(weights and optimisers), and a restore of the full state. Medians of ``--repeats``.

``kills``: ``pecli train pursuer -c quick`` killed with SIGKILL at random moments (seeded, uniform in
4-40 CPU-seconds of the process, so that they fall anywhere in the commit cycle), resumed
after each, until it finishes. Per kill: the CPU the killed process had spent since its newest commit
(lost work; before its first commit, since it started, imports included) against the CPU between two
commits (one checkpoint interval), and whether the resume worked (no dead end).
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np


def median_time(action, repeats: int) -> float:
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        action()
        times.append(time.perf_counter() - start)
    return statistics.median(times)


def size_mb(path: Path) -> float:
    files = [path] if path.is_file() else [p for p in path.rglob("*") if p.is_file()]
    return sum(p.stat().st_size for p in files) / 2**20


def bench_save(beliefs: list[str], repeats: int) -> None:
    import torch as th

    from pecli.policies import resolve_policy
    from pecli.rl.durable import DurableState, Ring, replay_arrays, write_chunk
    from pecli.rl.train import TrainJob, make_learner, with_overrides
    from pecli.scenario import load_scenario

    th.set_num_threads(1)
    print("| belief | what | time, s | size, MB |\n| --- | --- | ---: | ---: |")
    for belief in beliefs:
        scenario = with_overrides(load_scenario("paper"), {"belief": belief})
        t = scenario.training
        job = TrainJob("pursuer", scenario, "greedy", Path("unused"), "bench")
        _, model, fit = make_learner(job, resolve_policy("greedy", "evader", scenario), seed=0)
        rng = np.random.default_rng(0)
        buffer = model.replay_buffer
        for array in replay_arrays(buffer).values():  # a full buffer of plausible values
            array[:] = rng.uniform(-1, 1, array.shape).astype(array.dtype)
        buffer.full, buffer.pos = True, 0
        model.num_timesteps = t.buffer_size
        if fit is not None:
            for array in fit.buffer.arrays().values():
                array[:] = rng.uniform(-1, 1, array.shape).astype(array.dtype)
            fit.buffer.set_count(fit.buffer.capacity)
        interval_rows = 50_000 // t.n_envs
        with tempfile.TemporaryDirectory() as tmp:
            folder = Path(tmp)
            rows = [
                (
                    "SB3 pickled replay buffer (before)",
                    lambda: model.save_replay_buffer(folder / "buffer.pkl"),
                    folder / "buffer.pkl",
                )
            ]
            rows.append(
                (
                    "whole replay buffer as arrays",
                    lambda: write_chunk(
                        folder / "whole", "replay", replay_arrays(buffer), Ring(buffer.buffer_size), buffer.buffer_size
                    ),
                    folder / "whole",
                )
            )
            rows.append(
                (
                    "one interval of rows (50 000 transitions)",
                    lambda: write_chunk(
                        folder / "interval", "replay", replay_arrays(buffer), Ring(buffer.buffer_size, 0), interval_rows
                    ),
                    folder / "interval",
                )
            )
            if fit is not None:
                rows.append(
                    (
                        "whole belief buffer as arrays",
                        lambda: write_chunk(
                            folder / "belief",
                            "belief",
                            fit.buffer.arrays(),
                            Ring(fit.buffer.capacity),
                            fit.buffer.capacity,
                        ),
                        folder / "belief",
                    )
                )
            rows.append(
                ("model zip (weights, optimisers)", lambda: model.save(folder / "model.zip"), folder / "model.zip")
            )
            for directory in ("whole", "interval", "belief"):
                (folder / directory).mkdir()
            for what, action, path in rows:
                print(f"| {belief} | {what} | {median_time(action, repeats):.3f} | {size_mb(path):.1f} |")
            state = DurableState(folder / "state")
            print(
                f"| {belief} | durable save, first (whole buffers) | "
                f"{median_time(lambda: (setattr(state, 'record', None), state.save(model, fit, 0, 0.0)), repeats):.3f}"
                " | "
                f"{size_mb(folder / 'state'):.1f} |"
            )
            record = state.read()
            print(
                f"| {belief} | restore of that state | "
                f"{median_time(lambda: state.restore(record, model, fit), repeats):.3f} | |"
            )


def process_cpu(pid: int) -> float:
    """CPU seconds (user + system) of a live process, from /proc."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def stamp_of(path: Path) -> int | None:
    try:
        return path.stat().st_mtime_ns
    except FileNotFoundError:
        return None


def bench_kills(kills: int, seed: int, zoo: Path) -> None:
    shutil.rmtree(zoo / "kb", ignore_errors=True)
    rng = np.random.default_rng(seed)
    base = [sys.executable, "-m", "pecli", "train", "pursuer", "--name", "kb", "--zoo", str(zoo), "-q"]
    start = [*base, "-c", "quick", "--steps", "60000"]
    state_file = zoo / "kb" / "pursuer" / "resume" / "state.json"
    lost, intervals, dead_ends, rows = [], [], 0, []
    command = start
    for k in range(kills + 1):
        process = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        moment = rng.uniform(4.0, 40.0)  # CPU seconds of the process (imports take about 4)
        seen = stamp_of(state_file)
        last_commit_cpu, commits = 0.0, 0  # before its first commit, everything the process spent is at stake
        while process.poll() is None and (k == kills or process_cpu(process.pid) < moment):
            stamp = stamp_of(state_file)
            if stamp != seen:  # a commit
                cpu = process_cpu(process.pid)
                if commits:
                    intervals.append(cpu - last_commit_cpu)
                last_commit_cpu, commits, seen = cpu, commits + 1, stamp
            time.sleep(0.02)
        if process.poll() is None:
            at_kill = process_cpu(process.pid)
            process.send_signal(signal.SIGKILL)
            process.wait()
            lost.append(at_kill - last_commit_cpu)
            record = json.loads(state_file.read_text()) if state_file.is_file() else None
            rows.append(
                (k + 1, f"{moment:.1f}", f"{at_kill:.1f}", f"{lost[-1]:.1f}", record["steps"] if record else "-")
            )
        else:
            output = process.stdout.read()
            if process.returncode != 0:
                dead_ends += 1
                print(f"resume failed: {output.strip().splitlines()[-1]}")
            break
        command = [*base, "--resume"]
    print(
        "| kill | chosen moment, CPU s | CPU of the killed process, s | CPU lost since its newest commit, s | "
        "committed step |"
    )
    print("| ---: | ---: | ---: | ---: | ---: |")
    for row in rows:
        print("| " + " | ".join(str(x) for x in row) + " |")
    final = zoo / "kb" / "pursuer" / "final.json"
    steps = json.loads(final.read_text())["steps"] if final.is_file() else None
    print(f"\nkills: {len(rows)}, dead ends: {dead_ends}, finished: {steps == 60000} (steps {steps})")
    if lost:
        print(f"CPU lost per kill: median {statistics.median(lost):.1f} s, max {max(lost):.1f} s")
    if intervals:
        print(
            f"CPU between two commits (one interval): median {statistics.median(intervals):.1f} s, "
            f"max {max(intervals):.1f} s"
        )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = parser.add_subparsers(dest="what", required=True)
    save = sub.add_parser("save")
    save.add_argument("--belief", nargs="+", default=["none", "bimdn"])
    save.add_argument("--repeats", type=int, default=5)
    kills = sub.add_parser("kills")
    kills.add_argument("--kills", type=int, default=8)
    kills.add_argument("--seed", type=int, default=0)
    kills.add_argument("--zoo", type=Path, default=Path("runs/bench_kills"))
    args = parser.parse_args()
    if args.what == "save":
        bench_save(args.belief, args.repeats)
    else:
        bench_kills(args.kills, args.seed, args.zoo)


if __name__ == "__main__":
    main()
