"""Checkpoints are data: a pickled payload in a checkpoint never runs, unless the user says --trust."""

from __future__ import annotations

import base64
import json
import pickle
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest
from typer.testing import CliRunner

from pecli.cli import app
from pecli.policies import resolve_policy
from pecli.rl.train import DEFAULT_OPPONENT, TrainJob, checkpoint_meta, make_env, make_model, with_overrides
from pecli.scenario import Scenario
from pecli.trust import UntrustedFileError
from pecli.zoo import Run

runner = CliRunner()


class Payload:
    """What an attacker pickles: unpickling it creates ``marker`` (any code could run there)."""

    def __init__(self, marker: Path) -> None:
        self.marker = marker

    def __reduce__(self):
        return (Path.touch, (self.marker,))


def rewrite_zip(path: Path, replace: dict[str, bytes]) -> None:
    """Replace entries of the zip at ``path``."""
    with zipfile.ZipFile(path) as archive:
        entries = {name: archive.read(name) for name in archive.namelist()}
    entries.update(replace)
    with zipfile.ZipFile(path, "w") as archive:
        for name, data in entries.items():
            archive.writestr(name, data)


@pytest.fixture(scope="module")
def zoo(tmp_path_factory, quick: Scenario) -> Path:
    """A zoo with one tiny pursuer run: ``zoo/run/pursuer/final.zip``."""
    zoo = tmp_path_factory.mktemp("zoo")
    scenario = with_overrides(
        quick, {"buffer_size": 500, "batch_size": 16, "learning_starts": 50, "net_arch": [16, 16], "n_envs": 2}
    )
    job = TrainJob(role="pursuer", scenario=scenario, opponent=DEFAULT_OPPONENT["pursuer"], zoo=zoo, name="run")
    model = make_model(job, make_env(job, resolve_policy("greedy", "evader", scenario), seed=0), tensorboard=None)
    model.learn(60)
    Run.create(zoo, "run", scenario, {"command": "test"}).save(
        model, "pursuer", "final", checkpoint_meta(job, model, 0)
    )
    return zoo


def poisoned_copy(zoo: Path, tmp_path: Path, marker: Path, entry: str) -> Path:
    """A copy of the zoo whose checkpoint carries a payload in ``entry``: in ``data`` as SB3 stores pickled
    objects (base64 under ':serialized:'), or as the whole ``policy.pth``."""
    copy = tmp_path / "zoo"
    shutil.copytree(zoo, copy)
    path = copy / "run" / "pursuer" / "final.zip"
    with zipfile.ZipFile(path) as archive:
        data = json.loads(archive.read("data"))
    if entry == "data":
        data["policy_class"] = {
            ":type:": "<class 'type'>",
            ":serialized:": base64.b64encode(pickle.dumps(Payload(marker))).decode(),
        }
        rewrite_zip(path, {"data": json.dumps(data).encode()})
    else:
        rewrite_zip(path, {"policy.pth": pickle.dumps(Payload(marker))})
    return path


def test_the_payload_is_real(zoo: Path, tmp_path: Path) -> None:
    """SB3's own loader runs the payload: what pecli must never do."""
    from stable_baselines3 import TD3

    marker = tmp_path / "ran"
    path = poisoned_copy(zoo, tmp_path, marker, "data")
    with pytest.raises(Exception):  # noqa: B017 (SB3 fails however it fails; the payload ran)
        TD3.load(path)
    assert marker.exists()


def test_a_payload_in_data_never_runs(zoo: Path, tmp_path: Path) -> None:
    marker = tmp_path / "ran"
    path = poisoned_copy(zoo, tmp_path, marker, "data")
    for command in (
        ["play", "-p", str(path), "-e", "greedy", "-n", "4"],
        [
            "tournament",
            str(path.parents[2]),
            "--baselines",
            "--episodes",
            "4",
            "--seeds",
            "1",
            "--out",
            str(tmp_path / "t"),
        ],
        ["export", "onnx", str(path), "--out", str(tmp_path / "exported.onnx")],
        ["zoo", "show", str(path)],
    ):
        result = runner.invoke(app, command)
        assert result.exit_code == 0, (command, result.output)  # the weights are fine; the payload is ignored
        assert not marker.exists(), command


