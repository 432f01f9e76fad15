"""Self-play runs compared at an equal budget (``pecli.experiment.compare``): picking each run's players, the tests
between groups of runs, and ``pecli experiment compare`` on a tiny run and its fork."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest
from typer.testing import CliRunner

from pecli.cli import app
from pecli.errors import PecliError
from pecli.experiment.compare import contrast, main_players, over_every_evader, run_rates, welch_p

RUNS = ["none-league-s0", "none-league-s1", "none-alternating-s0", "none-alternating-s1", "none-simultaneous-s0"]


def turn(r: int, role: str, checkpoint: str, cpu_seconds: float, **more: object) -> dict:
    return {
        "round": r,
        "role": role,
        "steps": 100 * r,
        "episodes": 10,
        "captures": 5,
        "cpu_seconds": cpu_seconds,
        "checkpoint": checkpoint,
        "opponents": 3,
        **more,
    }


def fake_run(zoo: Path, name: str, cpu_per_round: float, rounds: int) -> Path:
    """A self-play run's record and checkpoint files as far as picking players reads them."""
    run = zoo / name
    turns = []
    for r in range(1, rounds + 1):
        for role in ("pursuer", "evader"):
            (run / role).mkdir(parents=True, exist_ok=True)
            (run / role / f"round-{r:03d}.zip").write_bytes(b"w")
            turns.append(turn(r, role, f"{role}/round-{r:03d}.zip", cpu_per_round / 2))
    turns.append(turn(1, "evader", "exploiter-evader/round-001.zip", 0.0, learner="exploiter"))
    pools = {role: {"role": role, "entries": []} for role in ("pursuer", "evader")}
    (run / "selfplay.json").write_text(json.dumps({"seed": 0, "curriculum_steps": 0, "pools": pools, "turns": turns}))
    return run


def test_each_run_is_taken_at_an_equal_budget(tmp_path: Path) -> None:
    fake_run(tmp_path, "fast", 1800.0, 4)  # half a CPU-hour a round
    fake_run(tmp_path, "slow", 3600.0, 2)
    left: list[str] = []
    newest = main_players(tmp_path, report=left.append)
    assert (newest["fast"].round, newest["slow"].round, left) == (4, 2, [])
    assert newest["fast"].pursuer == tmp_path / "fast" / "pursuer" / "round-004.zip"
    at_one_hour = main_players(tmp_path, cpu_hours=1.0)
    assert (at_one_hour["fast"].round, at_one_hour["slow"].round) == (2, 1)
    assert at_one_hour["fast"].cpu_hours == pytest.approx(1.0)
    at_three = main_players(tmp_path, at_round=3, report=left.append)
    assert list(at_three) == ["fast"] and left == ["slow: left out, round 2 of 3 so far"]
    assert list(main_players(tmp_path, pattern=re.compile("s.*"))) == ["slow"]
    with pytest.raises(PecliError, match="has the rounds asked for"):
        main_players(tmp_path, cpu_hours=100.0)
    record = json.loads((tmp_path / "slow" / "selfplay.json").read_text())
    record["turns"][0]["captures"] = 11  # more captures than games: a damaged record, refused in one line
    (tmp_path / "slow" / "selfplay.json").write_text(json.dumps(record))
    with pytest.raises(PecliError, match=r"slow/selfplay.json: damaged self-play record \(turns.0: Value error"):
        main_players(tmp_path)


def test_groups_are_compared_over_the_evaders_all_their_pursuers_met() -> None:
    rate = {
        "none-league-s0": 90,
        "none-league-s1": 88,
        "none-alternating-s0": 60,
        "none-alternating-s1": 62,
        "none-simultaneous-s0": 70,
    }  # against other runs' evaders
    faced = {name: {"greedy": (90, 100), **{o: (rate[name], 100) for o in RUNS if o != name}} for name in RUNS}
    common, league, alternating, p = contrast(faced, RUNS[:2], RUNS[2:4])
    assert common == {"greedy", "none-simultaneous-s0"}  # not the evaders of the runs compared: one of them met each
    assert (league, alternating) == (358 / 400, 302 / 400) and p < 1e-3
    assert run_rates(faced, RUNS[:2], common) == [0.9, 0.89]
    assert welch_p(run_rates(faced, RUNS[:2]), run_rates(faced, RUNS[2:4])) < 0.05
    assert welch_p([0.9], [0.5, 0.6]) is None  # a test needs 2 runs a side
    with pytest.raises(ValueError, match="no evader"):
        contrast({"a": {"x": (1, 2)}, "b": {"y": (1, 2)}}, ["a"], ["b"])


