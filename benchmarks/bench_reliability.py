"""Reliability figures: bad inputs, hard kills, concurrent writers and NaN policies,
each through the real CLI (``python -m pecli ...``) in a subprocess.

    python benchmarks/bench_reliability.py                         # everything, a few CPU-minutes
    python benchmarks/bench_reliability.py --only inputs nan       # some parts: inputs, nan, kills, writers
    python benchmarks/bench_reliability.py --source /tmp/pecli-main  # the same cases against other code

A bad input is *refused cleanly* when the command exits with code 1 and prints exactly one
``error:`` line and no traceback; an *internal error* is exit code 2, a traceback or any other
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
import os
import resource
import shutil
import signal
import subprocess
import sys
import tempfile
import time
import zipfile
from dataclasses import asdict, dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
NEUTRAL = Path(
    tempfile.gettempdir()
)  # where the subprocesses run: `python -m` puts the working folder first on sys.path
TINY = [
    "--set",
    "learning_starts=50",
    "--set",
    "n_envs=2",
    "--set",
    "net_arch=[16, 16]",
    "--set",
    "buffer_size=500",
    "--set",
    "batch_size=16",
    "-q",
]
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
    if code == 1 and len(errors) == 1 and "Traceback" not in output and "internal error" not in output:
        verdict = "refused"
    elif code == 0:
        verdict = "accepted"
    else:
        verdict = "internal error"
    last = [line.strip() for line in output.splitlines() if line.strip()][-1:] or [""]
    return Outcome(part, case, code, len(errors), verdict, (errors[0] if errors else last[0])[:200])


# -- bad inputs ------------------------------------------------------------------------------------------------
def config_cases(folder: Path) -> list[tuple[str, Path]]:
    """Bad scenario files made from configs/quick.yaml by one edit each."""
    quick = (ROOT / "configs" / "quick.yaml").read_text()
    edits = {
        "v_min: .nan": ("v_min: -1.0", "v_min: .nan"),
        "dt: .inf": ("dt: 0.1", "dt: .inf"),
        "v_max: .inf": ("v_max: 2.5", "v_max: .inf"),
        "arena width: .inf": ("width: 8.0", "width: .inf"),
        "arena height: -.inf": ("height: 8.0", "height: -.inf"),
        "capture reward: .inf": ("capture: 1000.0", "capture: .inf"),
        "distance reward: .nan": ("distance: 1.0", "distance: .nan"),
        "sensor fov: .nan": ("fov: 2pi/3", "fov: .nan"),
        "learning_rate: .inf": ("batch_size: 256", "batch_size: 256\n  learning_rate: .inf"),
        "horizon twice": ("horizon: 150", "horizon: 150\nhorizon: 400"),
        "sensor range twice": ("range: 6.0, fov", "range: 6.0, range: 9.0, fov"),
        "horizon: true": ("horizon: 150", "horizon: true"),
        "dt: true": ("dt: 0.1", "dt: true"),
        "curriculum enabled: 1": ("enabled: true", "enabled: 1"),
        "n_envs: 100000000": ("steps: 100000", "steps: 100000\n  n_envs: 100000000"),
        "net_arch: [60000, 60000, 60000]": ("steps: 100000", "steps: 100000\n  net_arch: [60000, 60000, 60000]"),
        "net_arch: [1000000000000]": ("steps: 100000", "steps: 100000\n  net_arch: [1000000000000]"),
        "net_arch of 100 layers": ("steps: 100000", "steps: 100000\n  net_arch: [" + ", ".join(["64"] * 100) + "]"),
        "steps: 10^40": ("steps: 100000", "steps: " + "1" + "0" * 40),
        "buffer_size: 10^8 with a belief": ("buffer_size: 100000", "buffer_size: 100000000\n  belief: bimdn"),
        "horizon: 10^12": ("horizon: 150", "horizon: 1000000000000"),
        "history_length: 10^9": ("steps: 100000", "steps: 100000\n  history_length: 1000000000"),
        "frame_stack: 10^6": ("steps: 100000", "steps: 100000\n  frame_stack: 1000000"),
        "fov: sideways": ("fov: 2pi/3", "fov: sideways"),
        "unknown key": ("dt: 0.1", "dt: 0.1\nspeed_of_light: 3e8"),
        "python object tag": ("dt: 0.1", "dt: !!python/object/apply:os.getpid []"),
    }
    cases = []
    for name, (old, new) in edits.items():
        assert old in quick, old
        path = folder / f"{len(cases):02d}.yaml"
        path.write_text(quick.replace(old, new, 1))
        cases.append((name, path))
    nested = folder / "nested.yaml"
    nested.write_text("a: " + "[" * 5000 + "]" * 5000 + "\n")
    big = folder / "big.yaml"
    big.write_text(quick + "#" * (2 << 20) + "\n")
    return cases + [("YAML nested 5000 deep", nested), ("a 2 MiB file", big)]


def bad_inputs(work: Path, env: dict[str, str], base: Path) -> list[Outcome]:
    outcomes = []
    zoo = work / "zoo-inputs"
    for i, (name, path) in enumerate(config_cases(work)):
        code, out = pecli(
            ["train", "pursuer", "-c", str(path), "--zoo", str(zoo), "--name", f"c{i}", "--steps", "20", "-q"], env
        )
        outcomes.append(judge("inputs", f"config {name}", code, out))
    sets = [
        "learning_rate=.inf",
        "learning_rate=nan",
        "gamma=.nan",
        "n_envs=true",
        "curriculum.enabled=1",
        "steps=1e400",
        "n_envs=100000000",
        "net_arch=[64,1e9]",
        "belief_settings.hidden=100000000",
    ]
    for i, item in enumerate(sets):
        budget = [] if item.startswith("steps=") else ["--steps", "20"]  # --steps would override --set steps
        code, out = pecli(
            ["train", "pursuer", "-c", "quick", "--zoo", str(zoo), "--name", f"s{i}", *budget, "--set", item, "-q"], env
        )
        outcomes.append(judge("inputs", f"--set {item}", code, out))
    for command in (["tournament", "--baselines", "--seeds", "1", "-w", "1", "--out", str(work / "huge")], ["play"]):
        code, out = pecli([*command, "-c", "quick", "--episodes", "10000000000"], env)
        outcomes.append(judge("inputs", f"{command[0]} --episodes 10^10", code, out))
    for name in ["../../escape", "/tmp/pecli-bench-escape", "a/b", ".", "..", ".hidden", "a b"]:
        for command in (
            ["train", "pursuer", "--steps", "20"],
            ["selfplay", "--rounds", "1", "--steps-per-round", "20"],
        ):
            code, out = pecli(
                [*command, "-c", "quick", "--zoo", str(work / "deep" / "zoo"), "--name", name, *TINY], env
            )
            outcomes.append(judge("inputs", f"{command[0]} --name {name!r}", code, out))
    shutil.rmtree("/tmp/pecli-bench-escape", ignore_errors=True)
    outcomes += export_and_zoo_inputs(work, env, base)
    return outcomes


def export_and_zoo_inputs(work: Path, env: dict[str, str], base: Path) -> list[Outcome]:
    """Edited sidecars under ``export check``; damaged and foreign zips under ``zoo best`` and ``zoo show``."""
    outcomes = []
    checkpoint = base / "pursuer" / "final.zip"
    model = work / "export" / "final.onnx"
    code, out = pecli(["export", "onnx", str(checkpoint), "--out", str(model), "-n", "1"], env)
    if code != 0:
        return [Outcome("inputs", "exporting the base checkpoint", code, 0, "setup failed", out[-200:])]
    sidecar = json.loads(Path(f"{model}.json").read_text())
    edits = {
        "fov_rad": lambda s: s["sensor"].update(fov_rad=1.0),
        "command_limits": lambda s: s.update(command_limits=[9.0, 2.0]),
        "fingerprint": lambda s: s["scenario"].update(fingerprint="0123456789abcdef"),
        "dt_s": lambda s: s["control"].update(dt_s=0.05),
        "scenario config": lambda s: s["scenario"]["config"]["pursuer"]["sensor"].update(range=9.0),
    }
    for name, edit in edits.items():
        copy = work / "export" / f"edited-{name.replace(' ', '-')}.onnx"
        copy.write_bytes(model.read_bytes())
        edited = json.loads(json.dumps(sidecar))
        edit(edited)
        Path(f"{copy}.json").write_text(json.dumps(edited))
        code, out = pecli(["export", "check", str(copy), str(checkpoint), "-n", "1"], env)
        outcomes.append(judge("inputs", f"export check, sidecar {name} edited", code, out))
    zoo = work / "zoo-damaged"
    shutil.copytree(base, zoo / "run")
    role = zoo / "run" / "pursuer"
    (role / "empty.zip").write_bytes(b"")
    shutil.copy(role / "final.json", role / "empty.json")
    ratings = [
        {"name": "empty", "spec": str(role / "empty.zip"), "role": "pursuer", "elo": 1500.0, "stderr": 1.0},
        {"name": "final", "spec": str(role / "final.zip"), "role": "pursuer", "elo": 1000.0, "stderr": 1.0},
    ]
    (zoo / "tournament").mkdir()
    (zoo / "tournament" / "results.json").write_text(json.dumps({"ratings": ratings}))
    code, out = pecli(["zoo", "best", "pursuer", str(zoo)], env)
    named = out.strip().splitlines()[-1] if out.strip() else ""
    outcomes.append(
        Outcome(
            "inputs",
            "zoo best, top-rated checkpoint empty",
            code,
            0,
            "refused" if code == 0 and named.endswith("final.zip") else "accepted",
            named[-80:],
        )
    )
    foreign = zoo / "photos.zip"
    with zipfile.ZipFile(foreign, "w") as archive:
        archive.writestr("holiday.jpg", b"\xff\xd8")
    shutil.copy(role / "final.json", zoo / "photos.json")
    code, out = pecli(["zoo", "show", str(foreign)], env)
    outcomes.append(judge("inputs", "zoo show, a zip that is not a checkpoint", code, out))
    code, out = pecli(["zoo", "show", str(role / "empty.zip")], env)
    outcomes.append(judge("inputs", "zoo show, a zero-byte checkpoint", code, out))
    return outcomes


# -- NaN policies ----------------------------------------------------------------------------------------------
def non_finite_checkpoints(folder: Path) -> tuple[int, int]:
    """(checkpoints under ``folder``, those whose network weights hold NaN or inf)."""
    import io

    import torch

    total = broken = 0
    for path in folder.rglob("*.zip"):
        total += 1
        try:
            with zipfile.ZipFile(path) as archive:
                weights = torch.load(io.BytesIO(archive.read("policy.pth")), weights_only=True, map_location="cpu")
        except Exception:  # another checkpoint format: count it as unreadable, not as NaN
            continue
        broken += any(not torch.isfinite(t).all() for t in weights.values() if torch.is_tensor(t))
    return total, broken


POISON = """
import io, math, shutil, sys, zipfile
from pathlib import Path
import torch
checkpoint, out = Path(sys.argv[1]), Path(sys.argv[2])
with zipfile.ZipFile(checkpoint) as source, zipfile.ZipFile(out, "w") as copy:
    for entry in source.infolist():
        data = source.read(entry)
        if entry.filename == "policy.pth":
            weights = torch.load(io.BytesIO(data), weights_only=True)
            weights["actor.mu.0.weight"].fill_(math.nan)
            buffer = io.BytesIO()
            torch.save(weights, buffer)
            data = buffer.getvalue()
        copy.writestr(entry, data)