def test_a_payload_in_the_weights_is_refused(zoo: Path, tmp_path: Path) -> None:
    marker = tmp_path / "ran"
    path = poisoned_copy(zoo, tmp_path, marker, "policy.pth")
    result = runner.invoke(app, ["play", "-p", str(path), "-e", "greedy", "-n", "4"])
    assert result.exit_code == 1 and "holds pickled objects" in result.output and "--trust" in result.output
    assert len(result.output.strip().splitlines()) == 1
    tournament = runner.invoke(
        app,
        [
            "tournament",
            str(path.parents[2]),
            "--baselines",
            "--episodes",
            "2",
            "--seeds",
            "1",
            "--workers",
            "2",
            "--out",
            str(tmp_path / "t"),
        ],
    )
    assert tournament.exit_code == 1 and "holds pickled objects" in tournament.output  # from a worker process
    assert not marker.exists()


def pickled_where_older_pecli_kept_them(path: Path) -> None:
    """Save the checkpoint again with its classes pickled under the modules an older pecli had
    (``pecli.rl.policies``)."""
    import sys
    import zipfile

    from stable_baselines3 import TD3

    import pecli.models.extractors as extractors
    import pecli.models.policies as policies

    model = TD3.load(path)  # our own file, written by this test's zoo
    modules = {f"pecli.rl.{m.__name__.rpartition('.')[2]}": m for m in (policies, extractors)}
    classes = {
        c: c.__module__
        for m in modules.values()
        for c in vars(m).values()
        if isinstance(c, type) and c.__module__ == m.__name__
    }
    try:
        for old, module in modules.items():
            sys.modules[old] = module
        for c in classes:
            c.__module__ = c.__module__.replace("pecli.models.", "pecli.rl.")
        model.save(path)
    finally:
        for c, module in classes.items():
            c.__module__ = module
        for old in modules:
            sys.modules.pop(old, None)
    with zipfile.ZipFile(path) as archive:
        assert b"pecli.rl.policies" in __import__("base64").b64decode(
            json.loads(archive.read("data"))["policy_class"][":serialized:"]
        )


def test_playing_a_checkpoint_unpacks_its_policy_weights_alone(zoo: Path, tmp_path: Path) -> None:
    from pecli.models.checkpoint import read_weights

    marker = tmp_path / "ran"
    path = poisoned_copy(zoo, tmp_path, marker, "data")  # data is never unpickled either
    rewrite_zip(path, {"actor.optimizer.pth": pickle.dumps(Payload(marker)), "big.pth": bytes(5_000_000)})
    result = runner.invoke(app, ["play", "-p", str(path), "-e", "greedy", "-n", "4"])
    assert result.exit_code == 0, result.output  # what a policy does not need is not unpacked, nor refused
    with pytest.raises(UntrustedFileError, match="holds pickled objects"):
        read_weights(path)  # every entry, as a resumed run reads them
    assert not marker.exists()


def test_a_checkpoint_of_an_older_pecli_needs_trust(zoo: Path, tmp_path: Path, monkeypatch) -> None:
    """Metadata without a network description: only unpickling can rebuild it."""
    monkeypatch.setenv("PECLI_TRUST", "0")  # and restored after the test, which sets it through --trust
    copy = tmp_path / "zoo"
    shutil.copytree(zoo, copy)
    meta_path = copy / "run" / "pursuer" / "final.json"
    meta = json.loads(meta_path.read_text())
    del meta["policy_kwargs"]
    meta_path.write_text(json.dumps(meta))
    pickled_where_older_pecli_kept_them(meta_path.with_suffix(".zip"))
    command = ["play", "-p", str(meta_path.with_suffix(".zip")), "-e", "greedy", "-n", "4"]
    refused = runner.invoke(app, command)
    assert refused.exit_code == 1 and "written before pecli described networks" in refused.output
    assert "--trust" in refused.output
    trusted = runner.invoke(app, ["--trust", *command])
    assert trusted.exit_code == 0, trusted.output


