"""``pecli tune``: a small study runs, reports to the pruner, persists, resumes (also after a killed trial),
runs trials in parallel processes and reports; bad search spaces are refused in one line."""

from __future__ import annotations

import os
import time
from pathlib import Path

import optuna
import pytest
import yaml
from typer.testing import CliRunner

from pecli.cli import app
from pecli.rl import tune
from pecli.rl.search_space import load_space, parse_space
from pecli.scenario import Scenario, load_scenario

runner = CliRunner()
pytestmark = pytest.mark.usefixtures("keep_torch_threads")
SMALL = {
    "fixed": {"steps": 5000, "learning_starts": 100, "buffer_size": 2000, "batch_size": 32, "n_envs": 4},
    "parameters": {
        "algo": {"type": "categorical", "choices": ["td3", "sac"]},
        "learning_rate": {"type": "float", "low": 1e-4, "high": 1e-3, "log": True},
        "action_noise": {"type": "float", "low": 0.05, "high": 0.3, "algos": ["td3"]},
        "net_width": {"type": "categorical", "choices": [16, 32]},
    },
}
FAST = ["--cpu-minutes", "0.01", "--evaluations", "2", "--eval-episodes", "4"]


def write_space(folder: Path, data: object) -> Path:
    path = folder / "space.yaml"
    path.write_text(data if isinstance(data, str) else yaml.safe_dump(data))
    return path


def finished(study: optuna.Study) -> list[optuna.trial.FrozenTrial]:
    states = (optuna.trial.TrialState.COMPLETE, optuna.trial.TrialState.PRUNED)
    return study.get_trials(states=states)


@pytest.mark.filterwarnings("ignore:Heartbeat of storage")
def test_a_study_runs_persists_resumes_after_a_kill_in_parallel_and_reports(tmp_path: Path, monkeypatch) -> None:
    monkeypatch.setattr(tune, "HEARTBEAT_S", 1)
    monkeypatch.setattr(tune, "GRACE_S", 1)
    space = write_space(tmp_path, SMALL)
    folder = tmp_path / "tune"
    result = runner.invoke(
        app, ["tune", "pursuer", "-c", "quick", "--space", str(space), "--trials", "2", "--dir", str(folder), *FAST]
    )
    assert result.exit_code == 0, result.output
    storage = tune.open_storage(tune.sqlite_url(folder / "studies.db"))
    study = optuna.load_study(study_name="quick-pursuer", storage=storage)
    trials = finished(study)
    assert len(trials) == 2
    baseline = trials[0]  # the config's own settings, where the space can express them
    assert baseline.user_attrs["baseline"] and baseline.params["algo"] == "td3"
    assert baseline.params["learning_rate"] == 5e-4 and baseline.params["action_noise"] == 0.1
    for trial in trials:  # both evaluations reached Optuna; the last is the score
        assert sorted(trial.intermediate_values) == [1, 2] and trial.value == trial.intermediate_values[2]
        assert trial.user_attrs["overrides"]["net_arch"] in ([16, 16], [32, 32])
        assert ("action_noise" in trial.params) == (trial.params["algo"] == "td3")
    result = runner.invoke(app, ["tune", "pursuer", "--study", "quick-pursuer", "--trials", "2", "--dir", str(folder)])
    assert result.exit_code == 1 and "continue it with --resume" in result.output
    result = runner.invoke(
        app, ["tune", "pursuer", "--study", "quick-pursuer", "--resume", "--cpu-minutes", "1", "--dir", str(folder)]
    )
    assert result.exit_code == 1 and "keeps its settings (not --cpu-minutes)" in result.output
    result = runner.invoke(app, ["tune", "pursuer", "--study", "quick-pursuer", "--resume", "--dir", str(folder)])
    assert result.exit_code == 0 and "2 trials of" in result.output  # its own number, not the default 30
    assert len(finished(study)) == 2

    killed = study.ask({"algo": optuna.distributions.CategoricalDistribution(["td3", "sac"])})  # its process died
    storage.record_heartbeat(killed._trial_id)
    time.sleep(2.5)
    result = runner.invoke(
        app,
        [
            "tune",
            "pursuer",
            "--study",
            "quick-pursuer",
            "--resume",
            "--trials",
            "4",
            "--jobs",
            "2",
            "--dir",
            str(folder),
        ],
    )
    assert result.exit_code == 0, result.output
    trials = optuna.load_study(study_name="quick-pursuer", storage=storage).get_trials()
    assert len(finished(study)) >= 4  # two processes may overshoot by one
    assert trials[killed.number].state == optuna.trial.TrialState.FAIL  # run again with the same settings:
    retried = [t for t in trials if t.system_attrs.get("failed_trial") == killed.number]
    assert len(retried) == 1 and retried[0].params["algo"] == killed.params["algo"]
    assert retried[0].state in (optuna.trial.TrialState.COMPLETE, optuna.trial.TrialState.PRUNED)

    result = runner.invoke(
        app, ["tune", "report", "quick-pursuer", "--dir", str(folder), "--profile", str(tmp_path / "tuned.yaml")]
    )
    assert result.exit_code == 0, result.output
    assert "Best trials" in result.output
    assert {"report.md", "space.yaml", "history.png", "intermediate.png"} <= {
        p.name for p in (folder / "quick-pursuer").iterdir()
    }
    assert yaml.safe_load((folder / "quick-pursuer" / "space.yaml").read_text()) == SMALL
    profile = load_scenario(str(tmp_path / "tuned.yaml"))
    best = optuna.load_study(study_name="quick-pursuer", storage=storage).best_trial
    assert profile.name == "tuned" and profile.training.algo == best.params["algo"]
    assert profile.training.learning_rate == pytest.approx(best.params["learning_rate"])
    assert profile.fingerprint() == load_scenario("quick").fingerprint()  # the same game


