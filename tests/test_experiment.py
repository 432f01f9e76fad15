"""Experiments: validated files, and the smoke experiment on Ray (embedded with 2 CPUs; a driver killed
mid-run, resumed on a two-node cluster started on this machine) without redoing finished work."""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
import yaml
from conftest import hold
from typer.testing import CliRunner

from pecli.cli import app
from pecli.errors import ConfigError, PecliError
from pecli.experiment import ExperimentRunner, builtin_experiments, load_experiment
from pecli.experiment.runs import SELFPLAY_STATE, averages_behind, run_progress
from pecli.experiment.spec import RunSpec, experiment_from_dict
from pecli.rl.handover import averaged_from
from pecli.rl.train import with_overrides
from pecli.scenario import load_scenario
from pecli.zoo import metadata_path

runner = CliRunner()

EXPLOITER_KEYS = ("league_exploiter_every", "league_exploiter_roles", "league_exploiter_share")
SMOKE = {
    "name": "t",
    "scenario": "quick",
    "runs": {"kinds": ["none"], "seeds": [0], "rounds": 1, "steps_per_round": 100},
}


def write(tmp_path: Path, data: dict) -> Path:
    path = tmp_path / "exp.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def test_the_status_table_gives_each_self_play_run_its_rounds_per_cpu_hour() -> None:
    from rich.console import Console

    from pecli.cli.experiment import runs_table
    from pecli.experiment.folder import RunStatus
    from pecli.experiment.runs import RunProgress

    none, bimdn = load_experiment("smoke").runs()
    rows = [
        RunStatus(none, RunProgress(round=46, rounds=150, steps=3_680_000, cpu_seconds=3642.0, done=True), "done"),
        RunStatus(bimdn, RunProgress(round=0, rounds=150, steps=4_000, cpu_seconds=20.0, done=False), "running"),
    ]
    console = Console(width=200, record=True)
    console.print(runs_table(rows, "t"))
    lines = console.export_text().splitlines()
    assert "rounds/CPU-h" in lines[2]
    assert next(line for line in lines if none.name in line).split("│")[7].strip() == "45"  # 46 rounds in 1.01 h
    assert next(line for line in lines if bimdn.name in line).split("│")[7].strip() == "-"  # no round yet


def test_builtin_experiments() -> None:
    assert {
        "smoke",
        "table1",
        "table1-small",
        "table1-paper-settings",
        "table1-paper-settings-full",
        "table2",
        "strength",
        "schedules",
        "strength-small",
        "strength-exploiters",
        "strength-joingames",
        "strength-share",
        "strength-lite",
        "strength-floor",
        "exploitability",
        "exploitability-exploiters",
    } <= set(builtin_experiments())
    paper_settings = load_experiment("table1-paper-settings")
    assert {run.kind for run in paper_settings.runs()} == {"none", "ukf", "image", "bimdn", "bimdn-mixed"}
    assert len(paper_settings.runs()) == 15 and len({run.name for run in paper_settings.runs()}) == 15
    run = paper_settings.runs()[0]
    assert run.scenario.training.belief == run.kind and run.scenario.training.selfplay.rounds == 8
    table1 = load_experiment("table1-small")  # the same grid trained by the league recipe, 1 CPU-hour a run
    assert [(r.kind, r.seed) for r in table1.runs()] == [(r.kind, r.seed) for r in paper_settings.runs()]
    assert all(r.schedule == "league" and r.cpu_hours == 1 for r in table1.runs())
    assert table1.spec.ranking.players == "handed-over" and table1.scenario.fingerprint() == run.scenario.fingerprint()
    full = load_experiment("table1")  # the league recipe at the paper's budget: 55 rounds of 40 000, ~2.2M transitions
    assert [(r.kind, r.seed, r.schedule, r.cpu_hours) for r in full.runs()] == [
        (r.kind, r.seed, "league", None) for r in paper_settings.runs()
    ]
    selfplay = full.runs()[0].scenario.training.selfplay
    assert selfplay.rounds * selfplay.steps_per_round == 2_200_000 and full.spec.ranking.players == "handed-over"
    paper_full = load_experiment("table1-paper-settings-full").runs()[0].scenario.training.selfplay
    assert paper_full.rounds * paper_full.steps_per_round == 2_200_000
    assert load_experiment("table2").scenario.name == "point_mass"
    smoke = load_experiment("smoke")
    assert [r.kind for r in smoke.runs()] == ["none", "bimdn"] and smoke.scenario.training.learning_starts == 200
    schedules = load_experiment("schedules")  # the curriculum's span is fixed, whatever the CPU budget stops
    assert [(r.kind, r.seed, r.schedule) for r in schedules.runs()] == [  # the league first, as in strength.yaml
        ("none", seed, schedule) for schedule in ("league", "alternating", "simultaneous") for seed in (0, 1, 2)
    ]
    assert all(
        r.cpu_hours == 0.5 and r.scenario.training.curriculum.span(6_000_000) == 300_000 for r in schedules.runs()
    )
    strength = {(r.kind, r.seed, r.schedule): r for r in load_experiment("strength").runs()}
    for run in schedules.runs():  # strength.yaml's `none` runs (it extends strength), stopped earlier
        theirs = strength[(run.kind, run.seed, run.schedule)]
        assert run.name == theirs.name and run.scenario.training == theirs.scenario.training
    small = load_experiment("strength-small")  # the league as measured best at half a CPU-hour: no exploiters
    assert [(r.kind, r.seed, r.schedule) for r in small.runs()] == [
        (kind, seed, "league") for seed in (0, 1, 2) for kind in ("none", "bimdn")
    ]
    league = small.runs()[0].scenario.training.selfplay
    assert (league.opponents, league.league_exploiter_every, league.league_floor, league.league_floor_split) == (
        "league",
        0,
        0.3,
        "pfsp",
    )
    late = load_experiment("strength-exploiters").runs()[0].scenario.training.selfplay  # its exploiter after 2 CPU-h
    assert (late.league_exploiter_every, late.league_exploiter_after, late.league_exploiter_roles) == (
        1,
        2.0,
        ["evader"],
    )
    joining = load_experiment("strength-joingames").runs()[0].scenario.training.selfplay  # join games, a timeout
    assert (joining.league_exploiter_after, joining.exploiter_join_games, joining.league_exploiter_timeout) == (
        3.0,
        200,
        3,
    )
    sharing = load_experiment("strength-share").runs()[0].scenario.training.selfplay  # and a share of the games
    assert (sharing.exploiter_join_games, sharing.league_exploiter_share, sharing.league_floor) == (200, 0.25, 0.3)
    exploiters = load_experiment("exploitability-exploiters").runs()  # the league arm of exploitability, + exploiters
    league = [r for r in load_experiment("exploitability").runs() if r.schedule == "league"]
    for mine, theirs in zip(exploiters, league, strict=True):
        settings = mine.scenario.training.selfplay
        assert (settings.league_exploiter_every, settings.league_exploiter_roles) == (1, ["evader"])
        assert settings.league_exploiter_share == 0.2 and mine.cpu_hours == theirs.cpu_hours == 4
        plain = settings.model_copy(update={k: getattr(theirs.scenario.training.selfplay, k) for k in EXPLOITER_KEYS})
        assert plain == theirs.scenario.training.selfplay and mine.name == theirs.name
    lite = load_experiment("strength-lite").runs()  # strength-small's runs but for a BiMDN of 64 units
    assert [r.scenario.training.belief_settings.hidden for r in lite] == [64] * 6
    for mine, theirs in zip(lite, small.runs(), strict=True):  # so its `none` runs are strength-small's
        training = theirs.scenario.training
        assert mine.name == theirs.name and mine.scenario.fingerprint() == theirs.scenario.fingerprint()
        assert mine.scenario.training.model_copy(update={"belief_settings": training.belief_settings}) == training
    floor = load_experiment("strength-floor").runs()  # strength-lite's runs with half the games for the scripted
    for mine, theirs in zip(floor, lite, strict=True):
        settings = mine.scenario.training
        assert (settings.selfplay.league_floor, settings.selfplay.league_floor_split) == (0.5, "pfsp")
        assert settings.model_copy(update={"selfplay": theirs.scenario.training.selfplay}) == theirs.scenario.training
    for run in small.runs():  # so the league runs of strength-small and strength.yaml are the same runs
        assert run.scenario.training == strength[(run.kind, run.seed, run.schedule)].scenario.training
    preset = load_scenario("league")  # `pecli selfplay -c league` trains strength-small's runs, one at a time
    for run in small.runs():
        assert with_overrides(preset, {"belief": run.kind}).training == run.scenario.training
        assert preset.fingerprint() == run.scenario.fingerprint()
    for run in lite:  # and with `--belief bimdn --set belief_settings.hidden=64` strength-lite's
        settings = {"belief": run.kind, "belief_settings.hidden": 64}
        assert with_overrides(preset, settings).training == run.scenario.training


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"extra": 1}, "extra: unknown key"),
        ({"runs": {**SMOKE["runs"], "kinds": ["lstm"]}}, "runs.kinds.0: Input should be"),
        ({"runs": {**SMOKE["runs"], "kinds": []}}, "runs.kinds: List should have at least 1 item"),
        ({"runs": {**SMOKE["runs"], "seeds": "zero"}}, "runs.seeds: Input should be a valid list"),
        ({"ranking": {"keep": 0}}, "ranking.keep: Input should be greater than or equal to 1"),
        ({"training": {"batch_size": "big"}}, "training.batch_size: Input should be a valid integer"),
        ({"training": {"no_such": 1}}, "training.no_such: unknown key"),
        ({"scenario": "nowhere"}, "scenario: config not found: nowhere"),
        ({"runs": {**SMOKE["runs"], "seeds": [True]}}, "runs.seeds.0: a number is expected here, not the boolean true"),
        ({"runs": {**SMOKE["runs"], "schedules": ["pursuer"]}}, "train only pursuers"),
        (
            {"runs": {**SMOKE["runs"], "schedules": ["pursuer", "evader"], "opponent": "greedy"}},
            "runs.opponent: one opponent cannot train both",
        ),
        (
            {"runs": {**SMOKE["runs"], "schedules": ["selfplay", "evader"], "opponent": "greedy"}},
            "runs.opponent: 'greedy' cannot play pursuer",
        ),
        ({"tournament": {"players": ["hj"]}}, "tournament.players.0: hj plays point mass vs point mass only"),
        ({"tournament": {"players": ["grabby"]}}, "tournament.players.0: unknown player 'grabby'"),
        ({"tournament": {"episodes": 10**7}}, "tournament.episodes: Input should be less than or equal to 1000000"),
        ({"ranking": {"players": "best"}}, "ranking.players: Input should be 'ranked' or 'handed-over'"),
        (
            {
                "runs": {**SMOKE["runs"], "schedules": ["selfplay", "evader"], "opponent": "greedy"},
                "ranking": {"players": "handed-over"},
            },
            "handed-over takes each self-play run's average.zip, and schedules ['evader'] train one role",
        ),
    ],
)
def test_bad_experiment_files_give_one_line(tmp_path: Path, change: dict, message: str) -> None:
    path = write(tmp_path, {**SMOKE, **change})
    with pytest.raises(ConfigError) as info:
        load_experiment(path)
    assert str(info.value).startswith(f"{path}: ") and message in str(info.value)
    assert "\n" not in str(info.value)


