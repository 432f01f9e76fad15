"""Reliability figures: bad inputs, hard kills, concurrent writers and NaN policies,
each through the real CLI (``python -m pecli ...``) in a subprocess.

    python benchmarks/bench_reliability.py                         # everything, a few CPU-minutes
    python benchmarks/bench_reliability.py --only inputs nan       # some parts: inputs, nan, kills, writers
    python benchmarks/bench_reliability.py --source /tmp/pecli-main  # the same cases against other code

A bad input is *refused cleanly* when the command exits with code 1 (2: a usage error) and prints exactly one
``error:`` line and no traceback; an *internal error* is exit code 3, a traceback or any other
crash; *accepted* means it exited 0 (the input went through). Kills: a tournament with two
workers, one stuck in a pairing that never ends, is killed (SIGKILL or SIGTERM) once a pairing is
cached; processes of it still alive 10 s later are orphans. Writers: two tournaments with the
same ``--out`` started 0.5 s apart, and two ``--resume`` of one run: both exiting 0 is a
corruption (one overwrites the other). NaN: training with a learning rate of 1e30 (finite, so
strict configs take it, but the networks become NaN within a few updates), exporting a checkpoint
with NaN weights, and a robot controller on a NaN model; every checkpoint written is opened and
its weights checked. ``--source`` runs the subprocesses on another checkout of pecli (for a
before/after comparison). Results: a table on stdout and ``runs/bench_reliability.json``.
"""

from __future__ import annotations

import argparse
import json
import tempfile
from pathlib import Path

from reliability import ROOT, TINY, Outcome, environment, pecli, set_memory_limit, write
from reliability.faults import kills, nan_policies, writers
from reliability.inputs import bad_inputs


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--only", nargs="*", default=["inputs", "nan", "kills", "writers"])
    parser.add_argument("--tries", type=int, default=3, help="kills per signal, concurrent pairs per kind")
    parser.add_argument("--source", type=Path, default=None, help="another checkout of pecli to run (its root folder)")
    parser.add_argument("--memory-limit-gib", type=float, default=8.0, help="address space of each subprocess")
    parser.add_argument("--out", type=Path, default=ROOT / "runs" / "bench_reliability.json")
    args = parser.parse_args()
    set_memory_limit(args.memory_limit_gib)
    env = environment(args.source)
    outcomes: list[Outcome] = []
    print("| part | case | exit | error lines | verdict | message |\n|---|---|---|---|---|---|", flush=True)
    with tempfile.TemporaryDirectory(prefix="pecli-reliability-") as tmp:
        work = Path(tmp)
        base = work / "zoo-base" / "base"
        code, out = pecli(
            ["train", "pursuer", "-c", "quick", "--zoo", str(base.parent), "--name", "base", "--steps", "300", *TINY],
            env,
        )
        if code != 0:
            raise SystemExit(f"cannot train the base run: {out}")
        parts = {
            "inputs": lambda: bad_inputs(work, env, base),
            "nan": lambda: nan_policies(work, env, base),
            "kills": lambda: kills(work, environment(args.source, work), args.tries),
            "writers": lambda: writers(work, env, base, args.tries),
        }
        for name in args.only:
            for o in parts[name]():
                outcomes.append(o)
                print(
                    f"| {o.part} | {o.case} | {o.exit_code} | {o.error_lines} | {o.verdict} | "
                    f"{o.detail.replace('|', '/')} |",
                    flush=True,
                )
            write(outcomes, args.out)
    print(json.dumps(write(outcomes, args.out), indent=1))


if __name__ == "__main__":
    main()