def test_edited_metadata_is_one_clear_line(zoo: Path, tmp_path: Path) -> None:
    copy = tmp_path / "zoo"
    shutil.copytree(zoo, copy)
    meta_path = copy / "run" / "pursuer" / "final.json"
    original = json.loads(meta_path.read_text())
    for change, message in (
        (
            {"frame_stack": 5},
            "does not describe its network: actor.mu.0.weight has shape [16, 22] in the weights but "
            "[16, 55] by the metadata",
        ),
        ({"frame_stack": "two"}, "damaged metadata (frame_stack must be a whole number from 1 to 1000, not 'two')"),
        ({"belief": "bimdn"}, "without its belief_kwargs"),
        ({"algo": "ppo"}, "unknown algorithm 'ppo'"),
        ({"policy_kwargs": {"net_arch": [64, 64]}}, "has shape [16, 22] in the weights but [64, 22] by the metadata"),
    ):
        meta_path.write_text(json.dumps({**original, **change}))
        for command in (
            ["play", "-p", str(meta_path.with_suffix(".zip")), "-e", "greedy", "-n", "2"],
            ["export", "onnx", str(meta_path.with_suffix(".zip")), "--out", str(tmp_path / "x.onnx")],
            ["zoo", "show", str(meta_path.with_suffix(".zip"))],
            [
                "tournament",
                str(meta_path.with_suffix(".zip")),
                "greedy",
                "--episodes",
                "2",
                "--seeds",
                "1",
                "--workers",
                "1",
                "--out",
                str(tmp_path / "t"),
            ],
        ):
            result = runner.invoke(app, command)
            assert result.exit_code == 1 and message in result.output, (change, command, result.output)
            assert "Traceback" not in result.output and "internal error" not in result.output


def test_a_payload_in_the_durable_state_is_refused(tmp_path: Path) -> None:
    import io

    import numpy as np

    tiny = [
        "--set",
        "buffer_size=400",
        "--set",
        "batch_size=16",
        "--set",
        "learning_starts=50",
        "--set",
        "net_arch=[16,16]",
        "--set",
        "n_envs=2",
        "--set",
        "checkpoint_every=2",
    ]
    start = ["train", "pursuer", "-c", "quick", "--steps", "300", "--name", "r", "--zoo", str(tmp_path), "-q", *tiny]
    assert runner.invoke(app, start).exit_code == 0
    marker = tmp_path / "ran"
    chunk = sorted((tmp_path / "r" / "pursuer" / "resume").glob("replay-*.npz"))[-1]
    with np.load(chunk) as data:
        arrays = {key: data[key] for key in data.files}
    arrays["actions"] = np.array([Payload(marker)] * len(arrays["actions"]), dtype=object)
    buffer = io.BytesIO()
    np.savez(buffer, **arrays)
    chunk.write_bytes(buffer.getvalue())
    result = runner.invoke(
        app, ["train", "pursuer", "--name", "r", "--zoo", str(tmp_path), "--resume", "-q", "--steps", "400"]
    )
    assert result.exit_code == 1 and "buffer files hold pickled objects" in result.output
    assert not marker.exists()


TINY = [
    "--set",
    "buffer_size=400",
    "--set",
    "batch_size=16",
    "--set",
    "learning_starts=50",
    "--set",
    "net_arch=[16,16]",
    "--set",
    "n_envs=2",
    "--set",
    "checkpoint_every=2",
]


@pytest.fixture
def stopped(tmp_path: Path) -> Path:
    """A tiny train run ``r`` in ``tmp_path`` with a durable state, as a stranger's zoo would hold it."""
    start = ["train", "pursuer", "-c", "quick", "--steps", "300", "--name", "r", "--zoo", str(tmp_path), "-q", *TINY]
    assert runner.invoke(app, start).exit_code == 0
    return tmp_path / "r"


def resume(run: Path, *extra: str):
    return runner.invoke(
        app,
        ["train", "pursuer", "--name", run.name, "--zoo", str(run.parent), "--resume", "-q", "--steps", "400", *extra],
    )


@pytest.mark.parametrize(
    "value, allowed",
    [
        ("off", None),
        ("n", None),
        ("none", None),
        ("maybe", None),
        ("0", False),
        ("no", False),
        ("FALSE", False),
        ("", False),
        ("1", True),
        ("Yes", True),
    ],
)
def test_pecli_trust_takes_exactly_yes_or_no(monkeypatch, value: str, allowed: bool | None) -> None:
    from pecli.errors import PecliError
    from pecli.trust import trusted

    monkeypatch.setenv("PECLI_TRUST", value)
    if allowed is None:
        with pytest.raises(PecliError, match="set it to 1, true or yes"):
            trusted()
    else:
        assert trusted() is allowed