def test_an_experiment_extends_another_key_by_key(tmp_path: Path) -> None:
    from pecli.scenario import builtin_config_dir

    mine = tmp_path / "mine.yaml"  # a built-in, one nested setting changed, the seeds replaced whole
    mine.write_text(
        yaml.safe_dump(
            {
                "name": "mine",
                "extends": "strength-small",
                "runs": {"seeds": [7]},
                "training": {"selfplay": {"league_floor": 0.5}},
            }
        )
    )
    loaded, small = load_experiment(mine), load_experiment("strength-small")
    assert loaded.spec.name == "mine" and loaded.spec.description == ""  # the name is its own; no description
    assert [(r.kind, r.seed) for r in loaded.runs()] == [("none", 7), ("bimdn", 7)]
    league = loaded.runs()[0].scenario.training.selfplay
    assert (league.league_floor, league.league_floor_split, league.league_exploiter_every) == (0.5, "pfsp", 0)
    assert loaded.spec.tournament == small.spec.tournament and loaded.spec.runs.cpu_hours == small.spec.runs.cpu_hours
    folder = tmp_path / "games"  # a file of the user's, its scenario file beside it, extended from elsewhere
    folder.mkdir()
    (folder / "game.yaml").write_text(
        (builtin_config_dir() / "quick.yaml").read_text().replace("horizon: 150", "horizon: 120")
    )
    (folder / "base.yaml").write_text(yaml.safe_dump({**SMOKE, "scenario": "game.yaml"}))
    (tmp_path / "top.yaml").write_text(yaml.safe_dump({"name": "top", "extends": "games/base.yaml"}))
    assert load_experiment(tmp_path / "top.yaml").runs()[0].scenario.horizon == 120


@pytest.mark.parametrize(
    ("top", "message"),
    [
        ({"extends": "strength-small"}, "needs a name of its own"),
        ({"name": "x", "extends": "nothing-such"}, "extends: experiment not found: nothing-such"),
        ({"name": "x", "extends": ["strength-small"]}, "extends: give the experiment it starts from"),
        ({"name": "x", "extends": "exp.yaml"}, "a loop"),
        ({"name": "x", "extends": "strength-small", "runs": {"kinds": ["lstm"]}}, "runs.kinds.0: Input should be"),
    ],
)
def test_a_bad_extends_gives_one_line(tmp_path: Path, top: dict, message: str) -> None:
    path = write(tmp_path, top)
    with pytest.raises(ConfigError) as info:
        load_experiment(path)
    assert str(info.value).startswith(f"{path}: ") and message in str(info.value) and "\n" not in str(info.value)


def test_saved_tournament_players_must_be_of_the_experiments_game(tmp_path: Path) -> None:
    import torch as th
    from test_export import make_checkpoint

    from pecli.scenario import load_scenario

    th.set_num_threads(1)
    other = make_checkpoint(tmp_path / "zoo", load_scenario("point_mass"), "none")  # another game than quick's
    (tmp_path / "empty").mkdir()
    (tmp_path / "junk.zip").write_bytes(b"not a checkpoint")
    for player, message in [
        (str(other), "trained on scenario 'point_mass', not 'quick'"),
        (str(tmp_path / "zoo"), "no checkpoint of scenario 'quick' under"),
        (str(tmp_path / "empty"), "no checkpoints under"),
        (str(tmp_path / "junk.zip"), "junk.zip"),
    ]:
        path = write(tmp_path, {**SMOKE, "tournament": {"players": [player]}})
        with pytest.raises(ConfigError, match=f"tournament.players.0: .*{message}") as info:
            load_experiment(path)
        assert "\n" not in str(info.value)
    mine = make_checkpoint(tmp_path / "mine", load_scenario("quick"), "none")
    assert load_experiment(write(tmp_path, {**SMOKE, "tournament": {"players": [str(mine)]}})).spec.tournament.players


