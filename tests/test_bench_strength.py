"""``pecli zoo fork``: a stopped run copied whole, with scripted players joining its pools; and the strength
report's verdicts (``benchmarks/bench_strength.py``)."""

from __future__ import annotations

import importlib.util
import json
import subprocess
from pathlib import Path
from types import ModuleType

import pytest

from pecli.rl.pool import OpponentPool

SCRIPT = Path(__file__).resolve().parents[1] / "benchmarks" / "bench_strength.py"


def load_script() -> ModuleType:
    spec = importlib.util.spec_from_file_location("bench_strength", SCRIPT)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


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
    state = {"turns": [{"round": 1, "cpu_seconds": 1800.0}], "pools": {r: p.to_dict() for r, p in pools.items()}}
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
    added = [e for pool in forked["pools"].values() for e in pool["entries"]
             if e["name"] in ("corner-sitter", "interceptor")]
    assert [(e["generation"], e["episodes"]) for e in added] == [(0, 0), (0, 0)]  # scripted (generation 0): in for good
    assert json.loads((run / "selfplay.json").read_text()) == state  # the original is untouched
    assert not list((tmp_path / "arm").glob(".*partial"))


def test_fork_refuses_with_one_line_and_leaves_nothing(tmp_path: Path) -> None:
    run = tmp_path / "zoo" / "none-league-s0"
    make_run(run)
    arm = tmp_path / "arm"
    for args, says in ((["--add", "nobody"], "not a scripted player"),
                       (["--add", "greedy"], "already holds 'greedy'"),
                       ([], None)):
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


def test_schedules_are_compared_over_the_evaders_all_their_pursuers_met(capsys: pytest.CaptureFixture[str]) -> None:
    bench = load_script()
    runs = ["none-league-s0", "none-league-s1", "none-alternating-s0", "none-alternating-s1", "none-simultaneous-s0",
            "bimdn-league-s0", "bimdn-alternating-s0"]
    rate = {"none-league-s0": 90, "none-league-s1": 88, "none-alternating-s0": 60, "none-alternating-s1": 62,
            "none-simultaneous-s0": 70, "bimdn-league-s0": 95, "bimdn-alternating-s0": 50}  # vs other runs' evaders
    faced = {name: {"greedy": (90, 100), **{o: (rate[name], 100) for o in runs if o != name}} for name in runs}
    common, league, alternating, p = bench.contrast(faced, runs[:2], runs[2:4])
    assert common == {"greedy", *runs[4:]}  # not the evaders of the runs compared, which one of them met
    assert (league, alternating) == (714 / 800, 546 / 800) and p < 1e-6
    groups: dict[tuple[str, str], list[str]] = {}
    for name in runs:
        belief, schedule, _ = name.split("-")
        groups.setdefault((schedule, belief), []).append(name)
    bench.print_schedules(faced, groups, "at 0.5 CPU-h")
    lines = capsys.readouterr().out.splitlines()
    pairs = [line for line in lines if line.startswith("- ")]
    assert [line.split(" over ")[0] for line in pairs] == [  # each pair once, within one belief
        "- bimdn: alternating 0.567 vs league 0.942", "- none: alternating 0.682 vs league 0.892",
        "- none: alternating 0.668 vs simultaneous 0.740", "- none: league 0.892 vs simultaneous 0.740"]
    assert ("over the 4 evaders all of them met (bimdn-alternating-s0, bimdn-league-s0, greedy, none-simultaneous-s0): "
            f"z-test p = {p:.2g}") in pairs[1]
    per_run = lines[lines.index(pairs[1]) + 1]
    assert per_run.startswith("  per run: alternating 0.675, 0.690; league 0.900, 0.885; Welch")
    assert lines[lines.index(pairs[3]) + 1].endswith("simultaneous 0.740 (a test needs 2 runs of each)")
    with pytest.raises(ValueError, match="no evader"):
        bench.contrast({"a": {"x": (1, 2)}, "b": {"y": (1, 2)}}, ["a"], ["b"])


def test_beliefs_are_compared_over_every_evader_stratified_by_evader(capsys: pytest.CaptureFixture[str]) -> None:
    bench = load_script()
    runs = ["bimdn-league-s0", "bimdn-league-s1", "none-league-s0", "none-league-s1"]
    hard = {"bimdn-league-s0", "bimdn-league-s1"}  # the bimdn runs' evaders escape more, whoever chases them

    def faced(bonus: int) -> dict[str, dict[str, tuple[int, int]]]:
        gain = {name: bonus if name.startswith("bimdn") else 0 for name in runs}
        return {name: {"greedy": (93 + 2 * name.endswith("s1") + gain[name], 100),  # seeds differ, kinds alike
                       **{o: ((60 if o in hard else 90) + gain[name], 100) for o in runs if o != name}}
                for name in runs}

    # equal against each evader; pooled, bimdn looks better only because it meets its own kind's evaders less
    every, rate_b, rate_n, p, excess, p_stratified = bench.over_every_evader(faced(0), runs[:2], runs[2:])
    assert every == {"greedy", *runs}
    assert (rate_b, rate_n) == (668 / 800, 608 / 800) and p < 0.05
    assert excess == pytest.approx(0.0, abs=1e-9) and p_stratified == pytest.approx(1.0)
    every, rate_b, rate_n, p, excess, p_stratified = bench.over_every_evader(faced(4), runs[:2], runs[2:])
    assert excess > 0 and p_stratified < 0.05
    hours = {"bimdn": 4.02, "none": 4.01}
    missed = bench.print_beliefs(faced(0), "league", runs[:2], runs[2:], hours)  # pooled alone would say met
    first = capsys.readouterr().out.splitlines()[1]
    assert "z-test p = " in first and "(NOT met" in first and missed is not None
    assert missed.startswith("league: bimdn pursuers capture more than none over every evader")
    assert bench.print_beliefs(faced(4), "league", runs[:2], runs[2:], hours) is None
    lines = capsys.readouterr().out.splitlines()
    assert "(met: bimdn must capture more" in lines[1] and lines[2].startswith("  per run (the training seed")
    assert lines[3].startswith("  over the 1 evaders every one of them met (greedy): bimdn 0.980 vs none 0.940")
    with pytest.raises(ValueError, match="no evader"):
        bench.over_every_evader({"a": {"x": (1, 2)}, "b": {"y": (1, 2)}}, ["a"], ["b"])