def test_kinds_are_compared_over_every_evader_stratified_by_evader() -> None:
    runs = ["bimdn-league-s0", "bimdn-league-s1", "none-league-s0", "none-league-s1"]
    hard = {"bimdn-league-s0", "bimdn-league-s1"}  # the bimdn runs' evaders escape more, whoever chases them

    def faced(bonus: int) -> dict[str, dict[str, tuple[int, int]]]:
        gain = {name: bonus if name.startswith("bimdn") else 0 for name in runs}
        return {
            name: {
                "greedy": (93 + 2 * name.endswith("s1") + gain[name], 100),  # seeds differ, kinds alike
                **{o: ((60 if o in hard else 90) + gain[name], 100) for o in runs if o != name},
            }
            for name in runs
        }

    # equal against each evader; pooled, bimdn looks better only because it meets its own kind's evaders less
    every, rate_b, rate_n, p, excess, p_stratified = over_every_evader(faced(0), runs[:2], runs[2:])
    assert every == {"greedy", *runs}
    assert (rate_b, rate_n) == (668 / 800, 608 / 800) and p < 0.05
    assert excess == pytest.approx(0.0, abs=1e-9) and p_stratified == pytest.approx(1.0)
    every, rate_b, rate_n, p, excess, p_stratified = over_every_evader(faced(4), runs[:2], runs[2:])
    assert excess > 0 and p_stratified < 0.05
    with pytest.raises(ValueError, match="no evader"):
        over_every_evader({"a": {"x": (1, 2)}, "b": {"y": (1, 2)}}, ["a"], ["b"])


def test_a_run_misses_each_target_it_is_below_in_one_line() -> None:
    from pecli.experiment.compare import ADVERSARIES, HEURISTIC_EVADERS, ArmRow, Comparison, Targets

    scripted = dict.fromkeys((*HEURISTIC_EVADERS, *ADVERSARIES), 0.95) | {"rash": 0.89, "hider": 0.85}
    row = ArmRow(
        "a", "none-league-s0", 12, 1.0, scripted, cross_play=0.79, held_by_pure_pursuit=0.26, evader_vs_others=None
    )
    missed = Comparison(["a"], ["none-league-s0"], [], 500, rows=[row]).missed()
    assert missed == [
        "none-league-s0 vs rash: 0.890 < 0.9",
        "none-league-s0 cross-play: 0.790 < 0.8",
        "none-league-s0's evader lets pure pursuit catch 0.260 > 0.25",
    ]  # hider at 0.85 meets its 0.85
    lenient = Targets(heuristics=0.8, cross_play=0.7, pure_pursuit_held_to=0.3)
    assert Comparison(["a"], ["none-league-s0"], [], 500, rows=[row]).missed(lenient) == []
    two_arms = Comparison(["a", "b"], ["none-league-s0"], [], 500, rows=[row]).missed()
    assert two_arms[0].startswith("a/none-league-s0 vs rash")


def test_runs_group_by_schedule_or_opponent_rule_and_belief() -> None:
    from pecli.experiment.compare import recipe
    from pecli.rl.train import with_overrides
    from pecli.scenario import load_scenario

    league = load_scenario("league")
    assert recipe(league) == ("league", league.training.belief)
    plain = with_overrides(league, {"selfplay.opponents": "pfsp", "selfplay.schedule": "simultaneous", "belief": "ukf"})
    assert recipe(plain) == ("simultaneous", "ukf")


def test_compare_refuses_with_one_line(tmp_path: Path) -> None:
    runner = CliRunner()
    fake_run(tmp_path / "zoo", "sp", 1.0, 1)
    zoo = f"a={tmp_path / 'zoo'}"
    for arms, says in (
        (["a"], "LABEL=ZOO"),
        ([zoo, zoo], "labels of their own"),
        ([f"a={tmp_path / 'none'}"], "is not a folder"),
        ([f"a={tmp_path / 'zoo'}"], None),
    ):
        args = [part for arm in arms for part in ("--arms", arm)]
        result = runner.invoke(app, ["experiment", "compare", *args, "--round", "5", "-c", "quick"])
        assert result.exit_code == 1 and "Traceback" not in result.output
        assert says is None or says in result.output
    result = runner.invoke(
        app, ["experiment", "compare", "--arms", f"a={tmp_path / 'zoo'}", "--round", "1", "--cpu-hours", "1"]
    )
    assert result.exit_code == 1 and "not both" in result.output