def test_a_run_record_that_names_code_imports_nothing(stopped: Path, monkeypatch) -> None:
    marker = stopped.parent / "ran"
    (stopped.parent / "evil.py").write_text(
        f"from pathlib import Path\nPath({str(marker)!r}).touch()\nclass Evader: pass\n"
    )
    monkeypatch.syspath_prepend(str(stopped.parent))  # as `python -m pecli` puts the working folder on the path
    record = json.loads((stopped / "run.json").read_text())
    (stopped / "run.json").write_text(json.dumps({**record, "opponent": "evil:Evader"}))
    result = resume(stopped)
    assert result.exit_code == 1 and "imports no code a file names" in result.output
    assert not marker.exists()
    outside = stopped.parent.parent / f"{stopped.parent.name}-outside.zip"  # a file out of the zoo
    outside.write_bytes(b"PK")
    (stopped / "run.json").write_text(json.dumps({**record, "opponent": str(outside)}))
    result = resume(stopped)
    assert result.exit_code == 1 and "outside" in result.output and "--opponent" in result.output
    (stopped / "run.json").write_text(json.dumps({**record, "seed": "zero"}))
    result = resume(stopped)
    assert result.exit_code == 1 and "run.json: damaged" in result.output


def test_a_durable_state_naming_a_file_outside_its_folder_is_refused(stopped: Path) -> None:
    state = stopped / "pursuer" / "resume" / "state.json"
    record = json.loads(state.read_text())
    outside = stopped.parent / "secret.zip"
    outside.write_bytes((stopped / "pursuer" / "resume" / record["model"]).read_bytes())
    for name in ("../../../secret.zip", str(outside)):
        state.write_text(json.dumps({**record, "model": name}))
        result = resume(stopped)
        assert result.exit_code == 1 and "not a file of" in result.output, result.output
    link = stopped / "pursuer" / "resume" / "linked.zip"
    link.symlink_to(outside)
    state.write_text(json.dumps({**record, "model": link.name}))
    result = resume(stopped)
    assert result.exit_code == 1 and "names files that are gone" in result.output


def test_a_lock_file_linked_elsewhere_is_not_written_through(stopped: Path) -> None:
    victim = stopped.parent / "victim.txt"
    victim.write_text("keep me\n")
    lock = stopped / ".pecli.lock"
    lock.unlink(missing_ok=True)
    lock.symlink_to(victim)
    result = subprocess.run(
        [
            sys.executable,
            "-m",
            "pecli",
            "train",
            "pursuer",
            "--name",
            "r",
            "--zoo",
            str(stopped.parent),
            "--resume",
            "-q",
            "--steps",
            "400",
        ],
        capture_output=True,
        text=True,
    )
    assert result.returncode == 1 and "symbolic link" in result.stderr, result.stderr
    assert victim.read_text() == "keep me\n"


def test_a_selfplay_pool_entry_that_names_code_imports_nothing(quick: Scenario, tmp_path: Path) -> None:
    from pecli.errors import PolicyError
    from pecli.rl.selfplay import SelfPlay, SelfPlayJob

    scenario = with_overrides(
        quick,
        {
            "buffer_size": 400,
            "batch_size": 16,
            "learning_starts": 50,
            "net_arch": [16, 16],
            "n_envs": 2,
            "selfplay.rounds": 1,
            "selfplay.steps_per_round": 60,
        },
    )
    SelfPlay(SelfPlayJob(scenario, tmp_path, "sp", progress=False)).run()
    state_path = tmp_path / "sp" / "selfplay.json"
    state = json.loads(state_path.read_text())
    state["pools"]["evader"]["entries"][0]["spec"] = "os:system"
    state_path.write_text(json.dumps(state))
    play = SelfPlay(SelfPlayJob(scenario, tmp_path, "sp", resume=True, progress=False))
    with pytest.raises(PolicyError, match="imports no code"):
        play.players.player("evader", "os:system")
    (tmp_path.parent / f"{tmp_path.name}-elsewhere.zip").write_bytes(b"PK")
    with pytest.raises(PolicyError, match="outside"):
        play.players.player("evader", f"../../{tmp_path.name}-elsewhere.zip")


