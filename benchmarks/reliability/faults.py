"""Faults: NaN policies (training, export, a robot controller), hard kills of tournaments and concurrent
writers of one run, each through the real CLI."""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
import time
import zipfile
from pathlib import Path

from pecli.process import descendants, live_parents
from reliability import NEUTRAL, STALLING, TINY, Outcome, judge, limit_memory, pecli


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
