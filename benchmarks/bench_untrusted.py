"""Untrusted files through every loading path: does a planted payload ever run?

    python benchmarks/bench_untrusted.py [--out runs/bench_untrusted]

Trains a tiny run, then plants a pickled payload (unpickling it creates a marker file) in one file at a
time: a checkpoint's ``data`` entry (where SB3 keeps pickled objects), its ``policy.pth``, its
optimiser's ``.pth``, the durable state's model and replay-buffer arrays, and an older pecli's
checkpoint (no network description, which only unpickling can rebuild). Each is given to every
command that reads it (``play``, ``tournament``, ``export onnx``, ``zoo list|show|best``,
``train --resume``), in a subprocess. Printed: per file and command, the exit code and whether the
payload ran; then the totals (target: 0 payloads run; refusals are one line, exit 1).
"""

from __future__ import annotations

import argparse
import base64
import io
import json
import pickle
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import numpy as np


class Payload:
    """Unpickling it creates ``marker``: stands for any code an attacker wants run."""

    def __init__(self, marker: Path) -> None:
        self.marker = marker

    def __reduce__(self):
        return (Path.touch, (self.marker,))


def pecli(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "pecli", *args], capture_output=True, text=True, env=None)


def rewrite_zip(path: Path, replace: dict[str, bytes]) -> None:
    with zipfile.ZipFile(path) as archive:
        entries = {name: archive.read(name) for name in archive.namelist()}
    entries.update(replace)
    with zipfile.ZipFile(path, "w") as archive:
        for name, data in entries.items():
            archive.writestr(name, data)


def plant_in_data(path: Path, marker: Path) -> None:
    with zipfile.ZipFile(path) as archive:
        data = json.loads(archive.read("data"))
    data["policy_class"] = {":type:": "<class 'type'>",
                            ":serialized:": base64.b64encode(pickle.dumps(Payload(marker))).decode()}
    rewrite_zip(path, {"data": json.dumps(data).encode()})


def plant_in_entry(entry: str):
    def plant(path: Path, marker: Path) -> None:
        rewrite_zip(path, {entry: pickle.dumps(Payload(marker))})
    return plant


def plant_in_chunk(run: Path, marker: Path) -> None:
    resume = run / "pursuer" / "resume"
    chunk = sorted(resume.glob("replay-*.npz"))[-1]
    with np.load(chunk) as data:
        arrays = {key: data[key] for key in data.files}
    first = next(iter(arrays))
    arrays[first] = np.array([Payload(marker)] * len(arrays[first]), dtype=object)
    buffer = io.BytesIO()
    np.savez(buffer, **arrays)
    chunk.write_bytes(buffer.getvalue())


def plant_as_older_pecli(path: Path, marker: Path) -> None:
    plant_in_data(path, marker)
    meta_path = path.with_suffix(".json")
    meta = json.loads(meta_path.read_text())
    del meta["policy_kwargs"]
    meta_path.write_text(json.dumps(meta))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", type=Path, default=Path("runs/bench_untrusted"))
    args = parser.parse_args()
    out = args.out.resolve()
    shutil.rmtree(out, ignore_errors=True)
    clean = out / "clean"
    tiny = ["--set", "buffer_size=2000", "--set", "batch_size=32", "--set", "learning_starts=100",
            "--set", "net_arch=[16,16]", "--set", "n_envs=4", "--set", "checkpoint_every=5"]
    made = pecli("train", "pursuer", "-c", "quick", "--steps", "800", "--name", "victim", "--zoo", str(clean), "-q", *tiny)
    if made.returncode != 0:
        sys.exit(made.stdout + made.stderr)

    def commands(zoo: Path, checkpoint: Path) -> dict[str, list[str]]:
        return {
            "play": ["play", "-p", str(checkpoint), "-e", "greedy", "-n", "4"],
            "tournament": ["tournament", str(zoo), "--baselines", "--episodes", "4", "--seeds", "1",
                           "--out", str(zoo / "t")],
            "export onnx": ["export", "onnx", str(checkpoint), "--out", str(zoo / "x.onnx")],
            "zoo list": ["zoo", "list", str(zoo)],
            "zoo show": ["zoo", "show", str(checkpoint)],
            "zoo best": ["zoo", "best", "pursuer", str(zoo)],
            "train --resume": ["train", "pursuer", "--name", "victim", "--zoo", str(zoo), "--resume", "-q",
                               "--steps", "1000"],
        }

    cases = {
        "checkpoint: data entry": ("final", plant_in_data),
        "checkpoint: policy.pth": ("final", plant_in_entry("policy.pth")),
        "checkpoint: actor.optimizer.pth": ("final", plant_in_entry("actor.optimizer.pth")),
        "durable state: model data entry": ("resume", plant_in_data),
        "durable state: replay arrays": ("chunk", None),
        "older pecli checkpoint (no --trust)": ("final", plant_as_older_pecli),
    }
    rows, ran, internal = [], 0, 0
    for label, (where, plant) in cases.items():
        zoo = out / label.replace(" ", "_").replace(":", "").replace("(", "").replace(")", "")
        shutil.copytree(clean, zoo)
        run = zoo / "victim"
        checkpoint = run / "pursuer" / "final.zip"
        marker = zoo / "PAYLOAD_RAN"
        if where == "chunk":
            plant_in_chunk(run, marker)
        elif where == "resume":
            plant(sorted((run / "pursuer" / "resume").glob("model-*.zip"))[-1], marker)
        else:
            plant(checkpoint, marker)
        for name, command in commands(zoo, checkpoint).items():
            result = pecli(*command)
            executed = marker.exists()
            marker.unlink(missing_ok=True)
            ran += executed
            internal += result.returncode not in (0, 1)
            lines = [line for line in (result.stderr + result.stdout).strip().splitlines() if line.startswith("error")]
            rows.append((label, name, result.returncode, "YES" if executed else "no", lines[0][:110] if lines else ""))
    print("| file | command | exit | payload ran | refusal |\n| --- | --- | ---: | --- | --- |")
    for row in rows:
        print("| " + " | ".join(str(x) for x in row) + " |")
    print(f"\nloads tried: {len(rows)}, payloads run: {ran}, internal errors: {internal}")


if __name__ == "__main__":
    main()