DEEP = "[" * 100_000 + "]" * 100_000


def test_deeply_nested_records_are_one_clear_line(stopped: Path, tmp_path: Path) -> None:
    """Every JSON record pecli reads back from a run: too deep to parse is 'damaged', never a RecursionError."""
    from pecli.errors import PecliError
    from pecli.rl.durable import DurableState
    from pecli.zoo import Run, read_metadata

    final = stopped / "pursuer" / "final.json"
    final.write_text(DEEP)
    with pytest.raises(PecliError, match="damaged metadata"):
        read_metadata(stopped / "pursuer" / "final.zip")
    (stopped / "run.json").write_text(DEEP)
    with pytest.raises(PecliError, match="damaged run record"):
        Run(stopped).job()
    (stopped / "pursuer" / "resume" / "state.json").write_text(DEEP)
    with pytest.raises(PecliError, match="damaged resume state"):
        DurableState(stopped / "pursuer" / "resume").read()
    (stopped / "config.yaml").write_text("a: " + "[" * 20_000 + "]" * 20_000 + "\n")
    with pytest.raises(PecliError, match="nested too deeply"):
        Run(stopped).scenario()
    result = runner.invoke(
        app,
        [
            "train",
            "pursuer",
            "-c",
            "quick",
            "--set",
            "gamma=" + "[" * 20_000 + "]" * 20_000,
            "--zoo",
            str(tmp_path / "z"),
        ],
    )
    assert result.exit_code == 1 and "nested too deeply" in result.output


def test_poisoned_tournament_records_are_not_believed(tmp_path: Path, quick: Scenario) -> None:
    """A pairing cache with impossible numbers is played again; results with a rating of NaN rank nothing."""
    from pecli.tournament import tournament_ratings

    out = tmp_path / "t"
    args = [
        "tournament",
        "--baselines",
        "-c",
        "quick",
        "-n",
        "20",
        "--seeds",
        "1",
        "-w",
        "1",
        "--out",
        str(out),
        "--json",
    ]
    first = json.loads(runner.invoke(app, args).stdout)
    for cache in (out / "pairings").glob("*.json"):
        cache.write_text(
            json.dumps(
                {
                    "pursuer": "x",
                    "evader": "y",
                    "episodes": 0,
                    "captures": 5,
                    "time_to_capture_mean": float("nan"),
                    "time_to_capture_std": 1e9,
                }
            )
        )
    again = runner.invoke(app, [*args, "--resume"])
    assert again.exit_code == 0, again.output
    assert json.loads(again.stdout)["pairings"] == first["pairings"]  # played again, the same games
    results = out / "results.json"
    data = json.loads(results.read_text())
    data["ratings"][0]["elo"] = float("nan")
    assert len(tournament_ratings(tmp_path)) == len(data["ratings"])
    results.write_text(json.dumps(data))
    assert tournament_ratings(tmp_path) == {}


@pytest.mark.parametrize(
    "edit, message",
    [
        ({"policy_kwargs": {"net_arch": [2147483648], "n_critics": 2}}, "not a list of at most"),
        ({"policy_kwargs": {"net_arch": [16, 16], "n_critics": 1_000_000}}, "n_critics"),
        ({"policy_kwargs": {"net_arch": [16] * 100_000, "n_critics": 2}}, "not a list of at most"),
        ({"policy_kwargs": {"net_arch": [4096, 4096], "n_critics": 2}}, "more than its"),
        ({"frame_stack": 10**9}, "frame_stack must be a whole number from 1 to 1000"),
        ({"history_length": 10**12}, "history_length must be"),
        ({"steps": 10**400}, r"steps must be .*, not 1000000000000000000000000000000000000\.\.\.\)$"),
        ({"cpu_seconds": float("nan")}, "cpu_seconds must be a number from 0 to"),
        ({"eval_capture_rate": float("inf")}, "eval_capture_rate must be a number from 0 to 1"),
        ({"run": 5}, "run must be a string, not 5"),
        ({"round": "x"}, "round must be a whole number"),
        ({"opponents": [1]}, "opponents must be a list of JSON objects"),
    ],
)
def test_metadata_cannot_make_pecli_build_what_its_weights_do_not_hold(
    zoo: Path, tmp_path: Path, quick: Scenario, edit: dict, message: str
) -> None:
    from pecli.errors import PolicyError

    copy = tmp_path / "zoo"
    shutil.copytree(zoo, copy)
    meta_path = copy / "run" / "pursuer" / "final.json"
    meta = json.loads(meta_path.read_text())
    meta_path.write_text(json.dumps({**meta, **edit}))
    with pytest.raises(PolicyError, match=message):
        resolve_policy(str(copy / "run" / "pursuer" / "final.zip"), "pursuer", quick)