def settings(quick: Scenario, what: str = "pursuer", **changes: object) -> tune.TuneSettings:
    values = {
        "what": what,
        "scenario": quick.model_dump(mode="json"),
        "space": SMALL,
        "opponent": None if what == "selfplay" else "greedy",
        "eval_opponents": [] if what == "selfplay" else ["greedy"],
        "cpu_minutes": 0.01,
        "evaluations": 2,
        "eval_episodes": 4,
    }
    return tune.TuneSettings(**{**values, **changes})


def test_evaluations_reach_the_pruner(quick: Scenario, tmp_path: Path) -> None:
    study = optuna.create_study(direction="maximize", pruner=optuna.pruners.ThresholdPruner(lower=1.5))
    study.optimize(tune.Objective(settings(quick), tmp_path), n_trials=1)
    trial = study.trials[0]
    assert trial.state == optuna.trial.TrialState.PRUNED and list(trial.intermediate_values) == [1]


def test_a_trial_with_repeats_trains_on_each_seed_and_scores_their_mean(
    quick: Scenario, tmp_path: Path, monkeypatch
) -> None:
    seeds: list[int] = []
    train = tune.Objective._one_role

    def recorded(self, trial, scenario, seed, clock, report):  # type: ignore[no-untyped-def]
        seeds.append(seed)
        return train(self, trial, scenario, seed, clock, report)

    monkeypatch.setattr(tune.Objective, "_one_role", recorded)
    study = optuna.create_study(direction="maximize")
    study.optimize(tune.Objective(settings(quick, repeats=3, seed=10), tmp_path), n_trials=2)
    assert seeds == [10, 11, 12, 13, 14, 15]  # trial n trains on seed + 3n + i: no seed is used twice
    for trial in study.trials:
        scores = trial.user_attrs["scores"]
        assert trial.state == optuna.trial.TrialState.COMPLETE and len(scores) == 3
        assert sorted(trial.intermediate_values) == [1, 2, 3, 4, 5, 6]  # run i's evaluation k is step 2i + k
        assert trial.value == pytest.approx(sum(scores) / 3) == pytest.approx(trial.intermediate_values[6])
        assert trial.intermediate_values[4] == pytest.approx((scores[0] + scores[1]) / 2)  # the running mean


@pytest.mark.parametrize(
    "option, value, message",
    [
        ("--repeats", "0", "--repeats must be positive, not 0"),
        ("--evaluations", "0", "--evaluations must be positive, not 0"),
        ("--eval-episodes", "0", "--eval-episodes must be positive, not 0"),
        ("--cpu-minutes", "0", "--cpu-minutes must be in (0, 100000], not 0"),
        ("--cpu-minutes", "nan", "--cpu-minutes must be in (0, 100000], not nan"),
    ],
)
def test_zero_budgets_are_refused_not_taken_for_the_default(
    tmp_path: Path, option: str, value: str, message: str
) -> None:
    result = runner.invoke(app, ["tune", "pursuer", "-c", "quick", option, value, "--dir", str(tmp_path)])
    assert result.exit_code == 1 and message in result.output, result.output
    assert not (tmp_path / "studies.db").exists()