def test_the_training_left_is_estimated_from_the_finished_runs_of_each_kind() -> None:
    from pecli.experiment.runs import RunProgress, training_left

    experiment = experiment_from_dict(
        {**SMOKE, "runs": {**SMOKE["runs"], "kinds": ["none", "bimdn"], "seeds": [0, 1, 2]}}, "exp.yaml"
    )
    runs = {run.name: run for run in experiment.runs()}
    progress = {name: RunProgress(0, 2, 0, 0.0, False) for name in runs}
    progress["none-s0"] = RunProgress(2, 2, 0, 100.0, True)
    progress["none-s1"] = RunProgress(2, 2, 0, 140.0, True)
    progress["none-s2"] = RunProgress(1, 2, 0, 30.0, False)  # mean 120, 30 used: 90 left
    pairs = [(runs[name], progress[name]) for name in runs]
    assert training_left(pairs) == (90.0, 3)  # no bimdn run has finished: those 3 are not counted
    progress["bimdn-s0"] = RunProgress(2, 2, 0, 400.0, True)
    progress["bimdn-s1"] = RunProgress(2, 2, 0, 450.0, False)  # past the mean: nothing left, not less
    assert training_left([(runs[name], progress[name]) for name in runs]) == (90.0 + 400.0, 0)


def test_a_scenario_file_is_read_beside_the_experiment(tmp_path: Path) -> None:
    from pecli.scenario import builtin_config_dir

    folder = tmp_path / "mine"
    folder.mkdir()
    (folder / "game.yaml").write_text(
        (builtin_config_dir() / "quick.yaml").read_text().replace("horizon: 150", "horizon: 120")
    )
    loaded = load_experiment(
        write(folder, {**SMOKE, "scenario": "game.yaml", "training": {"selfplay": {"pfsp_power": 1}}})
    )
    run = loaded.runs()[0]
    assert run.scenario.horizon == 120 and run.scenario.training.selfplay.pfsp_power == 1
    assert Path(loaded.spec.scenario) == (folder / "game.yaml").resolve()  # so --out can read it from anywhere


def test_an_edited_scenario_under_an_experiment_is_refused(tmp_path: Path) -> None:
    from pecli.experiment.folder import SCENARIO_FILE
    from pecli.scenario import builtin_config_dir

    game = tmp_path / "game.yaml"
    game.write_text((builtin_config_dir() / "quick.yaml").read_text())
    path, out = write(tmp_path, {**SMOKE, "scenario": "game.yaml"}), tmp_path / "out"

    def prepare() -> None:  # a driver that records the experiment and ends
        runner = ExperimentRunner(load_experiment(path), out)
        runner.prepare()
        runner._save(ended="interrupted")

    prepare()
    assert (out / SCENARIO_FILE).is_file()
    prepare()  # the same game: continues
    game.write_text(game.read_text().replace("horizon: 150", "horizon: 120"))
    with pytest.raises(PecliError, match=r"'.*game.yaml' has changed since .* \(horizon: 150 -> 120; as first run"):
        prepare()
    (out / SCENARIO_FILE).unlink()  # an experiment from before pecli recorded its scenario: recorded now
    prepare()
    assert (out / SCENARIO_FILE).is_file()
    game.write_text(game.read_text().replace("description:", "description: edited,"))
    prepare()  # the name and description are no part of the game
    recorded = yaml.safe_load((out / SCENARIO_FILE).read_text())
    del recorded["training"]["n_step"]  # a setting pecli added after the experiment started: it ran at its default
    (out / SCENARIO_FILE).write_text(yaml.safe_dump(recorded))
    prepare()  # which the scenario keeps (quick.yaml leaves n_step at 1)
    del recorded["training"]["batch_size"]  # quick.yaml sets 256: not the default the experiment ran at
    (out / SCENARIO_FILE).write_text(yaml.safe_dump(recorded))
    with pytest.raises(PecliError, match=r"training.batch_size: 512 \(its default\) -> 256"):
        prepare()


def test_cli_refuses_a_bad_file_in_one_line(tmp_path: Path) -> None:
    path = write(tmp_path, {**SMOKE, "runs": {**SMOKE["runs"], "kinds": ["none", "none"]}})
    result = runner.invoke(app, ["experiment", "run", str(path), "--out", str(tmp_path / "out")])
    assert result.exit_code == 1
    assert result.output.strip().count("\n") == 0 and "exp.yaml: runs: kinds repeats a value" in result.output
    result = runner.invoke(app, ["experiment", "status", str(tmp_path / "nothing")])
    assert result.exit_code == 1 and "holds no experiment" in result.output
    result = runner.invoke(app, ["experiment", "run", "smoke", "--cpus", "0", "--out", str(tmp_path / "zero")])
    assert result.exit_code == 1 and "--cpus must be at least 1" in result.output
    assert not (tmp_path / "zero" / "experiment.json").exists()  # refused before anything is recorded


def test_cli_shows_an_experiment_as_it_will_run(tmp_path: Path) -> None:
    result = runner.invoke(app, ["experiment", "show", "strength-share"])  # extends strength-joingames, which extends
    assert result.exit_code == 0, result.output  # strength-small
    shown = yaml.safe_load(result.output[: result.output.index("fingerprint ")])
    assert shown["name"] == "strength-share" and "extends" not in shown
    assert shown["training"]["selfplay"]["league_exploiter_share"] == 0.25  # its own
    assert shown["training"]["selfplay"]["exploiter_join_games"] == 200  # strength-joingames'
    assert shown["training"]["selfplay"]["league_floor"] == 0.3  # strength-small's
    assert (
        f"fingerprint {load_experiment('strength-share').spec.fingerprint()}; 6 runs: none-league-s0" in result.output
    )
    result = runner.invoke(app, ["experiment", "show", str(write(tmp_path, {"extends": "strength-small"}))])
    assert result.exit_code == 1 and result.output.strip().count("\n") == 0 and "a name of its own" in result.output


def test_one_driver_per_out_folder(tmp_path: Path) -> None:
    """Another process writing --out (an OS lock, whatever its PID record says) refuses a second driver."""
    out = tmp_path / "out"
    out.mkdir()
    holder = hold(out)
    try:
        assert holder.poll() is None  # it holds the lock
        result = runner.invoke(app, ["experiment", "run", "smoke", "--out", str(out)])
        assert result.exit_code == 1 and f"is being written by process {holder.pid}" in result.output
        assert not (out / "experiment.json").exists()
    finally:
        holder.kill()
        holder.wait()


def test_self_play_schedules_and_a_cpu_budget_in_the_grid(tmp_path: Path) -> None:
    grid = {**SMOKE["runs"], "schedules": ["selfplay", "simultaneous", "league", "pursuer"], "cpu_hours": 2}
    runs = {run.name: run for run in experiment_from_dict({**SMOKE, "runs": grid}, "exp.yaml").runs()}
    assert list(runs) == ["none-s0", "none-simultaneous-s0", "none-league-s0", "none-pursuer-s0"]
    settings = {
        name: (
            run.scenario.training.selfplay.schedule,
            run.scenario.training.selfplay.opponents,
            run.roles,
            run.cpu_hours,
        )
        for name, run in runs.items()
    }
    assert settings["none-simultaneous-s0"][0] == "simultaneous"
    assert settings["none-league-s0"][:2] == ("alternating", "league")
    assert settings["none-league-s0"][2] == ("pursuer", "evader") and settings["none-league-s0"][3] == 2
    assert settings["none-pursuer-s0"][2:] == (("pursuer",), None)  # a one-role run has its own budget (steps)
    for bad, message in ((0, "greater than 0"), (float("inf"), "finite number"), ("two", "valid number")):
        with pytest.raises(ConfigError, match=message):
            experiment_from_dict({**SMOKE, "runs": {**grid, "cpu_hours": bad}}, "exp.yaml")


def test_runs_start_schedule_by_schedule_with_every_kind_of_a_seed_together() -> None:
    """A cluster smaller than the grid finishes the first schedule for every kind, seed by seed, first."""
    grid = {**SMOKE["runs"], "kinds": ["none", "bimdn"], "seeds": [0, 1], "schedules": ["league", "alternating"]}
    names = [run.name for run in experiment_from_dict({**SMOKE, "runs": grid}, "exp.yaml").runs()]
    assert names == [
        "none-league-s0",
        "bimdn-league-s0",
        "none-league-s1",
        "bimdn-league-s1",
        "none-alternating-s0",
        "bimdn-alternating-s0",
        "none-alternating-s1",
        "bimdn-alternating-s1",
    ]