@pytest.mark.parametrize(
    "weights, message",
    [
        ("nan", "actor.mu.0.weight holds NaN or infinite values"),
        ("list", "a list, not a table of named tensors"),
        ("text", "actor.mu.0.weight is not a named tensor"),
        ("complex", "actor.mu.0.weight is a tensor of complex64"),
        ("sparse", "actor.mu.0.weight is a sparse tensor"),
    ],
)
def test_weights_that_are_no_finite_tensors_are_one_clear_line(
    zoo: Path, tmp_path: Path, quick: Scenario, weights: str, message: str
) -> None:
    import io

    import torch as th

    from pecli.errors import PolicyError

    copy = tmp_path / "zoo"
    shutil.copytree(zoo, copy)
    checkpoint = copy / "run" / "pursuer" / "final.zip"
    with zipfile.ZipFile(checkpoint) as archive:
        state = th.load(io.BytesIO(archive.read("policy.pth")), weights_only=True)
    first = "actor.mu.0.weight"
    state = {
        "nan": {**state, first: th.full_like(state[first], float("nan"))},
        "list": list(state),
        "text": {**state, first: "weights"},
        "complex": {**state, first: state[first].to(th.complex64)},
        "sparse": {**state, first: state[first].to_sparse()},
    }[weights]
    buffer = io.BytesIO()
    th.save(state, buffer)
    rewrite_zip(checkpoint, {"policy.pth": buffer.getvalue()})
    with pytest.raises(PolicyError, match=f"damaged policy weights \\({message}\\)"):
        resolve_policy(str(checkpoint), "pursuer", quick)


def test_weights_that_unpack_beyond_the_limit_are_not_read(
    zoo: Path, tmp_path: Path, quick: Scenario, monkeypatch
) -> None:
    from pecli.errors import PolicyError
    from pecli.models import checkpoint

    monkeypatch.setattr(checkpoint, "MAX_WEIGHTS_BYTES", 1000)  # a zip bomb's member, at a test's size
    with pytest.raises(PolicyError, match="unpack to more than 1,000 bytes"):
        resolve_policy(str(zoo / "run" / "pursuer" / "final.zip"), "pursuer", quick)


def test_weights_that_unpack_far_past_their_compressed_size_are_not_read(
    zoo: Path, tmp_path: Path, quick: Scenario
) -> None:
    from pecli.errors import PolicyError

    copy = tmp_path / "zoo"
    shutil.copytree(zoo, copy)
    checkpoint = copy / "run" / "pursuer" / "final.zip"
    with zipfile.ZipFile(checkpoint) as archive:
        entries = {name: archive.read(name) for name in archive.namelist()}
    entries["policy.pth"] = bytes(64 << 20)  # 64 MiB of zeros: a few kilobytes compressed
    with zipfile.ZipFile(checkpoint, "w", zipfile.ZIP_DEFLATED) as archive:
        for name, data in entries.items():
            archive.writestr(name, data)
    assert checkpoint.stat().st_size < 1 << 20
    with pytest.raises(
        PolicyError, match="its policy.pth unpacks to 67,108,864 bytes from [0-9,]+: weights do not compress 8 times"
    ):
        resolve_policy(str(checkpoint), "pursuer", quick)


def test_weights_that_are_no_pickle_are_damaged_whatever_the_trust(
    zoo: Path, tmp_path: Path, quick: Scenario, monkeypatch
) -> None:
    from pecli.errors import PolicyError

    copy = tmp_path / "zoo"
    shutil.copytree(zoo, copy)
    checkpoint = copy / "run" / "pursuer" / "final.zip"
    rewrite_zip(checkpoint, {"policy.pth": b"garbage" * 100})
    for trust in ("0", "1"):
        monkeypatch.setenv("PECLI_TRUST", trust)
        with pytest.raises(PolicyError, match="damaged \\(not what torch.save writes\\)"):
            resolve_policy(str(checkpoint), "pursuer", quick)


