"""`pecli zoo` on an empty, a normal and a damaged zoo; `best` after a tournament; `rm`."""

from __future__ import annotations

import shutil
import sys
import zipfile
from pathlib import Path
from unittest import mock

import pytest
from typer.testing import CliRunner

from pecli.cli import app

runner = CliRunner()
TINY = [
    "--set",
    "buffer_size=2000",
    "--set",
    "batch_size=32",
    "--set",
    "learning_starts=100",
    "--set",
    "net_arch=[16, 16]",
    "--set",
    "checkpoint_every=4",
    "--set",
    "n_envs=4",
    "--steps",
    "800",
    "-q",
]


def invoke(*args: str):
    with mock.patch.object(sys, "argv", ["pecli", *args]):
        return runner.invoke(app, list(args))


@pytest.fixture(scope="module")
def zoo(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("zoo")
    for role, name in (("pursuer", "p"), ("evader", "e")):
        result = invoke("train", role, "-c", "quick", "--zoo", str(root), "--name", name, *TINY)
        assert result.exit_code == 0, result.output
    return root


def test_a_folder_of_checkpoints_plays_their_runs_scenario(zoo: Path) -> None:
    from pecli.cli.common import scenario_for

    assert scenario_for([str(zoo / "p" / "pursuer")], None, folders=True).name == "quick"  # no config.yaml below
    assert scenario_for([str(zoo / "p" / "pursuer")], None).name == "paper"  # folders are not looked into


def test_empty_and_missing_zoos(tmp_path: Path) -> None:
    result = invoke("zoo", "list", str(tmp_path))
    assert result.exit_code == 0 and "no runs yet" in result.output
    result = invoke("zoo", "list", str(tmp_path / "nope"))
    assert result.exit_code == 1 and "no zoo at" in result.output


def test_list_and_show(zoo: Path) -> None:
    result = invoke("zoo", "list", str(zoo))
    assert result.exit_code == 0 and "final" in result.output and "evader" in result.output
    shown = invoke("zoo", "show", str(zoo / "p" / "pursuer" / "final.zip"))
    assert shown.exit_code == 0 and '"role": "pursuer"' in shown.output and '"steps": 800' in shown.output


def test_a_damaged_zoo_is_listed_without_a_traceback(zoo: Path, tmp_path: Path, monkeypatch) -> None:
    from pecli.cli.common import console

    monkeypatch.setattr(console, "width", 200)  # no wrapping inside the table's cells
    damaged = tmp_path / "zoo"
    shutil.copytree(zoo / "p", damaged / "p")
    (damaged / "p" / "pursuer" / "final.json").unlink()  # a checkpoint without metadata
    last = damaged / "p" / "pursuer" / "last.zip"
    last.write_bytes(last.read_bytes()[:300])  # a truncated zip
    result = invoke("zoo", "list", str(damaged))
    assert result.exit_code == 0, result.output
    assert "no metadata" in result.output and "damaged zip" in result.output
    assert "Traceback" not in result.output


def test_best_needs_a_tournament_then_names_the_top_checkpoint(zoo: Path) -> None:
    result = invoke("zoo", "best", "pursuer", str(zoo))
    assert result.exit_code == 1 and "run `pecli tournament" in result.output
    played = invoke("tournament", str(zoo), "--baselines", "-c", "quick", "-n", "10", "--seeds", "1", "-w", "1")
    assert played.exit_code == 0, played.output
    assert (zoo / "tournament" / "results.json").is_file()  # the default --out of a zoo
    best = invoke("zoo", "best", "pursuer", str(zoo))
    assert best.exit_code == 0 and best.output.strip().endswith(".zip") and "/p/pursuer/" in best.output
    listed = invoke("zoo", "list", str(zoo))
    assert "±" in listed.output  # ratings show up in the list
    assert invoke("zoo", "best", "referee", str(zoo)).exit_code == 1


def test_rm_asks_and_deletes(zoo: Path, tmp_path: Path) -> None:
    copy = tmp_path / "zoo"
    shutil.copytree(zoo / "e", copy / "e")
    checkpoint = copy / "e" / "evader" / "final.zip"
    refused = runner.invoke(app, ["zoo", "rm", str(checkpoint)], input="n\n")
    assert refused.exit_code == 1 and checkpoint.exists()
    deleted = runner.invoke(app, ["zoo", "rm", str(checkpoint)], input="y\n")
    assert deleted.exit_code == 0 and not checkpoint.exists() and not checkpoint.with_suffix(".json").exists()
    assert invoke("zoo", "rm", str(copy / "e"), "--yes").exit_code == 0 and not (copy / "e").exists()
    assert invoke("zoo", "rm", str(tmp_path)).exit_code == 1  # not a run folder
    project = tmp_path / "project"  # a folder of the user's that happens to hold a config.yaml
    (project / "src").mkdir(parents=True)
    (project / "config.yaml").write_text("lr: 0.1\n")
    (project / "src" / "main.py").write_text("print(1)\n")
    photos = tmp_path / "photos.zip"  # a zip of the user's, with a JSON of the same name
    with zipfile.ZipFile(photos, "w") as archive:
        archive.writestr("a.jpg", b"...")
    photos.with_suffix(".json").write_text('{"album": 1}')
    for target in (project, photos):
        refused = invoke("zoo", "rm", str(target), "--yes")
        assert refused.exit_code == 1 and "refusing to delete it" in refused.output, refused.output
    assert (project / "src" / "main.py").is_file() and photos.is_file() and photos.with_suffix(".json").is_file()
    shutil.copytree(zoo / "e", copy / "e2")
    broken = copy / "e2" / "evader" / "final.zip"  # a damaged checkpoint of a run, its metadata damaged too
    broken.write_bytes(b"PK")
    broken.with_suffix(".json").write_text("{}")
    assert invoke("zoo", "rm", str(broken), "--yes").exit_code == 0
    assert not broken.exists() and not broken.with_suffix(".json").exists()


def test_play_takes_the_scenario_a_checkpoint_was_trained_on(zoo: Path) -> None:
    checkpoint = str(zoo / "p" / "pursuer" / "final.zip")
    result = invoke("play", "-p", checkpoint, "-n", "4")  # no --config: the run's own (quick)
    assert result.exit_code == 0, result.output
    assert "on quick" in result.stdout
    refused = invoke("play", "-p", checkpoint, "-c", "paper", "-n", "4")
    assert refused.exit_code == 1 and "pass the config it was trained with" in refused.output


def test_a_resumed_run_refuses_another_scenario(zoo: Path) -> None:
    result = invoke("train", "pursuer", "--zoo", str(zoo), "--name", "p", "--resume", "-c", "paper")
    assert result.exit_code == 1 and "plays scenario 'quick'" in result.output and "drop --config" in result.output
    result = invoke("selfplay", "--zoo", str(zoo), "--name", "p", "--resume", "-c", "paper")
    assert result.exit_code == 1 and "plays scenario 'quick'" in result.output
    same = invoke("train", "pursuer", "--zoo", str(zoo), "--name", "p", "--resume", "-c", "quick", "--seed", "5")
    assert same.exit_code == 1 and "keeps it" in same.output and "plays scenario" not in same.output  # past the check


def test_a_damaged_run_config_leaves_the_scenario_to_config(zoo: Path, tmp_path: Path) -> None:
    run = tmp_path / "damaged"
    shutil.copytree(zoo / "p", run)
    (run / "config.yaml").write_text("arena: [not, a, mapping")
    result = invoke("play", "-p", str(run / "pursuer" / "final.zip"), "-c", "quick", "-n", "2", "--json")
    assert result.exit_code == 0, result.output
    result = invoke("play", "-p", str(run / "pursuer" / "final.zip"), "-n", "2")  # falls back to paper, then refuses
    assert result.exit_code == 1 and "pass the config it was trained with" in result.output


def test_best_passes_over_a_damaged_checkpoint(zoo: Path, tmp_path: Path) -> None:
    """The top-rated checkpoint is a zero-byte file (a full disk, a cut copy): the next good one is named."""
    import json

    run = tmp_path / "zoo" / "p"
    shutil.copytree(zoo / "p", run)
    good = run / "pursuer" / "final.zip"
    for name, content in (("empty", b""), ("cut", good.read_bytes()[: good.stat().st_size // 2])):
        (run / "pursuer" / f"{name}.zip").write_bytes(content)
        shutil.copy(good.with_suffix(".json"), run / "pursuer" / f"{name}.json")
    ratings = [
        {"name": n, "spec": str(run / "pursuer" / f"{n}.zip"), "role": "pursuer", "elo": elo, "stderr": 1.0}
        for n, elo in (("empty", 1500.0), ("cut", 1400.0), ("final", 1000.0))
    ]
    (tmp_path / "zoo" / "tournament").mkdir()
    results = {"episodes_per_seed": 4, "seeds": [0], "pairings": [], "ratings": ratings}
    (tmp_path / "zoo" / "tournament" / "results.json").write_text(json.dumps(results))
    result = invoke("zoo", "best", "pursuer", str(tmp_path / "zoo"))
    assert result.exit_code == 0, result.output
    assert result.stdout.strip() == str(good)
    assert "empty.zip: empty file" in result.output and "cut.zip: not a pecli checkpoint" in result.output
    good.write_bytes(b"")
    result = invoke("zoo", "best", "pursuer", str(tmp_path / "zoo"))
    assert result.exit_code == 1 and "every rated pursuer checkpoint" in result.output


def test_show_refuses_a_zip_that_is_not_a_checkpoint(zoo: Path, tmp_path: Path) -> None:
    import zipfile

    other = tmp_path / "photos.zip"
    with zipfile.ZipFile(other, "w") as archive:
        archive.writestr("holiday.jpg", b"\xff\xd8")
    shutil.copy(zoo / "p" / "pursuer" / "final.json", tmp_path / "photos.json")  # metadata beside it, by mistake
    result = invoke("zoo", "show", str(other))
    assert result.exit_code == 1 and "not a pecli checkpoint (no 'data' in the zip" in result.output
    assert len(result.output.strip().splitlines()) == 1
    assert invoke("zoo", "show", str(zoo / "p" / "pursuer" / "final.zip")).exit_code == 0


def test_show_refuses_damaged_weights_even_where_the_network_cannot_be_checked(zoo: Path, tmp_path: Path) -> None:
    import io
    import json

    import torch

    source = zoo / "p" / "pursuer" / "final"
    meta = json.loads(source.with_suffix(".json").read_text())
    (tmp_path / "final.json").write_text(json.dumps({**meta, "scenario": "a-lab-elsewhere"}))  # no scenario at hand
    with zipfile.ZipFile(source.with_suffix(".zip")) as archive, zipfile.ZipFile(tmp_path / "final.zip", "w") as out:
        for info in archive.infolist():
            out.writestr(info, archive.read(info))
    result = invoke("zoo", "show", str(tmp_path / "final.zip"))
    assert result.exit_code == 0 and "('a-lab-elsewhere') is not at hand" in result.output
    with zipfile.ZipFile(source.with_suffix(".zip")) as archive, zipfile.ZipFile(tmp_path / "final.zip", "w") as out:
        for info in archive.infolist():
            data = archive.read(info)
            if info.filename == "policy.pth":
                weights = torch.load(io.BytesIO(data), weights_only=True)
                next(iter(weights.values())).fill_(float("nan"))
                buffer = io.BytesIO()
                torch.save(weights, buffer)
                data = buffer.getvalue()
            out.writestr(info, data)
    result = invoke("zoo", "show", str(tmp_path / "final.zip"))
    assert result.exit_code == 1 and "damaged policy weights" in result.output
    assert len(result.output.strip().splitlines()) == 1


def test_average_writes_the_mean_of_a_runs_checkpoints(zoo: Path, tmp_path: Path, quick) -> None:
    from pecli.game import Game
    from pecli.models.checkpoint import read_weights
    from pecli.policies import resolve_policy
    from pecli.zoo import read_metadata

    trained = zoo / "p" / "pursuer"
    rounds = tmp_path / "run" / "pursuer"  # two checkpoints of one learner, named like a self-play run's rounds
    rounds.mkdir(parents=True)
    for name, source in (("round-999", sorted(trained.glob("ep*.zip"))[0].stem), ("round-1000", "final")):
        for suffix in (".zip", ".json"):
            shutil.copy(trained / f"{source}{suffix}", rounds / f"{name}{suffix}")
    (rounds / "round-x.zip").write_bytes(b"")  # a file of the user's, not a round: left out, no error
    result = invoke("zoo", "average", str(rounds), "--last", "2")
    assert result.exit_code == 0, result.output
    out = rounds / "average-999-1000.zip"  # rounds in their order, not the names' (round-1000 < round-999)
    a, b, mean = (
        read_weights(path)[0]["policy"] for path in (rounds / "round-999.zip", rounds / "round-1000.zip", out)
    )
    key = next(k for k in mean if k.startswith("actor.") and mean[k].is_floating_point())
    assert not a[key].equal(b[key]) and mean[key].allclose((a[key] + b[key]) / 2)
    meta = read_metadata(out)
    assert meta.averaged == [str(rounds / "round-999.zip"), str(rounds / "round-1000.zip")] and meta.role == "pursuer"
    policy = resolve_policy(str(out), "pursuer", quick, seed=0)  # it plays like any checkpoint
    assert policy.act(Game(quick, n=2, seed=0).reset()["pursuer"]).shape == (2, 2)


def test_average_refuses_checkpoints_of_different_networks(zoo: Path, tmp_path: Path) -> None:
    p, e = zoo / "p" / "pursuer" / "final.zip", zoo / "e" / "evader" / "final.zip"
    result = invoke("zoo", "average", str(p), str(e), "--out", str(tmp_path / "mix.zip"))
    assert result.exit_code == 1 and "its role differs" in result.output and result.output.strip().count("\n") == 0
    result = invoke("zoo", "average", str(p), str(p))
    assert result.exit_code == 1 and "give --out" in result.output
    result = invoke("zoo", "average", str(tmp_path / "nowhere.zip"))  # a typo is named before --out is asked for
    assert result.exit_code == 1 and "no checkpoint at" in result.output and "nowhere.zip" in result.output
    result = invoke("zoo", "average", str(zoo / "p" / "pursuer"), "--last", "50")
    assert result.exit_code == 1 and "fewer than --last 50" in result.output
    assert not (tmp_path / "mix.zip").exists()


def test_list_names_a_leagues_exploiters_by_their_folder_and_fits_120_columns(zoo: Path, tmp_path: Path) -> None:
    from pecli.zoo import metadata_path

    league = tmp_path / "league-with-a-rather-long-run-name-seed-0"
    shutil.copytree(zoo / "p", league)
    (league / "exploiter-pursuer").mkdir()
    for folder in ("pursuer", "exploiter-pursuer"):
        for suffix in (".zip", metadata_path(Path("x.zip")).suffix):
            shutil.copy(league / "pursuer" / f"final{suffix}", league / folder / f"round-001{suffix}")
    result = invoke("zoo", "list", str(tmp_path))
    assert result.exit_code == 0, result.output
    rows = [" ".join(line.replace("│", " ").split()) for line in result.output.splitlines() if "round-001" in line]
    assert len(rows) == 2 and rows[0] != rows[1]
    assert any("exploiter-pursuer round-001" in row for row in rows)
    assert max(len(line) for line in result.output.splitlines()) <= 120
    listed = invoke("config", "list")
    assert listed.exit_code == 0 and max(len(line) for line in listed.output.splitlines()) <= 120