def test_a_setting_added_since_a_run_started_is_a_change_only_where_set_otherwise(paper) -> None:
    """A recorded scenario without a newer training setting ran at that setting's default."""
    from pecli.experiment.runs import setting_changes as changes
    from pecli.rl.train import with_overrides

    recorded = paper.model_dump(mode="json")
    del recorded["training"]["curriculum"]["steps"]  # recorded before pecli had the setting
    assert changes(recorded, paper.model_dump(mode="json")) == []
    later = with_overrides(paper, {"curriculum.steps": 400}).model_dump(mode="json")
    assert changes(recorded, later) == ["training.curriculum.steps: None (its default) -> 400"]
    assert changes(paper.model_dump(mode="json"), later) == ["training.curriculum.steps: None -> 400"]


def test_the_ranking_draws_its_pairings_over_runs_in_the_grids_own_order() -> None:
    """Kind, then seed, then schedule, whatever order the runs start in: an experiment ranked before runs started
    schedule by schedule keeps its random pairings."""
    grid = {**SMOKE["runs"], "kinds": ["none", "bimdn"], "seeds": [0, 1], "schedules": ["league", "alternating"]}
    experiment = experiment_from_dict({**SMOKE, "runs": grid}, "exp.yaml")
    names = [run.name for run in experiment.grid_order(experiment.runs())]
    assert names == [
        "none-league-s0",
        "none-alternating-s0",
        "none-league-s1",
        "none-alternating-s1",
        "bimdn-league-s0",
        "bimdn-alternating-s0",
        "bimdn-league-s1",
        "bimdn-alternating-s1",
    ]


@pytest.mark.parametrize("schedule", ["selfplay", "league"])
def test_a_cpu_budget_ends_a_run_after_the_round_that_reaches_it(tmp_path: Path, schedule: str) -> None:
    """A run whose budget is spent in round 1 stops there, well below its ceiling of 3 rounds, and a second
    call (a retried task) does nothing."""
    from pecli.experiment.runs import execute_run

    data = {
        **SMOKE,
        "training": {"learning_starts": 50, "batch_size": 16, "net_arch": [16, 16], "n_envs": 2},
        "runs": {**SMOKE["runs"], "rounds": 3, "schedules": [schedule], "cpu_hours": 1e-6},
    }
    (run,) = experiment_from_dict(data, "exp.yaml").runs()
    lines: list[str] = []
    first = execute_run(run, tmp_path, report=lines.append)
    assert first["did"] == "started" and first["progress"]["done"] and first["progress"]["round"] == 1
    assert lines[0].startswith("round 1/3: pursuer") and lines[-1].startswith("budget reached")  # round, budget
    turns = json.loads((tmp_path / run.name / SELFPLAY_STATE).read_text())["turns"]
    assert {t["round"] for t in turns} == {1}
    assert {t.get("learner", "main") for t in turns} == ({"main", "exploiter"} if schedule == "league" else {"main"})
    assert execute_run(run, tmp_path)["did"] == "finished"


class InlineCluster:
    """The part of :class:`~pecli.experiment.ray_executor.RayCluster` that trains runs, in this process: a run
    trains when submitted, and its ref is its index."""

    def __init__(self) -> None:
        self.trained: list[tuple[str, float | None]] = []
        self.outcomes: list[dict] = []

    def submit_run(self, run: RunSpec, zoo: Path, marker: Path) -> int:
        from pecli.experiment.runs import execute_run

        self.trained.append((run.name, run.cpu_hours))
        self.outcomes.append(execute_run(run, zoo.resolve()))  # as RayCluster hands it to its task
        return len(self.outcomes) - 1

    @staticmethod
    def wait(refs: list[int], timeout: float) -> list[int]:
        return list(refs)

    def result(self, ref: int) -> dict:
        return self.outcomes[ref]


def test_until_cpu_hours_pauses_every_run_at_that_budget_before_the_ranking(tmp_path: Path) -> None:
    """A run of 2 rounds whose first round passes the pause's budget stops there, paused, and nothing is ranked;
    called again without the pause, the same run trains its second round."""
    from pecli.experiment.folder import stage_lines

    data = {
        **SMOKE,
        "training": {"learning_starts": 50, "batch_size": 16, "net_arch": [16, 16], "n_envs": 2},
        "runs": {**SMOKE["runs"], "rounds": 2},
    }
    experiment = experiment_from_dict(data, "exp.yaml")
    with pytest.raises(PecliError, match="positive number of hours"):
        ExperimentRunner(experiment, tmp_path, until_cpu_hours=0)
    cluster = InlineCluster()
    paused = ExperimentRunner(experiment, tmp_path, until_cpu_hours=1e-6)
    assert paused.run(cluster) is None  # type: ignore[arg-type]  # no ranking: InlineCluster plays no pairings
    assert cluster.trained == [("none-s0", 1e-6)] and [row.status for row in paused.rows] == ["paused"]
    (run,) = experiment.runs()
    assert run_progress(run, tmp_path / "zoo").round == 1 and not run_progress(run, tmp_path / "zoo").done
    state = json.loads((tmp_path / "experiment.json").read_text())
    assert state["stages"]["train"] == "paused" and state["sessions"][-1]["ended"] == "paused"
    assert stage_lines(tmp_path, state, alive=False) == [
        "training: paused, every run at 1e-06 CPU-h or its own budget (--until-cpu-hours)"
    ]
    assert ExperimentRunner(experiment, tmp_path, until_cpu_hours=1e-6).run(cluster) is None  # nothing to train
    assert len(cluster.trained) == 1
    again = ExperimentRunner(experiment, tmp_path)
    again.prepare()
    again._train(cluster)  # type: ignore[arg-type]
    assert cluster.trained[-1] == ("none-s0", None) and run_progress(run, tmp_path / "zoo").done
    assert [row.status for row in again.rows] == ["done"]


def test_a_finished_runs_task_writes_the_averages_a_stop_left_behind_and_trains_nothing(
    tmp_path: Path, monkeypatch
) -> None:
    """Stopped between a run's last round and its averages: the next session submits the finished run, whose
    task writes them (counted as skipped: nothing is trained); once they are there, it is not submitted, with
    a relative --out too (the task writes absolute paths)."""
    data = {
        **SMOKE,
        "training": {"learning_starts": 50, "batch_size": 16, "net_arch": [16, 16], "n_envs": 2},
        "runs": {**SMOKE["runs"], "rounds": 1},
    }
    experiment = experiment_from_dict(data, "exp.yaml")
    (run,) = experiment.runs()
    monkeypatch.chdir(tmp_path)
    out = Path("out")
    zoo, cluster = out / "zoo", InlineCluster()

    def train() -> ExperimentRunner:
        runner = ExperimentRunner(experiment, out)
        runner.prepare()
        runner._train(cluster)  # type: ignore[arg-type]
        runner._save(ended="done")  # the stages after training are not this test's
        return runner

    train()
    average = zoo / run.name / "pursuer" / "average.zip"
    written = averaged_from(average)
    assert run_progress(run, zoo).done and written and not averages_behind(run, zoo)
    average.unlink()
    metadata_path(average).unlink()
    assert averages_behind(run, zoo)
    state = (zoo / run.name / SELFPLAY_STATE).read_bytes()
    again = train()
    assert len(cluster.trained) == 2 and cluster.outcomes[-1]["did"] == "finished"
    assert (again.session.runs_skipped, again.session.runs_started, again.session.runs_resumed) == (1, 0, 0)
    assert averaged_from(average) == written and (zoo / run.name / SELFPLAY_STATE).read_bytes() == state
    assert not averages_behind(run, zoo) and [row.status for row in again.rows] == ["done"]
    train()
    assert len(cluster.trained) == 2  # nothing behind: not submitted