def test_a_checkpoint_that_is_not_a_regular_file_is_not_opened(tmp_path: Path, quick: Scenario) -> None:
    import os

    from pecli.errors import PolicyError
    from pecli.rl.state import round_of

    fifo = tmp_path / "round-001.zip"
    os.mkfifo(fifo)  # opening it would wait for a writer forever
    with pytest.raises(PolicyError, match="not a regular file"):
        resolve_policy(str(fifo), "pursuer", quick)
    assert round_of(Path("round-012.zip")) == 12
    assert round_of(Path("round-\u00b2.zip")) is None  # a digit to str.isdigit, not to int()


def test_averaging_copies_no_more_than_a_checkpoint_unpacks_to(zoo: Path, tmp_path: Path, monkeypatch) -> None:
    from pecli.rl import averaging
    from pecli.zoo import ZooError

    source = zoo / "run" / "pursuer" / "final"
    for suffix in (".zip", ".json"):
        shutil.copy(source.with_suffix(suffix), tmp_path / f"newest{suffix}")
    with zipfile.ZipFile(source.with_suffix(".zip")) as archive:
        size = sum(item.file_size for item in archive.infolist())
    monkeypatch.setattr(averaging, "MAX_WEIGHTS_BYTES", size + 1000)
    averaging.average_checkpoints([source.with_suffix(".zip"), tmp_path / "newest.zip"], tmp_path / "mean.zip")
    with zipfile.ZipFile(tmp_path / "mean.zip") as archive:  # the newest's other entries, as they were
        assert sorted(archive.namelist()) == sorted(zipfile.ZipFile(tmp_path / "newest.zip").namelist())
    rewrite_zip(tmp_path / "newest.zip", {"notes.bin": bytes(2000)})  # a bomb's extra entry, at a test's size
    with pytest.raises(ZooError, match=f"newest.zip: unpacks to more than {size + 1000:,} bytes"):
        averaging.average_checkpoints([source.with_suffix(".zip"), tmp_path / "newest.zip"], tmp_path / "mean.zip")
    rewrite_zip(tmp_path / "newest.zip", {"notes.bin": b"a note of the run's, stored as it is"})
    data = (tmp_path / "newest.zip").read_bytes()
    (tmp_path / "newest.zip").write_bytes(data.replace(b"a note", b"A note"))  # its CRC no longer holds
    with pytest.raises(ZooError, match="newest.zip: damaged entry 'notes.bin'"):
        averaging.average_checkpoints([source.with_suffix(".zip"), tmp_path / "newest.zip"], tmp_path / "mean.zip")


@pytest.mark.parametrize(
    "old, new, message",
    [
        ("fov: 2pi/3", "fov: pi/0", "divides by zero"),
        ("fov: 2pi/3", "fov: " + "9" * 5000, "digits"),
        ("dt: 0.1", "dt: 1e300", "less than or equal to 10"),
        ("width: 8.0", "width: 1e308", "less than or equal to 1000000"),
    ],
)
def test_a_config_that_python_cannot_compute_is_one_line(tmp_path: Path, old: str, new: str, message: str) -> None:
    from pecli.errors import ConfigError
    from pecli.scenario import load_scenario

    text = (Path(__file__).parents[1] / "configs" / "quick.yaml").read_text()
    assert old in text
    path = tmp_path / "bad.yaml"
    path.write_text(text.replace(old, new, 1))
    with pytest.raises(ConfigError, match=message):
        load_scenario(path)
    result = runner.invoke(
        app, ["train", "pursuer", "-c", "quick", "--set", "selfplay.rounds=" + "9" * 5000, "--zoo", str(tmp_path / "z")]
    )
    assert result.exit_code == 1 and "too many digits" in result.output


def test_names_with_markup_print_as_text(tmp_path: Path) -> None:
    zoo = tmp_path / "z[/x]"
    result = runner.invoke(
        app, ["train", "pursuer", "-c", "quick", "--steps", "200", "--name", "r", "--zoo", str(zoo), "-q", *TINY]
    )
    assert result.exit_code == 0, result.output
    assert "z[/x]" in result.output