def test_a_trial_stopped_by_ctrl_c_leaves_no_report_but_a_failed_one_does(caplog) -> None:
    import logging
    from unittest import mock

    import pecli.rl.tune  # noqa: F401  (attaches the filter)

    study = optuna.create_study(direction="maximize")
    with caplog.at_level(logging.WARNING, logger="optuna"):
        study.optimize(lambda trial: (_ for _ in ()).throw(RuntimeError("diverged")), n_trials=1, catch=(RuntimeError,))
        with (
            mock.patch.object(optuna.Trial, "suggest_float", side_effect=KeyboardInterrupt),
            pytest.raises(KeyboardInterrupt),
        ):
            study.optimize(lambda trial: trial.suggest_float("x", 0, 1), n_trials=1)
    lines = [record.getMessage() for record in caplog.records]
    assert any("Trial 0 failed" in line and "diverged" in line for line in lines)  # a real failure is reported
    assert not any(line.startswith("Trial 1 ") for line in lines), lines  # an interrupted trial is not


def test_a_selfplay_runs_reports_take_one_step_per_round_so_the_next_run_never_reuses_them(quick: Scenario) -> None:
    """A self-play run evaluates after each round, more often than --evaluations when it has more rounds:
    the next run's steps start after its rounds (Optuna ignores a second value at a step)."""
    space = {**SMALL, "fixed": {**SMALL["fixed"], "selfplay.rounds": 4}}
    objective = tune.Objective(settings(quick, "selfplay", space=space, repeats=2, evaluations=2), Path("."))
    runs: list[list[float]] = [[0.2, 0.4, 0.6, 0.8], [0.1, 0.3]]  # 4 rounds, then a run stopped by the budget

    def selfplay(trial, scenario, seed, clock, report):  # type: ignore[no-untyped-def]
        values = runs.pop(0)
        for k, value in enumerate(values, 1):
            report(k, value)
        return values[-1]

    objective._selfplay = selfplay  # type: ignore[method-assign]
    study = optuna.create_study(direction="maximize")
    study.optimize(objective, n_trials=1)
    steps = study.trials[0].intermediate_values
    assert steps == pytest.approx(
        {1: 0.2, 2: 0.4, 3: 0.6, 4: 0.8, 5: 0.45, 6: 0.55}
    )  # run 2 from step 5, mean with 0.8
    assert study.trials[0].value == pytest.approx(0.55)


def test_repeats_are_kept_on_resume(tmp_path: Path) -> None:
    result = runner.invoke(
        app, ["tune", "pursuer", "--study", "x", "--resume", "--repeats", "2", "--dir", str(tmp_path)]
    )
    assert result.exit_code == 1 and "keeps its settings (not --repeats)" in result.output, result.output