def test_the_ranking_keeps_a_leagues_main_agents_not_its_exploiters() -> None:
    from pecli.experiment.pipeline import keep_best
    from pecli.scenario import load_scenario
    from pecli.tournament import PairingResult, Player, TournamentResults

    grid = {**SMOKE["runs"], "schedules": ["league"]}
    (run,) = experiment_from_dict({**SMOKE, "runs": grid}, "exp.yaml").runs()
    main = Player("main", f"zoo/{run.name}/pursuer/round-001.zip", "pursuer", "a")
    exploiter = Player("exploiter", f"zoo/{run.name}/exploiter-pursuer/round-001.zip", "pursuer", "b")
    evader = Player("evader", f"zoo/{run.name}/evader/round-001.zip", "evader", "c")
    pairings = [PairingResult("main", "evader", 10, 2, 0.5, 0.1), PairingResult("exploiter", "evader", 10, 9, 0.5, 0.1)]
    results = TournamentResults(
        load_scenario("quick"), {"pursuer": [main, exploiter], "evader": [evader]}, pairings, [], 10, [0]
    )
    assert keep_best(results, [run], keep=1)[run.name] == {"pursuer": [main.spec], "evader": [evader.spec]}


def test_handed_over_players_are_each_runs_averages(tmp_path: Path) -> None:
    from pecli.experiment.pipeline import handed_over

    grid = {**SMOKE["runs"], "schedules": ["league"]}
    runs = experiment_from_dict({**SMOKE, "runs": grid}, "exp.yaml").runs()
    for run in runs:
        for role in ("pursuer", "evader"):
            (tmp_path / run.name / role).mkdir(parents=True)
            (tmp_path / run.name / role / "average.zip").write_bytes(b"")
    kept = handed_over(runs, tmp_path)
    assert kept == {
        run.name: {role: [str(tmp_path / run.name / role / "average.zip")] for role in ("pursuer", "evader")}
        for run in runs
    }
    (tmp_path / runs[0].name / "evader" / "average.zip").unlink()
    with pytest.raises(PecliError, match=f"{runs[0].name} hands over no player: .*evader/average.zip is missing"):
        handed_over(runs, tmp_path)


def handed_over_tournament(
    tmp_path: Path, seeds: list[int], kinds: tuple[str, ...] = ("none",), schedules: tuple[str, ...] = ("league",)
) -> tuple[Path, dict]:
    """An experiment folder of one league schedule whose handed-over players (and the paper's pure pursuit and
    greedy) played a tournament in which every pairing caught 7 of 10; and its ``kept.json``."""
    from pecli.io import atomic_write_json
    from pecli.tournament import PairingResult, Player, TournamentResults, rate

    runs = {**SMOKE["runs"], "schedules": list(schedules), "seeds": seeds, "kinds": list(kinds)}
    data = {**SMOKE, "runs": runs, "ranking": {"players": "handed-over"}}
    experiment = experiment_from_dict(data, "exp.yaml")
    out = tmp_path / "out"
    (out / "tournament").mkdir(parents=True)
    (out / "experiment.yaml").write_text(yaml.safe_dump(data))
    players: dict = {"pursuer": [Player("pure-pursuit", "pure-pursuit", "pursuer", "pure-pursuit")], "evader": []}
    players["evader"].append(Player("greedy", "greedy", "evader", "greedy"))
    kept = {}
    for run in experiment.runs():
        kept[run.name] = {role: [f"zoo/{run.name}/{role}/average.zip"] for role in ("pursuer", "evader")}
        for role in ("pursuer", "evader"):
            players[role].append(Player(f"{run.name}/{role}", kept[run.name][role][0], role, run.name + role))
    pairings = [PairingResult(p.name, e.name, 10, 7, 0.5, 0.1) for p in players["pursuer"] for e in players["evader"]]
    results = TournamentResults(experiment.scenario, players, pairings, rate(players, pairings), 10, [0])
    atomic_write_json(out / "tournament" / "results.json", results.to_json())
    atomic_write_json(out / "kept.json", kept)
    return out, kept


def test_a_report_of_one_schedules_handed_over_players_lays_each_kind_beside_the_papers(tmp_path: Path) -> None:
    from pecli.experiment.report import ExperimentReport

    out, kept = handed_over_tournament(tmp_path, [0])
    text = ExperimentReport(out).markdown()
    assert "Players: each run's handed-over average.zip" in text and "Ranking:" not in text
    assert "| evader \\ pursuer | Pure Pursuit | MADDPG |" in text  # not "MADDPG (league)": the paper's kind
    assert "| Greedy | **0.70**† / 0.34 (+0.36) | **0.70**† / 0.83 (−0.13) |" in text
    assert "| MADDPG | pursuer | 1 | 0.700 | [0.700, 0.700] |" in text  # one model: an interval of one point
    assert "| MADDPG | evader | 1 | 0.300 | [0.300, 0.300] |" in text  # escapes
    assert "Best responses" not in text  # none measured yet

    (run,) = kept
    measured(out / "exploit" / run, kept[run]["pursuer"][0], kept[run]["evader"][0])
    text = ExperimentReport(out).markdown()
    row = f"| {run} | MADDPG | 0.700 | 0.200 [0.057, 0.510] | 0.900 [0.596, 0.982] | 0.700 ["
    assert "## Best responses to each run's players" in text and row in text and "20 CPU-minutes each" in text
    assert "| MADDPG | pursuer | 1 | 0.700 | [0.700, 0.700] |" in text  # one model: an interval of one point
    assert "| MADDPG | evader | 1 | 0.300 | [0.300, 0.300] |" in text  # escapes


@pytest.mark.parametrize(
    ("file", "change", "message"),
    [
        ("kept", lambda kept: {run: "x" for run in kept}, r"kept.json: damaged record of kept checkpoints"),
        ("kept", lambda kept: {run: {"referee": []} for run in kept}, r"kept.json: damaged record of kept"),
        ("results", lambda r: {**r, "ratings": "x"}, r"results.json: damaged tournament's results \(ratings"),
        ("results", lambda r: {**r, "ratings": [{"name": "a"}]}, r"ratings.0.role: Field required"),
        ("results", lambda r: {**r, "episodes_per_seed": float("nan")}, r"episodes_per_seed"),
        ("results", lambda r: {**r, "pairings": [{"pursuer": "p"}]}, r"pairings.0.evader: Field required"),
        ("results", lambda r: {**r, "pairings": [{**r["pairings"][0], "captures": 11}]}, r"11 captures in 10"),
        ("results", lambda r: {**r, "pairings": [{**r["pairings"][0], "pursuer": "x"}]}, r"x is no rated pursuer"),
    ],
)
def test_a_damaged_tournament_record_is_one_line_in_the_report(
    tmp_path: Path, file: str, change: Callable[[Any], Any], message: str
) -> None:
    from pecli.io import read_json

    out, _ = handed_over_tournament(tmp_path, [0])
    path = out / "kept.json" if file == "kept" else out / "tournament" / "results.json"
    path.write_text(json.dumps(change(read_json(path, "record"))))
    result = runner.invoke(app, ["experiment", "report", str(out)])
    assert result.exit_code == 1 and re.search(message, result.output), result.output
    assert result.output.strip().count("\n") == 0


