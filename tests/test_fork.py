"""``pecli zoo fork``: a stopped run copied whole, with scripted players joining its pools."""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

from pecli.records import Turn
from pecli.rl.pool import OpponentPool
from pecli.rl.state import SelfPlayState


def fork(run: str, *args: str):
    """``pecli zoo fork RUN ...`` in this process: ``returncode``, ``stdout``, ``stderr`` as a subprocess's."""
    from typer.testing import CliRunner

    from pecli.cli import app

    result = CliRunner().invoke(app, ["zoo", "fork", run, *args])
    return subprocess.CompletedProcess(args, result.exit_code, result.stdout, result.stderr)


def make_run(path: Path) -> dict:
    """A stopped run's files as far as a fork reads them: its state with both pools, a checkpoint, a link."""
    pools = {role: OpponentPool(role) for role in ("pursuer", "evader")}
    pools["evader"].add("greedy", "greedy", generation=0)
    pools["evader"].add("pursuer-r1", str(path / "pursuer" / "round-1.zip"), generation=1)
    pools["pursuer"].add("evader-r1", str(path / "evader" / "round-1.zip"), generation=1)
    turn = Turn(
        round=1,
        role="pursuer",
        steps=40_000,
        episodes=90,
        captures=45,
        cpu_seconds=1800.0,
        checkpoint="pursuer/round-1.zip",
        opponents=2,
    )
    state = SelfPlayState(seed=0, curriculum_steps=300_000, pools=pools, turns=[turn]).to_dict()
    state["turns"] = [turn.model_dump()]
    (path / "pursuer").mkdir(parents=True)
    (path / "pursuer" / "round-1.zip").write_bytes(b"weights")
    (path / "selfplay.json").write_text(json.dumps(state))
    (path / "latest").symlink_to("pursuer/round-1.zip")
    return state


def test_fork_copies_a_run_and_adds_scripted_players_to_its_pools(tmp_path: Path) -> None:
    run = tmp_path / "zoo" / "none-league-s0"
    state = make_run(run)
    result = fork(str(run), "--to", str(tmp_path / "arm"), "--add", "corner-sitter", "--add", "interceptor")
    assert result.returncode == 0, result.stderr
    copy = tmp_path / "arm" / run.name
    assert "0.50 CPU-h" in result.stdout and "corner-sitter, interceptor" in result.stdout
    assert (copy / "pursuer" / "round-1.zip").read_bytes() == b"weights" and (copy / "latest").is_symlink()
    forked = json.loads((copy / "selfplay.json").read_text())
    assert forked["turns"] == state["turns"]
    names = {role: [e["name"] for e in pool["entries"]] for role, pool in forked["pools"].items()}
    assert names == {"pursuer": ["evader-r1", "interceptor"], "evader": ["greedy", "pursuer-r1", "corner-sitter"]}
    added = [
        e for pool in forked["pools"].values() for e in pool["entries"] if e["name"] in ("corner-sitter", "interceptor")
    ]
    assert [(e["generation"], e["episodes"]) for e in added] == [(0, 0), (0, 0)]  # scripted (generation 0): in for good
    assert json.loads((run / "selfplay.json").read_text()) == state  # the original is untouched
    assert not list((tmp_path / "arm").glob(".*partial"))


def test_fork_refuses_with_one_line_and_leaves_nothing(tmp_path: Path) -> None:
    run = tmp_path / "zoo" / "none-league-s0"
    make_run(run)
    arm = tmp_path / "arm"
    for args, says in (
        (["--add", "nobody"], "not a scripted player"),
        (["--add", "greedy"], "already holds 'greedy'"),
        ([], None),
    ):
        result = fork(str(run), "--to", str(arm), *args)
        if says is None:
            assert result.returncode == 0, result.stderr
            continue
        assert result.returncode != 0 and says in result.stderr and result.stderr.strip().count("\n") == 0
        assert not (arm / run.name).exists()
    again = fork(str(run), "--to", str(arm))
    assert again.returncode != 0 and "exists" in again.stderr
    missing = fork(str(tmp_path / "zoo"), "--to", str(arm))
    assert missing.returncode != 0 and "not a self-play run" in missing.stderr