def test_a_strangers_escape_codes_reach_the_terminal_written_out(zoo: Path, tmp_path: Path) -> None:
    copy = tmp_path / "zoo"
    shutil.copytree(zoo, copy)
    sidecar = copy / "run" / "pursuer" / "final.json"
    meta = json.loads(sidecar.read_text())
    sidecar.write_text(json.dumps({**meta, "scenario": "\x1b[2J\x1b]0;title\x07[red]x"}))
    listed = runner.invoke(app, ["zoo", "list", str(copy)])
    assert listed.exit_code == 0 and "\x1b" not in listed.output and "\\x1b[2J" in listed.output, listed.output
    refused = runner.invoke(app, ["play", "-p", str(copy / "x\x1b]0;title\x07.zip"), "-e", "greedy"])
    assert refused.exit_code == 1 and "x\\x1b]0;title\\x07.zip" in refused.output, refused.output


def test_a_record_naming_a_file_that_is_not_there_imports_nothing(tmp_path: Path, quick: Scenario) -> None:
    """'this:x.zip' looks like a file; were it resolved, a missing file would be taken for module:Class."""
    from pecli.errors import PolicyError
    from pecli.policies.registry import recorded_policy

    for inside in (None, tmp_path):
        with pytest.raises(PolicyError, match="which is not there"):
            recorded_policy("this:x.zip", inside, "a record")
    nash = tmp_path / "nash.json"
    nash.write_text(
        json.dumps(
            {
                "kind": "nash",
                "scenario": "quick",
                "scenario_hash": quick.fingerprint(),
                "value": 0.5,
                "pursuer": [{"name": "m", "spec": "this:x.zip", "weight": 1.0}],
                "evader": [{"name": "e", "spec": "greedy", "weight": 1.0}],
            }
        )
    )
    with pytest.raises(PolicyError, match="which is not there"):
        resolve_policy(f"nash:{tmp_path}", "pursuer", quick)
    assert resolve_policy(f"nash:{tmp_path}", "evader", quick).names == ["e"]


def test_a_record_naming_a_mixture_follows_no_member_out_of_its_folder(tmp_path: Path) -> None:
    from pecli.errors import PolicyError
    from pecli.policies.registry import recorded_policy

    room, outside = tmp_path / "zoo", tmp_path / "elsewhere"
    for folder in (room / "run", outside / "run"):
        (folder / "pursuer").mkdir(parents=True)
        (folder / "pursuer" / "average.zip").write_bytes(b"")
    mixture = f"mix:greedy,{room / 'run'},{room / 'run' / 'pursuer' / 'average.zip'}"
    assert recorded_policy(mixture, room, "a record") == mixture
    for member in (outside / "run", outside / "run" / "pursuer" / "average.zip"):
        with pytest.raises(PolicyError, match="outside"):
            recorded_policy(f"mix:greedy,{member}", room, "a record")
    with pytest.raises(PolicyError, match="imports no code"):
        recorded_policy("mix:greedy,os:system", room, "a record")


def test_a_record_that_is_not_a_regular_file_is_not_read(tmp_path: Path) -> None:
    import os

    from pecli.errors import PecliError
    from pecli.io import read_json

    fifo = tmp_path / "results.json"
    os.mkfifo(fifo)  # reading it would block for ever
    with pytest.raises(PecliError, match="not a regular file"):
        read_json(fifo, "record")
    (tmp_path / "zero.json").symlink_to("/dev/zero")  # would never end
    with pytest.raises(PecliError, match="not a regular file"):
        read_json(tmp_path / "zero.json", "record")


def test_a_mixture_member_that_is_a_typo_is_an_unknown_name_and_code_needs_trust(quick) -> None:
    from pecli.errors import PolicyError
    from pecli.policies.registry import resolve_policy

    with pytest.raises(PolicyError, match="'interceptr', which is neither a built-in"):
        resolve_policy("mix:pure-pursuit,interceptr", "pursuer", quick)
    with pytest.raises(PolicyError, match="imports no code"):
        resolve_policy("mix:pure-pursuit,pecli.policies.heuristics:PurePursuit", "pursuer", quick)