def test_the_report_tests_the_papers_ordering_of_each_belief_against_maddpg(tmp_path: Path) -> None:
    from pecli.experiment.report import ExperimentReport
    from pecli.io import atomic_write_json, read_json

    out, _ = handed_over_tournament(tmp_path, [0], kinds=("none", "bimdn"))
    results = read_json(out / "tournament" / "results.json", "results")
    for pairing in results["pairings"]:  # Ours catches 9 of 10, MADDPG 5, pure pursuit 3, whoever the evader
        pairing["captures"] = 9 if "bimdn" in pairing["pursuer"] else 5 if "none" in pairing["pursuer"] else 3
    atomic_write_json(out / "tournament" / "results.json", results)
    report = ExperimentReport(out)
    (row,) = report.ordering()  # pure pursuit is no learned group; MADDPG is the base
    assert (row["group"], row["against"], row["evaders"], row["games"]) == ("Ours", "MADDPG", 3, 30)
    assert (row["capture_rate"], row["against_capture_rate"]) == pytest.approx((0.9, 0.5))
    assert row["excess_per_game"] == pytest.approx(0.2)  # 9 captures per evader where a shared 7 of 10 gives 7
    assert row["z_test_p"] < 0.01 and row["stratified_p"] < 0.01
    assert "## The paper's ordering: each belief against MADDPG" in report.markdown()
    assert report.to_json()["ordering"] == [row]

    for pairing in results["pairings"]:
        pairing["captures"] = 7  # no difference: nothing to claim
    atomic_write_json(out / "tournament" / "results.json", results)
    (row,) = ExperimentReport(out).ordering()
    assert row["excess_per_game"] == 0 and row["stratified_p"] == pytest.approx(1.0)


def measured(folder: Path, pursuer: str, evader: str, steps: int | None = None) -> None:
    """Records of best responses to a pair, as `pecli exploit --pair` writes them: responses catch 2 and 9 of 10,
    the pair itself 7 of 10; of 20 CPU-minutes each, or ``steps`` transitions."""
    from pecli.exploit import ExploitRecord, Response
    from pecli.io import atomic_write_json

    for role, target, captures in (("pursuer", pursuer, 2), ("evader", evader, 9)):
        response = Response(arm="fresh", seed=0, captures=captures, episodes=10, cpu_seconds=1, steps=5, checkpoint="")
        record = ExploitRecord(
            target=target, target_identity=target, role=role, scenario="quick", scenario_hash="h",
            cpu_minutes=None if steps else 20.0, steps=steps, episodes=10, belief="none",
            responses={"fresh-s0": response},
        )  # fmt: skip
        atomic_write_json(folder / f"against-{role}" / "exploit.json", record.model_dump(mode="json"))
    atomic_write_json(folder / "pair.json", {"captures": 7, "episodes": 10})


def test_a_groups_seeds_are_measured_as_one_mixed_pair(tmp_path: Path) -> None:
    from pecli.experiment.exploit import mixed_pairs, recorded_pairs
    from pecli.experiment.report import ExperimentReport

    out, _ = handed_over_tournament(tmp_path, [0, 1])
    pursuers, evaders = mixed_pairs(out)["none-league-mixed"]
    assert pursuers == "mix:zoo/none-league-s0/pursuer/average.zip,zoo/none-league-s1/pursuer/average.zip"
    assert evaders == "mix:zoo/none-league-s0/evader/average.zip,zoo/none-league-s1/evader/average.zip"
    measured(out / "exploit" / "none-league-mixed", pursuers, evaders, steps=600_000)
    assert list(recorded_pairs(out)) == ["none-league-mixed"]  # no run's own pair measured yet
    (row,) = ExperimentReport(out).best_responses()
    assert (row["run"], row["group"], row["nash_conv"]) == ("none-league-mixed", "MADDPG", pytest.approx(0.7))
    assert row["budget"] == "600,000 transitions" and "600,000 transitions each" in ExperimentReport(out).markdown()


def test_a_seeds_runs_of_every_kind_are_measured_as_one_population(tmp_path: Path) -> None:
    from pecli.experiment.exploit import mixed_pairs, population_pairs, recorded_pairs
    from pecli.experiment.report import ExperimentReport

    out, _ = handed_over_tournament(tmp_path, [0, 1], kinds=("none", "bimdn"))
    populations = population_pairs(out)
    assert list(populations) == ["population-league-s0", "population-league-s1"]
    pursuers, evaders = populations["population-league-s1"]
    assert pursuers == "mix:zoo/none-league-s1/pursuer/average.zip,zoo/bimdn-league-s1/pursuer/average.zip"
    assert evaders == "mix:zoo/none-league-s1/evader/average.zip,zoo/bimdn-league-s1/evader/average.zip"
    assert list(mixed_pairs(out)) == ["none-league-mixed", "bimdn-league-mixed"]  # by kind, over seeds
    measured(out / "exploit" / "population-league-s1", pursuers, evaders)
    assert list(recorded_pairs(out)) == ["population-league-s1"]
    (row,) = ExperimentReport(out).best_responses()
    assert (row["run"], row["group"], row["nash_conv"]) == ("population-league-s1", "every kind", pytest.approx(0.7))
    one_kind, _ = handed_over_tournament(tmp_path / "one", [0, 1], schedules=("league", "nash"))
    assert population_pairs(one_kind) == {}  # one kind under each schedule is no population


def test_each_pairs_responses_train_together_and_the_pair_is_recorded_before_the_next(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    import pecli.experiment.exploit as experiment_exploit

    out, _ = handed_over_tournament(tmp_path, [0, 1])
    calls = []

    def trained(jobs, report, workers):  # what would train, without training
        calls.append(([(job.out.relative_to(out), job.role, job.warm_start) for job in jobs], workers))
        return [f"result of {job.out.name}" for job in jobs]

    def measured(jobs, results, folder):  # the pair's own games, recorded before the next pair trains
        calls.append(folder.name)
        return folder.name, results

    monkeypatch.setattr(experiment_exploit, "exploit_all", trained)
    monkeypatch.setattr(experiment_exploit, "pair_result", measured)
    found = experiment_exploit.exploit_experiment(out, mixtures=True, runs=False, workers=4, cpu_minutes=1.0)
    mixed = Path("exploit/none-league-mixed")
    pair = [(mixed / "against-pursuer", "pursuer", None), (mixed / "against-evader", "evader", None)]
    assert calls == [(pair, 4), "none-league-mixed"]
    assert found == {
        "none-league-mixed": ("none-league-mixed", ["result of against-pursuer", "result of against-evader"])
    }
    calls.clear()
    found = experiment_exploit.exploit_experiment(out, mixtures=True, workers=2, cpu_minutes=1.0)
    assert [call if isinstance(call, str) else len(call[0]) for call in calls] == [
        2, "none-league-s0", 2, "none-league-s1", 2, "none-league-mixed"
    ]  # fmt: skip
    with pytest.raises(PecliError, match="no pair to measure"):
        experiment_exploit.exploit_experiment(out, mixtures=False, runs=False)
    with pytest.raises(PecliError, match="no pair to measure"):  # one kind: no seed holds a population
        experiment_exploit.exploit_experiment(out, runs=False, populations=True)


@pytest.mark.parametrize(
    ("flags", "chosen"),
    [
        ([], (True, False, False)),
        (["--mixtures"], (True, True, False)),
        (["--only-mixtures"], (False, True, False)),
        (["--populations"], (True, False, True)),
        (["--populations", "--only-mixtures"], (False, False, True)),
        (["--populations", "--mixtures", "--only-mixtures"], (False, True, True)),
        (["--steps", "5000"], (True, False, False)),
    ],
)
def test_experiment_exploit_flags_choose_runs_mixtures_and_populations(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, flags: list[str], chosen: tuple[bool, bool, bool]
) -> None:
    import pecli.experiment.exploit as experiment_exploit
    import pecli.experiment.report as experiment_report

    asked, budgets = [], []

    def measure(out, report, runs, mixtures, populations, **settings) -> None:
        asked.append((runs, mixtures, populations))
        budgets.append((settings["cpu_minutes"], settings["steps"]))

    monkeypatch.setattr(experiment_exploit, "exploit_experiment", measure)
    monkeypatch.setattr(experiment_report, "write_report", lambda out: [])
    result = runner.invoke(app, ["experiment", "exploit", str(tmp_path), *flags])
    assert result.exit_code == 0, result.output
    assert asked == [chosen] and budgets == [(20.0, 5000 if "--steps" in flags else None)]


def test_best_responses_need_the_experiments_kept_players(tmp_path: Path) -> None:
    result = runner.invoke(app, ["experiment", "exploit", str(tmp_path / "none")])
    assert result.exit_code == 1 and "holds no experiment" in result.output
    (tmp_path / "out").mkdir()
    (tmp_path / "out" / "experiment.yaml").write_text(yaml.safe_dump(SMOKE))
    result = runner.invoke(app, ["experiment", "exploit", str(tmp_path / "out"), "--seeds", "0"])
    assert result.exit_code == 1 and "--seeds" in result.output
    result = runner.invoke(app, ["experiment", "exploit", str(tmp_path / "out"), "--steps", "9", "--cpu-minutes", "1"])
    assert result.exit_code == 1 and "one budget" in result.output
    result = runner.invoke(app, ["experiment", "exploit", str(tmp_path / "out")])
    assert result.exit_code == 1 and "no players kept yet (kept.json)" in result.output
    assert len(result.output.strip().splitlines()) == 1
    for kept in ({"none-s0": {"pursuer": [7]}}, {"../../elsewhere": {"pursuer": ["p.zip"], "evader": ["e.zip"]}}):
        (tmp_path / "out" / "kept.json").write_text(json.dumps(kept))  # a run's name would be a folder of OUT
        result = runner.invoke(app, ["experiment", "exploit", str(tmp_path / "out")])
        assert result.exit_code == 1 and "kept.json: damaged record of kept checkpoints" in result.output
        assert len(result.output.strip().splitlines()) == 1


# -- on Ray ---------------------------------------------------------------------------------------------


def ray_processes(group: int | None = None) -> list[str]:
    """Ray's processes alive in process group ``group`` (default: this one's, where an embedded Ray starts its
    GCS, raylet and agents; its workers end with the raylet), as ``ps`` lines ``pid ppid pgid stat args``.

    A zombie (``stat`` Z: exited, not yet reaped) is not alive: a container whose PID 1 reaps orphans late keeps
    a dead raylet in ``ps`` as ``[raylet] <defunct>`` for a while."""
    group = os.getpgrp() if group is None else group
    out = subprocess.run(["ps", "-eo", "pid,ppid,pgid,stat,args"], capture_output=True, text=True).stdout
    return [
        line
        for line in out.splitlines()[1:]
        if int(line.split()[2]) == group
        and not line.split()[3].startswith("Z")
        and ("raylet" in line or "gcs_server" in line or "ray::" in line)
    ]


def alive(pid: int) -> bool:
    """Whether process ``pid`` runs (a zombie does not)."""
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] != "Z"
    except OSError:
        return False