def test_a_selfplay_trial_scores_both_sides_after_each_round(quick: Scenario, tmp_path: Path) -> None:
    space = {
        "fixed": {**SMALL["fixed"], "selfplay.rounds": 1, "selfplay.steps_per_round": 200, "curriculum.enabled": False},
        "parameters": {"learning_rate": SMALL["parameters"]["learning_rate"]},
    }
    study = optuna.create_study(direction="maximize")
    study.optimize(tune.Objective(settings(quick, "selfplay", space=space, eval_episodes=2), tmp_path), n_trials=1)
    trial = study.trials[0]
    assert trial.state == optuna.trial.TrialState.COMPLETE and list(trial.intermediate_values) == [1]
    assert 0.0 <= trial.value <= 1.0
    assert not any(tmp_path.iterdir())  # the trial's self-play run is scratch


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("parameters: {foo: {type: float, low: 0, high: 1}}", "'foo' is not a training setting"),
        (
            "parameters: {learning_rate: {type: float, low: 0, high: 1, log: true}}",
            "log-scaled parameter needs low > 0",
        ),
        ("parameters: {learning_rate: {type: float, low: 1}}", "needs low < high"),
        ("parameters: {learning_rate: {type: flot, low: 1, high: 2}}", "parameters.learning_rate.type"),
        ("parameters: {algo: {type: categorical, choices: [td3, ppo]}}", "parameters.algo = 'ppo'"),
        ("parameters: {batch_size: {type: int, low: 0, high: 8}}", "parameters.batch_size = 0"),
        ("parameters: {tau: {type: float, low: 0.1, high: 0.2, algos: [ppo]}}", "parameters.tau.algos"),
        ("parameters: {}", "parameters"),
        ("[1, 2]", "a search space is a mapping"),
        ("parameters: [", "not valid YAML"),
        (
            "parameters: {tau: {type: float, low: 0.1, high: 0.2}, tau: {type: float, low: 0.1, high: 0.3}}",
            "duplicate key 'tau'",
        ),
        ("parameters: {tau: {type: float, low: true, high: 0.2}}", "a bound is a number"),
    ],
)
def test_bad_search_spaces_are_refused_in_one_line(tmp_path: Path, text: str, message: str) -> None:
    space = write_space(tmp_path, text)
    folder = tmp_path / "tune"
    result = runner.invoke(app, ["tune", "pursuer", "-c", "quick", "--space", str(space), "--dir", str(folder)])
    assert result.exit_code == 1, result.output
    assert len(result.output.strip().splitlines()) == 1 and message in result.output, result.output
    assert not folder.exists()


def test_the_default_search_space_is_valid_for_every_builtin_config() -> None:
    for name in ("paper", "quick", "car_vs_car", "point_mass", "robots"):
        space, text = load_space(None, load_scenario(name))
        assert "algo" in space.parameters and text.startswith("#")
    result = runner.invoke(app, ["tune", "space"])
    assert result.exit_code == 0 and parse_space(yaml.safe_load(result.output), "printed").parameters


def test_a_trial_whose_process_is_gone_is_failed_and_queued_again_at_once(tmp_path: Path) -> None:
    import socket
    import subprocess
    import sys

    storage = tune.open_storage(tune.sqlite_url(tmp_path / "studies.db"))
    study = optuna.create_study(study_name="s", storage=storage, direction="maximize")
    gone = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True)
    dead_pid = int(gone.stdout)  # a process that has ended
    algo = {"algo": optuna.distributions.CategoricalDistribution(["td3", "sac"])}
    dead = study.ask(algo)
    dead.set_user_attr(tune.WORKER_ATTR, {"host": socket.gethostname(), "pid": dead_pid})
    alive = study.ask(algo)  # run by a live process (this one's parent), or on another machine
    alive.set_user_attr(tune.WORKER_ATTR, {"host": socket.gethostname(), "pid": os.getppid()})
    elsewhere = study.ask(algo)
    elsewhere.set_user_attr(tune.WORKER_ATTR, {"host": "another-machine", "pid": dead_pid})
    assert tune.reclaim_dead_trials(study) == [dead.number]
    trials = study.get_trials()
    assert trials[dead.number].state == optuna.trial.TrialState.FAIL
    assert trials[alive.number].state == trials[elsewhere.number].state == optuna.trial.TrialState.RUNNING
    again = [t for t in trials if t.system_attrs.get("failed_trial") == dead.number]
    assert len(again) == 1 and again[0].state == optuna.trial.TrialState.WAITING
    assert again[0].params["algo"] == dead.params["algo"]
    assert tune.reclaim_dead_trials(study) == []  # once


def test_tune_selfplay_offers_no_frozen_opponent_and_a_bad_count_is_named(tmp_path: Path) -> None:
    assert "--opponent" not in runner.invoke(app, ["tune", "selfplay", "--help"]).output
    assert "--opponent" in runner.invoke(app, ["tune", "pursuer", "--help"]).output
    refused = runner.invoke(app, ["tune", "selfplay", "-c", "quick", "--opponent", "greedy", "--dir", str(tmp_path)])
    assert refused.exit_code == 2 and "No such option" in refused.output
    jobs = runner.invoke(app, ["tune", "pursuer", "-c", "quick", "--jobs", "0", "--dir", str(tmp_path)])
    assert jobs.exit_code == 1 and "--jobs must be at least 1, not 0" in jobs.output, jobs.output
