"""What the reliability benchmark shares: running ``python -m pecli`` in a subprocess and judging its outcome.

A bad input is *refused cleanly* when the command exits with code 1 (2: a usage error, the command line's) and prints
exactly one ``error:`` line and no traceback; an *internal error* is exit code 3, a traceback or any other crash;
*accepted* means it exited 0.
"""

from __future__ import annotations

import json
import os
import resource
import subprocess
import sys
import tempfile
from dataclasses import asdict, dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
NEUTRAL = Path(tempfile.gettempdir())  # where the subprocesses run: `python -m` puts the working folder on sys.path
TINY = ["--set", "learning_starts=50", "--set", "n_envs=2", "--set", "net_arch=[16, 16]", "--set", "buffer_size=500"]
TINY += ["--set", "batch_size=16", "-q"]  # a run of a few seconds
STALLING = ROOT / "tests" / "stalling.py"  # the policy whose pairing keeps a worker busy until killed


@dataclass
class Outcome:
    part: str
    case: str
    exit_code: int
    error_lines: int
    verdict: str  # refused | accepted | internal error | ok | FAILED ...
    detail: str = ""


MEMORY_LIMIT = 8 << 30  # address space of each subprocess (--memory-limit-gib): a bad input must not take the machine


def set_memory_limit(gib: float) -> None:
    """The address space each subprocess may take from now on, GiB."""
    global MEMORY_LIMIT
    MEMORY_LIMIT = int(gib * 2**30)


def limit_memory() -> None:
    resource.setrlimit(resource.RLIMIT_AS, (MEMORY_LIMIT, MEMORY_LIMIT))


def environment(source: Path | None, extra: Path | None = None) -> dict[str, str]:
    paths = [str(p) for p in (source, extra) if p is not None]
    env = {**os.environ, "COLUMNS": "200", "OMP_NUM_THREADS": "1", "PYTHONPATH": os.pathsep.join(paths)}
    env.pop("PECLI_DEBUG", None)
    return env


def pecli(args: list[str], env: dict[str, str], timeout: float = 300) -> tuple[int, str]:
    """Run ``python -m pecli ARGS``; returns the exit code and stderr + stdout."""
    try:
        done = subprocess.run(
            [sys.executable, "-m", "pecli", *args],
            env=env,
            capture_output=True,
            text=True,
            timeout=timeout,
            cwd=NEUTRAL,
            preexec_fn=limit_memory,
        )
    except subprocess.TimeoutExpired:
        return -1, "timed out"
    return done.returncode, done.stderr + done.stdout


def judge(part: str, case: str, code: int, output: str) -> Outcome:
    errors = [line for line in output.splitlines() if line.startswith(("error:", "internal error:"))]
    if code in (1, 2) and len(errors) == 1 and "Traceback" not in output and "internal error" not in output:
        verdict = "refused"
    elif code == 0:
        verdict = "accepted"
    else:
        verdict = "internal error"
    last = [line.strip() for line in output.splitlines() if line.strip()][-1:] or [""]
    return Outcome(part, case, code, len(errors), verdict, (errors[0] if errors else last[0])[:200])


def write(outcomes: list[Outcome], path: Path) -> dict[str, dict[str, int]]:
    """Write the outcomes and their counts per part and verdict to ``path``; returns the counts."""
    summary: dict[str, dict[str, int]] = {}
    for o in outcomes:
        part = summary.setdefault(o.part, {})
        part[o.verdict] = part.get(o.verdict, 0) + 1
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps({"summary": summary, "outcomes": [asdict(o) for o in outcomes]}, indent=1))
    return summary