def cached_pairings(out: Path) -> int:
    return sum(
        len(list((out / stage / "pairings").glob("*.json")))
        for stage in ("ranking", "tournament")
        if (out / stage / "pairings").is_dir()
    )


def test_a_stop_cancels_no_finished_task_on_ray(monkeypatch: pytest.MonkeyPatch) -> None:
    """Ctrl-C or SIGTERM mid-tournament closes the pairings' generator: the tasks still out end with Ray's
    shutdown, none is cancelled (``ray.cancel`` racing a task's completion aborts the driver inside Ray, exit 1
    instead of 130, Ray's agents left behind); stopping runs cancels the unfinished ones only."""
    from types import SimpleNamespace

    import ray

    from pecli.experiment import ray_executor
    from pecli.experiment.ray_executor import RayCluster

    cancelled: list[str] = []
    monkeypatch.setattr(ray_executor, "_pairing_task", SimpleNamespace(remote=lambda job: job))  # a ref is its job
    monkeypatch.setattr(ray, "wait", lambda refs, num_returns=1, timeout=None: (refs[:num_returns], refs[num_returns:]))
    monkeypatch.setattr(ray, "get", lambda ref: f"played {ref}")
    monkeypatch.setattr(ray, "cancel", lambda ref, force=False: cancelled.append(ref))
    pairings = RayCluster().play_pairings(["j0", "j1", "j2"])  # type: ignore[list-item]
    assert next(pairings) == (0, "played j0")
    pairings.close()  # as run_tournament does when interrupted
    assert cancelled == []

    def finished(refs: list[str], num_returns: int, timeout: float) -> tuple[list[str], list[str]]:
        return [r for r in refs if r.startswith("done")], [r for r in refs if not r.startswith("done")]

    monkeypatch.setattr(ray, "wait", finished)
    RayCluster.stop(["done-a", "running-b"], grace=0)  # type: ignore[list-item]
    assert cancelled == ["running-b"]


def test_sigterm_while_ray_starts_stops_like_ctrl_c(monkeypatch: pytest.MonkeyPatch) -> None:
    """ray.init puts its own SIGTERM handler (exit code 15) in place of the caller's: the caller's gets a SIGTERM
    that comes while Ray starts, and is back once it has started."""
    import ray

    from pecli.experiment.ray_executor import WORKER_NICENESS, RayCluster
    from pecli.process import interrupt, sigterm_stops

    def init(signalled: bool, **options: object) -> None:
        signal.signal(signal.SIGTERM, lambda signum, frame: sys.exit(signum))  # as ray.init does
        if signalled:
            signal.getsignal(signal.SIGTERM)(signal.SIGTERM, None)  # type: ignore[operator]

    shutdowns: list[bool] = []
    monkeypatch.setenv(WORKER_NICENESS, "0")
    monkeypatch.setattr(ray, "is_initialized", lambda: False)
    monkeypatch.setattr(ray, "shutdown", lambda: shutdowns.append(True))
    with sigterm_stops():
        monkeypatch.setattr(ray, "init", lambda **options: init(False, **options))
        with RayCluster(cpus=1):
            assert signal.getsignal(signal.SIGTERM) is interrupt
        monkeypatch.setattr(ray, "init", lambda **options: init(True, **options))
        with pytest.raises(KeyboardInterrupt), RayCluster(cpus=1):
            pass
        assert signal.getsignal(signal.SIGTERM) is interrupt
    assert shutdowns == [True, True]  # what Ray had started is stopped either way


def test_smoke_end_to_end_on_embedded_ray(tmp_path: Path) -> None:
    from pecli.experiment import RayCluster

    experiment = load_experiment("smoke")
    out = tmp_path / "smoke"
    assert not ray_processes()
    with RayCluster(cpus=2) as cluster:
        assert cluster.total_cpus() == 2
        first = ExperimentRunner(experiment, out)
        report = first.run(cluster)
        again = ExperimentRunner(experiment, out)
        again.run(cluster)
    assert (first.session.runs_started, first.session.runs_skipped, first.session.pairings_cached) == (2, 0, 0)
    played = first.session.pairings_played
    assert played == cached_pairings(out) > 0
    assert (again.session.runs_started, again.session.runs_resumed, again.session.runs_skipped) == (0, 0, 2)
    assert (again.session.pairings_played, again.session.pairings_cached) == (0, played)
    text = report.read_text()
    assert "| evader \\ pursuer | Pure Pursuit | MADDPG | Ours |" in text
    assert "| Greedy | " in text and "| Ours | " in text and "†" in text  # 20 episodes < the paper's 1500
    data = json.loads((out / "report.json").read_text())
    cell = next(c for c in data["cells"] if (c["pursuer"], c["evader"]) == ("Ours", "Greedy"))
    assert cell["paper_capture_rate"] == 0.98 and cell["fewer_episodes_than_paper"]
    assert abs(cell["difference"] - (cell["capture_rate"] - 0.98)) < 1e-3
    assert "| rating | ± se | exploitability |" in text  # within the tournament's meta-game, every player met all
    assert all(0.0 <= r["exploitability"] <= 1.0 for r in data["ratings"])
    assert (out / "table.png").stat().st_size > 1000 and (out / "tournament" / "results.json").is_file()
    assert len(json.loads((out / "experiment.json").read_text())["sessions"]) == 2
    result = runner.invoke(app, ["experiment", "status", str(out)])
    assert result.exit_code == 0 and "2/2 runs done" in result.output and "tournament: done" in result.output
    other = experiment_from_dict({**SMOKE, "name": "smoke"}, "other")
    with pytest.raises(PecliError, match="holds experiment 'smoke' with other settings"):
        ExperimentRunner(other, out).prepare()
    time.sleep(1)
    assert not ray_processes()  # embedded Ray left nothing behind


