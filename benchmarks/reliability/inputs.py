"""Bad inputs: edited scenario files, ``--set`` values, episode counts and run names, edited export sidecars,
and damaged or foreign zips in a zoo, each through the real CLI."""

from __future__ import annotations

import json
import shutil
import zipfile
from pathlib import Path

from reliability import ROOT, TINY, Outcome, judge, pecli


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
