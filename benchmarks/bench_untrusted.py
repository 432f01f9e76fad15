"""Untrusted files through every loading path: does a planted payload ever run? Do hostile records?

    python benchmarks/bench_untrusted.py [--out runs/bench_untrusted] [--part all|payloads|records]

Trains a tiny run, then plants a pickled payload (unpickling it creates a marker file) in one file at a
time: a checkpoint's ``data`` entry (where SB3 keeps pickled objects), its ``policy.pth``, its
optimiser's ``.pth``, the durable state's model and replay-buffer arrays, and an older pecli's
checkpoint (no network description, which only unpickling can rebuild). Each is given to every
command that reads it (``play``, ``tournament``, ``export onnx``, ``zoo list|show|best``,
``train --resume``), in a subprocess. Printed: per file and command, the exit code and whether the
payload ran; then the totals (target: 0 payloads run; refusals are one line, exit 1). Then hostile records: a
``run.json`` that names code beside it, ``PECLI_TRUST=off``, a lock file linked outside, a durable state naming a
model outside its run, metadata that claims huge networks, records nested too deep, numbers of 5000 digits, markup
in a path, files that never end or never open (a link to /dev/zero, a FIFO), YAML aliases that expand past any
config, weights and graphs that unpack or allocate gigabytes; each outcome counted by class (target: 0 payloads,
0 internal errors, 0 hangs).
"""

from __future__ import annotations

import argparse
import base64
import io
import json
import pickle
import shutil
import sys
import zipfile
from pathlib import Path

import numpy as np
import reliability  # the reliability suite's subprocess runner (its time and memory limits)

HANG_SECONDS = 300  # a command still running after this long is counted as hanging


class Payload:
    """Unpickling it creates ``marker``: stands for any code an attacker wants run."""

    def __init__(self, marker: Path) -> None:
        self.marker = marker

    def __reduce__(self):
        return (Path.touch, (self.marker,))


def pecli(*args: str) -> tuple[int, str]:
    """``python -m pecli ARGS`` under the reliability suite's limits: its exit code (-1: still running after
    :data:`HANG_SECONDS`) and its output."""
    return reliability.pecli(list(args), reliability.environment(None), HANG_SECONDS)


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
    data["policy_class"] = {
        ":type:": "<class 'type'>",
        ":serialized:": base64.b64encode(pickle.dumps(Payload(marker))).decode(),
    }
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
    parser.add_argument(
        "--part",
        choices=["all", "payloads", "records"],
        default="all",
        help="planted payloads, hostile records, or both",
    )
    args = parser.parse_args()
    out = args.out.resolve()
    shutil.rmtree(out, ignore_errors=True)
    clean = out / "clean"
    tiny = [
        "--set",
        "buffer_size=2000",
        "--set",
        "batch_size=32",
        "--set",
        "learning_starts=100",
        "--set",
        "net_arch=[16,16]",
        "--set",
        "n_envs=4",
        "--set",
        "checkpoint_every=5",
    ]
    made = pecli(
        "train", "pursuer", "-c", "quick", "--steps", "800", "--name", "victim", "--zoo", str(clean), "-q", *tiny
    )
    if made[0] != 0:
        sys.exit(made[1])

    def commands(zoo: Path, checkpoint: Path) -> dict[str, list[str]]:
        return {
            "play": ["play", "-p", str(checkpoint), "-e", "greedy", "-n", "4"],
            "tournament": [
                "tournament",
                str(zoo),
                "--baselines",
                "--episodes",
                "4",
                "--seeds",
                "1",
                "--out",
                str(zoo / "t"),
            ],
            "export onnx": ["export", "onnx", str(checkpoint), "--out", str(zoo / "x.onnx")],
            "zoo list": ["zoo", "list", str(zoo)],
            "zoo show": ["zoo", "show", str(checkpoint)],
            "zoo best": ["zoo", "best", "pursuer", str(zoo)],
            "train --resume": [
                "train",
                "pursuer",
                "--name",
                "victim",
                "--zoo",
                str(zoo),
                "--resume",
                "-q",
                "--steps",
                "1000",
            ],
        }

    if args.part == "records":
        hostile_records(out, clean)
        return
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
            code, output = pecli(*command)
            executed = marker.exists()
            marker.unlink(missing_ok=True)
            ran += executed
            internal += code not in (0, 1, 2)  # 3: pecli's internal error; -1: a hang; else a crash
            lines = [line for line in output.splitlines() if line.startswith("error")]
            rows.append((label, name, code, "YES" if executed else "no", lines[0][:110] if lines else ""))
    print("| file | command | exit | payload ran | refusal |\n| --- | --- | ---: | --- | --- |")
    for row in rows:
        print("| " + " | ".join(str(x) for x in row) + " |")
    print(f"\nloads tried: {len(rows)}, payloads run: {ran}, internal errors: {internal}")
    if args.part == "all":
        hostile_records(out, clean)


def edit_json(path: Path, **changes: object) -> None:
    path.write_text(json.dumps({**json.loads(path.read_text()), **changes}))