def test_killed_driver_resumes_on_a_two_node_cluster(tmp_path: Path) -> None:
    from ray.cluster_utils import Cluster

    from pecli.experiment import RayCluster

    experiment = load_experiment("smoke")
    out = tmp_path / "smoke"
    driver = subprocess.Popen(
        [sys.executable, "-m", "pecli", "experiment", "run", "smoke", "--cpus", "2", "--out", str(out), "-q"],
        start_new_session=True,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    try:
        deadline = time.monotonic() + 240
        while not any(run_progress(run, out / "zoo").done for run in experiment.runs()):
            assert driver.poll() is None and time.monotonic() < deadline
            time.sleep(0.5)
        driver.send_signal(signal.SIGKILL)  # the driver alone, as the OOM killer would
        driver.wait()
        time.sleep(2)
        assert not [line for line in ray_processes(driver.pid) if "raylet" in line or "gcs_server" in line]
        workers = [json.loads(marker.read_text())["pid"] for marker in (out / "tasks").glob("*.json")]
        deadline = time.monotonic() + 10
        while any(alive(pid) for pid in workers):  # and so did the workers that ran the runs
            assert time.monotonic() < deadline
            time.sleep(0.5)
    finally:
        try:
            os.killpg(driver.pid, signal.SIGKILL)  # Ray's agents, which take ~90 s to notice on their own
        except ProcessLookupError:
            pass
    done = {
        run.name: (out / "zoo" / run.name / SELFPLAY_STATE).read_bytes()
        for run in experiment.runs()
        if run_progress(run, out / "zoo").done
    }
    cached = cached_pairings(out)

    cluster = Cluster(initialize_head=True, head_node_args={"num_cpus": 1, "object_store_memory": 80 * 1024**2})
    try:
        cluster.add_node(num_cpus=1, object_store_memory=80 * 1024**2)
        cluster.wait_for_nodes()
        with RayCluster(address=cluster.address) as joined:
            assert joined.nodes() == 2 and joined.total_cpus() == 2
            resumed = ExperimentRunner(experiment, out)
            resumed.run(joined)
    finally:
        cluster.shutdown()
    session = resumed.session
    assert session.runs_skipped == len(done) >= 1
    assert session.runs_started + session.runs_resumed == 2 - len(done)
    assert session.pairings_cached == cached and session.pairings_played == cached_pairings(out) - cached > 0
    for name, state in done.items():  # finished runs were not touched
        assert (out / "zoo" / name / SELFPLAY_STATE).read_bytes() == state
        assert (out / "zoo" / name / "command.txt").read_text().count("\n") == 1
    assert (out / "report.md").is_file()


def test_status_counts_the_pairings_a_stopped_stage_has_played(tmp_path: Path) -> None:
    from pecli.experiment.folder import stage_lines

    state = {
        "stages": {"ranking": {"pairings": 5, "status": "done"}, "tournament": {"pairings": 4, "status": "running"}}
    }
    cache = tmp_path / "tournament" / "pairings"
    cache.mkdir(parents=True)
    for i in range(3):
        (cache / f"{i}.json").write_text("{}")
    assert stage_lines(tmp_path, state, alive=False) == [
        "ranking: done, 5 pairings",
        "tournament: stopped, 3/4 pairings played",
    ]
    assert stage_lines(tmp_path, state, alive=True)[1] == "tournament: running, 3/4 pairings played"


def test_embedded_ray_starts_without_its_token_notice(monkeypatch: pytest.MonkeyPatch) -> None:
    """Starting Ray drops its notice that token authentication is on (its default), and only that: its other
    warnings pass; nothing of Ray's output is forwarded and no dashboard is started."""
    import logging

    from pecli.experiment import ray_executor

    started: list[dict] = []

    def init(**options: object) -> None:  # Ray's start, as far as its logging goes
        started.append(options)
        notices = logging.getLogger(ray_executor.TOKEN_LOGGER)
        notices.warning("Token authentication is enabled for this Ray cluster. Set RAY_AUTH_MODE=disabled to opt out.")
        notices.warning("Token authentication is disabled for this Ray cluster. Anyone with network access ...")

    monkeypatch.setattr(ray_executor.ray, "is_initialized", lambda: False)
    monkeypatch.setattr(ray_executor.ray, "init", init)
    monkeypatch.setattr(ray_executor.ray, "shutdown", lambda: None)
    monkeypatch.setenv(ray_executor.WORKER_NICENESS, "0")
    shown: list[str] = []
    handler = logging.Handler()
    handler.emit = lambda record: shown.append(record.getMessage()[:41])  # type: ignore[method-assign]
    logging.getLogger(ray_executor.TOKEN_LOGGER).addHandler(handler)  # Ray's loggers do not reach the root's
    try:
        with ray_executor.RayCluster(cpus=1), ray_executor.RayCluster(cpus=1):
            pass
    finally:
        logging.getLogger(ray_executor.TOKEN_LOGGER).removeHandler(handler)
    assert shown == 2 * ["Token authentication is disabled for this"]
    assert all(options["log_to_driver"] is False and options["include_dashboard"] is False for options in started)


def test_a_cluster_address_where_nothing_answers_is_refused_at_once() -> None:
    import socket

    from pecli.experiment.ray_executor import _check_reachable

    with socket.socket() as listening:
        listening.bind(("127.0.0.1", 0))
        listening.listen()
        _check_reachable(f"127.0.0.1:{listening.getsockname()[1]}")  # a head that answers
        _check_reachable("auto")  # left to Ray
    with socket.socket() as closed:
        closed.bind(("127.0.0.1", 0))
        port = closed.getsockname()[1]
    with pytest.raises(PecliError, match=f"cannot join the Ray cluster at ray://127.0.0.1:{port}: nothing answers"):
        _check_reachable(f"ray://127.0.0.1:{port}")
    with pytest.raises(PecliError, match="the port must be from 1 to 65535"):
        _check_reachable("127.0.0.1:99999999999999999999")
    with pytest.raises(PecliError, match="no host 'no-such-host.invalid'"):
        _check_reachable("no-such-host.invalid:6379")


@pytest.mark.parametrize(
    ("state", "message"),
    [
        ({"driver": "x"}, "driver: Input should be a valid dictionary"),
        ({"driver": {"pid": 10**30}}, "driver.pid: Input should be less than or equal to"),
        ({"runs": [1]}, "runs: Input should be a valid dictionary"),
        ({"sessions": [{"until_cpu_hours": "x"}]}, "sessions.0.until_cpu_hours: Input should be a valid number"),
        ({"stages": [1]}, "stages: Input should be a valid dictionary"),
        ([1], r"damaged experiment record \(not a JSON object\)"),
    ],
)
def test_a_damaged_experiment_record_is_one_line(tmp_path: Path, state: object, message: str) -> None:
    (tmp_path / "experiment.yaml").write_text(yaml.safe_dump(load_experiment("smoke").spec.model_dump(mode="json")))
    (tmp_path / "experiment.json").write_text(json.dumps(state))
    result = runner.invoke(app, ["experiment", "status", str(tmp_path)])
    assert result.exit_code == 1 and re.search(message, result.output), result.output
    assert result.output.strip().count("\n") == 0