shutil.copy(checkpoint.with_suffix(".json"), out.with_suffix(".json"))
"""

CONTROLLER = """
import math, sys
from pathlib import Path
import numpy as np
from pecli.errors import ExportError
from pecli.export.exporter import onnx_bytes
from pecli.export.sidecar import build_sidecar
from pecli.game.si import SILayout
from pecli.policies.learned import LearnedPolicy
from pecli.runtime import Controller, ExportedModel
from pecli.scenario import load_scenario
checkpoint = Path(sys.argv[1])
scenario = load_scenario("quick")
learned = LearnedPolicy.load(checkpoint, "pursuer", scenario)
graph, data = onnx_bytes(learned, SILayout(scenario, "pursuer"), 17)
sidecar = build_sidecar(graph, scenario, learned.meta, checkpoint, 17, learned.draws)
controller = Controller(ExportedModel.from_bytes(data, sidecar), seed=0)
sent = 0
for tick in range(20):
    try:
        command = controller.step(np.zeros(5), np.array([1.0, 1.0, 0.0, 0.0]))
    except ExportError as exc:
        print("error:", exc, file=sys.stderr)
        sys.exit(1)
    sent += int(not np.isfinite(command).all())
print("non-finite commands returned:", sent)
"""


def nan_policies(work: Path, env: dict[str, str], base: Path) -> list[Outcome]:
    outcomes = []
    for command in (
        ["train", "pursuer", "--steps", "3000", "--set", "checkpoint_every=1"],
        ["selfplay", "--rounds", "2", "--steps-per-round", "400"],
    ):
        zoo = work / f"zoo-nan-{command[0]}"
        code, out = pecli(
            [*command, "-c", "quick", "--zoo", str(zoo), "--name", "lr", *TINY, "--set", "learning_rate=1e30"], env
        )
        total, broken = non_finite_checkpoints(zoo)
        outcome = judge("nan", f"{command[0]} --set learning_rate=1e30", code, out)
        outcome.detail = f"{total} checkpoints written, {broken} with NaN weights; {outcome.detail}"[:200]
        outcome.verdict = f"{broken} NaN written, " + outcome.verdict
        outcomes.append(outcome)
    poisoned = base / "pursuer" / "poisoned.zip"
    done = subprocess.run(
        [sys.executable, "-c", POISON, str(base / "pursuer" / "final.zip"), str(poisoned)],
        env=env,
        capture_output=True,
        text=True,
        cwd=NEUTRAL,
    )
    if done.returncode != 0:
        return outcomes + [
            Outcome("nan", "poisoning a checkpoint", done.returncode, 0, "setup failed", done.stderr[-200:])
        ]
    code, out = pecli(["export", "onnx", str(poisoned), "-n", "1"], env)
    written = poisoned.with_suffix(".onnx").is_file()
    outcome = judge("nan", "export onnx of a checkpoint with NaN weights", code, out)
    outcome.verdict = f"{int(written)} NaN exported, " + outcome.verdict
    outcomes.append(outcome)
    done = subprocess.run(
        [sys.executable, "-c", CONTROLLER, str(poisoned)], env=env, capture_output=True, text=True, cwd=NEUTRAL
    )
    outcome = judge("nan", "robot Controller.step on a NaN network", done.returncode, done.stderr + done.stdout)
    if done.returncode == 0:
        outcome.verdict = "NaN commands returned"
    outcomes.append(outcome)
    return outcomes


# -- hard kills of tournaments ----------------------------------------------------------------------------------
def live_parents() -> dict[int, int]:
    found = {}
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        if fields[0] != "Z":
            found[int(stat.parent.name)] = int(fields[1])
    return found


def descendants(pid: int) -> set[int]:
    parents, found, frontier = live_parents(), set(), {pid}
    while frontier:
        frontier = {child for child, parent in parents.items() if parent in frontier} - found
        found |= frontier
    return found


def kills(work: Path, env: dict[str, str], tries: int) -> list[Outcome]:
    shutil.copy(STALLING, work / "stalling.py")
    outcomes = []
    for signal_name in ("SIGKILL", "SIGTERM"):
        for attempt in range(tries):
            out = work / f"kill-{signal_name}-{attempt}"
            driver = subprocess.Popen(
                [
                    sys.executable,
                    "-m",
                    "pecli",
                    "tournament",
                    "--baselines",
                    "stalling:StallingEvader",
                    "-c",
                    "quick",
                    "-n",
                    "4",
                    "--seeds",
                    "1",
                    "--workers",
                    "2",
                    "--out",
                    str(out),
                ],
                env=env,
                cwd=work,
                stdout=subprocess.DEVNULL,
                stderr=subprocess.DEVNULL,
                preexec_fn=limit_memory,
            )
            deadline = time.monotonic() + 300
            while driver.poll() is None and not any((out / "pairings").glob("*.json")) and time.monotonic() < deadline:
                time.sleep(0.1)
            children = descendants(driver.pid)
            driver.send_signal(getattr(signal, signal_name))
            driver.wait(timeout=60)
            time.sleep(10)
            orphans = children & set(live_parents())
            for pid in orphans:
                os.kill(pid, signal.SIGKILL)
            outcomes.append(
                Outcome(
                    "kills",
                    f"tournament --workers 2, {signal_name} #{attempt + 1}",
                    driver.returncode,
                    0,
                    f"{len(orphans)} orphans",
                    f"{len(children)} child processes before the kill",
                )
            )
    return outcomes


# -- concurrent writers -----------------------------------------------------------------------------------------
def writers(work: Path, env: dict[str, str], base: Path, tries: int) -> list[Outcome]:
    outcomes = []
    for attempt in range(tries):
        out = work / f"writers-tournament-{attempt}"
        args = [
            "tournament",
            "--baselines",
            "-c",
            "quick",
            "-n",
            "300",
            "--seeds",
            "2",
            "--workers",
            "1",
            "--out",
            str(out),
        ]
        codes, errors = concurrently([args, args], env)
        outcomes.append(writer_outcome(f"two tournaments, one --out #{attempt + 1}", codes, errors))
    for attempt in range(tries):
        zoo = work / f"writers-zoo-{attempt}"
        shutil.copytree(base, zoo / "base")
        args = ["train", "pursuer", "--zoo", str(zoo), "--name", "base", "--resume", "--steps", "3000", "-q"]
        codes, errors = concurrently([args, args], env)
        outcomes.append(writer_outcome(f"two train --resume of one run #{attempt + 1}", codes, errors))
    return outcomes


def concurrently(commands: list[list[str]], env: dict[str, str]) -> tuple[list[int], list[str]]:
    processes = []
    for args in commands:
        processes.append(
            subprocess.Popen(
                [sys.executable, "-m", "pecli", *args],
                env=env,
                cwd=NEUTRAL,
                stdout=subprocess.DEVNULL,
                stderr=subprocess.PIPE,
                text=True,
                preexec_fn=limit_memory,
            )
        )
        time.sleep(0.5)
    errors = [p.communicate(timeout=600)[1] for p in processes]
    return [p.returncode for p in processes], errors


def writer_outcome(case: str, codes: list[int], errors: list[str]) -> Outcome:
    refusals = [line for text in errors for line in text.splitlines() if "being written by" in line]
    corrupted = codes.count(0) > 1
    verdict = "1 corrupted" if corrupted else ("second refused" if refusals else "FAILED: " + str(codes))
    return Outcome("writers", case, max(codes), len(refusals), verdict, refusals[0][:200] if refusals else "")


# -- the whole ----------------------------------------------------------------------------------------------------
def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--only", nargs="*", default=["inputs", "nan", "kills", "writers"])
    parser.add_argument("--tries", type=int, default=3, help="kills per signal, concurrent pairs per kind")
    parser.add_argument("--source", type=Path, default=None, help="another checkout of pecli to run (its root folder)")
    parser.add_argument("--memory-limit-gib", type=float, default=8.0, help="address space of each subprocess")
    parser.add_argument("--out", type=Path, default=ROOT / "runs" / "bench_reliability.json")
    args = parser.parse_args()
    global MEMORY_LIMIT
    MEMORY_LIMIT = int(args.memory_limit_gib * 2**30)
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


def write(outcomes: list[Outcome], path: Path) -> dict[str, dict[str, int]]:
    """Write the outcomes and their counts per part and verdict to ``path``; returns the counts."""
    summary: dict[str, dict[str, int]] = {}
    for o in outcomes:
        part = summary.setdefault(o.part, {})
        part[o.verdict] = part.get(o.verdict, 0) + 1
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps({"summary": summary, "outcomes": [asdict(o) for o in outcomes]}, indent=1))
    return summary


if __name__ == "__main__":
    main()