def hostile_records(out: Path, clean: Path) -> None:
    """Records that name code or paths, or claim sizes, each given to the command that reads it; every outcome
    counted by class: refused (exit 1 or 2, an error line), accepted (exit 0), internal (any other exit), payload (code
    ran, or a file outside the zoo changed)."""
    deep = "[" * 100_000 + "]" * 100_000

    def case(label: str, setup, command: list[str], env: dict[str, str] | None = None):
        zoo = (out / ("hostile-" + "".join(c if c.isalnum() else "-" for c in label))).resolve()
        shutil.copytree(clean, zoo)
        run = zoo / "victim"
        victim = out / f"victim-{zoo.name}.txt"
        victim.write_text("keep\n")
        marker = zoo / "PAYLOAD_RAN"
        setup(zoo, run, marker, victim)
        args = [arg.format(zoo=zoo, run=run) for arg in command]
        # the zoo on the import path, as if pecli ran in it; the reliability suite's limits on time and memory
        code, output = reliability.pecli(args, {**reliability.environment(None, zoo), **(env or {})}, HANG_SECONDS)
        if code == -1:
            return label, "hang", f"still running after {HANG_SECONDS} s"
        payload = marker.exists() or victim.read_text() != "keep\n"
        kind = "payload" if payload else "refused" if code in (1, 2) else "accepted" if code == 0 else "internal"
        lines = [line for line in output.splitlines() if line.startswith("error")]
        return label, kind, lines[0][:110] if lines else ""

    final = "{run}/pursuer/final.zip"
    resume = ["train", "pursuer", "--name", "victim", "--zoo", "{zoo}", "--resume", "-q", "--steps", "1000"]
    play = ["play", "-p", final, "-e", "greedy", "-n", "4"]

    def evil_module(zoo: Path, run: Path, marker: Path, victim: Path) -> None:
        (zoo / "evil.py").write_text(f"from pathlib import Path\nPath({str(marker)!r}).touch()\nclass E: pass\n")
        edit_json(run / "run.json", opponent="evil:E")

    def older_checkpoint(zoo: Path, run: Path, marker: Path, victim: Path) -> None:
        plant_as_older_pecli(run / "pursuer" / "final.zip", marker)

    def linked_lock(zoo: Path, run: Path, marker: Path, victim: Path) -> None:
        (run / ".pecli.lock").unlink(missing_ok=True)
        (run / ".pecli.lock").symlink_to(victim)

    def model_outside(zoo: Path, run: Path, marker: Path, victim: Path) -> None:
        state = run / "pursuer" / "resume" / "state.json"
        model = json.loads(state.read_text())["model"]
        shutil.copy(run / "pursuer" / "resume" / model, out / "outside.zip")
        edit_json(state, model=str(out / "outside.zip"))

    def meta(**changes: object):
        def setup(zoo: Path, run: Path, marker: Path, victim: Path) -> None:
            edit_json(run / "pursuer" / "final.json", **changes)

        return setup

    def exported(zoo: Path, run: Path) -> Path:
        """The run's pursuer exported beside it."""
        code, output = pecli("export", "onnx", str(run / "pursuer" / "final.zip"), "-n", "2")
        if code != 0:
            sys.exit(output)
        return run / "pursuer" / "final.onnx"

    def rewritten(model: Path, graph: bytes) -> None:
        """``graph`` in place of the exported ``model``, its sidecar's hash made to match."""
        from pecli.runtime import file_sha256, sidecar_path

        model.write_bytes(graph)
        edit_json(sidecar_path(model), model_sha256=file_sha256(model))

    def huge_graph(zoo: Path, run: Path, marker: Path, victim: Path) -> None:
        """An export whose graph asks ONNX Runtime for a 10^6 x 10^6 tensor, its sidecar's hash made to match."""
        import numpy as np
        from onnx import TensorProto, helper, numpy_helper

        model = exported(zoo, run)
        shape = numpy_helper.from_array(np.array([10**6, 10**6], np.int64), "shape")
        graph = helper.make_graph(
            [helper.make_node("ConstantOfShape", ["shape"], ["action"])],
            "g",
            [helper.make_tensor_value_info("obs", TensorProto.FLOAT, ["n", 1, 1])],
            [helper.make_tensor_value_info("action", TensorProto.FLOAT, None)],
            [shape],
        )
        rewritten(model, helper.make_model(graph).SerializeToString())

    def sized_at_run_time(zoo: Path, run: Path, marker: Path, victim: Path) -> None:
        """An export whose graph joins its input's shape to 4096 x 8192: a size only the run decides."""
        import numpy as np
        import onnx
        from onnx import TensorProto, helper, numpy_helper

        model = exported(zoo, run)
        graph = onnx.load(model)
        graph.graph.initializer.extend(numpy_helper.from_array(np.array([n], np.int64), f"n{n}") for n in (4096, 8192))
        graph.graph.node.extend(
            [
                helper.make_node("Shape", ["obs"], ["obs_shape"]),
                helper.make_node("Concat", ["obs_shape", "n4096", "n8192"], ["huge_shape"], axis=0),
                helper.make_node("ConstantOfShape", ["huge_shape"], ["huge"]),
                helper.make_node("ReduceSum", ["huge"], ["huge_sum"], keepdims=0),
            ]
        )
        graph.graph.output.append(helper.make_tensor_value_info("huge_sum", TensorProto.FLOAT, None))
        rewritten(model, graph.SerializeToString())

    def weights_bomb(zoo: Path, run: Path, marker: Path, victim: Path) -> None:
        """policy.pth as 1 GiB of zeros: about a megabyte compressed."""
        path = run / "pursuer" / "final.zip"
        with zipfile.ZipFile(path) as archive:
            entries = {name: archive.read(name) for name in archive.namelist()}
        entries["policy.pth"] = bytes(1 << 30)
        with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as archive:
            for name, data in entries.items():
                archive.writestr(name, data)

    def linked(relative: str, target: str):
        def setup(zoo: Path, run: Path, marker: Path, victim: Path) -> None:
            (run / relative).unlink(missing_ok=True)
            (run / relative).symlink_to(target)

        return setup

    def fifo(relative: str):
        def setup(zoo: Path, run: Path, marker: Path, victim: Path) -> None:
            (run / relative).unlink(missing_ok=True)
            __import__("os").mkfifo(run / relative)

        return setup

    aliases = "\n".join(
        ["d0: &d0 {a: 1, b: 2}"]
        + [f"d{i}: &d{i} {{" + ", ".join(f"k{j}: *d{i - 1}" for j in range(8)) + "}" for i in range(1, 12)]
    )

    def text(relative: str, body: str):
        def setup(zoo: Path, run: Path, marker: Path, victim: Path) -> None:
            (run / relative).write_text(body)

        return setup

    rows = [
        case("run.json names evil:E beside it", evil_module, resume),
        case("PECLI_TRUST=off, an older checkpoint", older_checkpoint, play, env={"PECLI_TRUST": "off"}),
        case(".pecli.lock linked to a file outside", linked_lock, resume),
        case("state.json model outside the run", model_outside, resume),
        case("metadata net_arch [2147483648]", meta(policy_kwargs={"net_arch": [2147483648], "n_critics": 2}), play),
        case("metadata n_critics 1000000", meta(policy_kwargs={"net_arch": [16, 16], "n_critics": 1_000_000}), play),
        case("metadata 100000 layers", meta(policy_kwargs={"net_arch": [16] * 100_000, "n_critics": 2}), play),
        case("metadata frame_stack 10**9", meta(frame_stack=10**9), play),
        case("metadata nested 100000 deep", text("pursuer/final.json", deep), play),
        case("run.json nested 100000 deep", text("run.json", deep), resume),
        case("state.json nested 100000 deep", text("pursuer/resume/state.json", deep), resume),
        case("config.yaml nested 20000 deep", text("config.yaml", "a: " + "[" * 20_000 + "]" * 20_000), resume),
        case(
            "export: ConstantOfShape [10^6, 10^6]",
            huge_graph,
            ["play", "-p", "{run}/pursuer/final.onnx", "-e", "greedy", "-n", "4"],
        ),
        case("config.yaml linked to /dev/zero", linked("config.yaml", "/dev/zero"), resume),
        case("config.yaml a FIFO", fifo("config.yaml"), resume),
        case("config.yaml of nested aliases (8^11 values)", text("config.yaml", aliases), resume),
        case("policy.pth of 1 GiB zeros, compressed", weights_bomb, play),
        case(
            "policy.pth of bytes no pickle holds",
            lambda z, r, m, v: rewrite_zip(r / "pursuer" / "final.zip", {"policy.pth": b"garbage" * 100}),
            play,
        ),
        case("checkpoint a FIFO", fifo("pursuer/final.zip"), play),
        case(
            "export: a size joined to the input's shape",
            sized_at_run_time,
            ["play", "-p", "{run}/pursuer/final.onnx", "-e", "greedy", "-n", "4"],
        ),
        case(
            "--set rounds of 5000 digits",
            lambda *a: None,
            ["train", "pursuer", "-c", "quick", "--set", "selfplay.rounds=" + "9" * 5000, "--zoo", "{zoo}/new"],
        ),
        case(
            "--zoo with markup z[/x]",
            lambda *a: None,
            [
                "train",
                "pursuer",
                "-c",
                "quick",
                "--steps",
                "100",
                "--zoo",
                "{zoo}/z[/x]",
                "-q",
                "--set",
                "n_envs=2",
                "--set",
                "learning_starts=50",
                "--set",
                "buffer_size=200",
            ],
        ),
    ]
    kinds = ("refused", "accepted", "internal", "hang", "payload")
    counts = {kind: sum(row[1] == kind for row in rows) for kind in kinds}
    print("\n| hostile record | outcome | line |\n| --- | --- | --- |")
    for row in rows:
        print("| " + " | ".join(row) + " |")
    print(
        "\n" + ", ".join(f"{kind}: {n}" for kind, n in counts.items()) + " (the markup --zoo is accepted: it is a "
        "valid folder name, printed as text)"
    )


if __name__ == "__main__":
    main()
