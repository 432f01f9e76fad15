"""End to end with a tiny budget: train, checkpoint, reload, play; resume; Ctrl-C; curriculum; errors."""

from __future__ import annotations

import csv
import json
import math
import sys
from pathlib import Path
from unittest import mock

import numpy as np
import pytest
import torch as th
from typer.testing import CliRunner

from pecli.cli import app
from pecli.errors import PolicyError
from pecli.policies import resolve_policy
from pecli.rl.callbacks import CurriculumCallback, EpisodeStats, Evaluation
from pecli.scenario import Scenario

runner = CliRunner()
TINY = [
    "--set",
    "buffer_size=2000",
    "--set",
    "batch_size=32",
    "--set",
    "learning_starts=100",
    "--set",
    "net_arch=[32, 32]",
    "--set",
    "checkpoint_every=3",
    "--set",
    "n_envs=4",
]


def invoke(args: list[str]):
    """Run the CLI with ``sys.argv`` as a shell would set it (the zoo records the command)."""
    with mock.patch.object(sys, "argv", ["pecli", *args]):
        return runner.invoke(app, args)


def train(zoo: Path, *extra: str):
    return invoke(["train", "pursuer", "-c", "quick", "--zoo", str(zoo), "--name", "run", "-q", *TINY, *extra])


@pytest.fixture(scope="module")
def trained(tmp_path_factory) -> Path:
    zoo = tmp_path_factory.mktemp("zoo")
    result = train(zoo, "--steps", "1200")
    assert result.exit_code == 0, result.output
    return zoo


def test_a_run_writes_the_zoo_layout(trained: Path) -> None:
    run = trained / "run"
    for name in ("config.yaml", "command.txt", "versions.json"):
        assert (run / name).is_file(), name
    assert "pecli" in json.loads((run / "versions.json").read_text())
    assert "train pursuer" in (run / "command.txt").read_text()
    role = run / "pursuer"
    assert (
        (role / "final.zip").is_file() and (role / "last.zip").is_file() and (role / "resume" / "state.json").is_file()
    )
    assert json.loads((run / "run.json").read_text()) == {
        "command": "train",
        "role": "pursuer",
        "opponent": "greedy",
        "seed": 0,
    }
    periodic = sorted(role.glob("ep*.zip"))
    assert periodic, "expected checkpoints every 3 episodes"
    meta = json.loads((role / "final.json").read_text())
    assert meta["role"] == "pursuer" and meta["steps"] == 1200 and meta["algo"] == "td3"
    assert meta["opponent"] == "greedy" and meta["belief"] == "none" and meta["episodes"] >= 3
    first = json.loads(periodic[0].with_suffix(".json").read_text())
    assert first["episodes"] >= 3 and first["steps"] < 1200
    assert not [p for p in role.iterdir() if p.name.startswith(".")]  # no temporaries left


def test_a_checkpoint_plays_as_a_policy(trained: Path, quick: Scenario) -> None:
    final = trained / "run" / "pursuer" / "final.zip"
    result = runner.invoke(app, ["play", "-p", str(final), "-c", "quick", "-n", "20", "--json"])
    assert result.exit_code == 0, result.output
    assert json.loads(result.stdout)["episodes"] == 20
    policy = resolve_policy(str(final), "pursuer", quick)
    policy.reset(3)
    actions = policy.act(np.zeros((3, 11), dtype=np.float32))
    assert actions.shape == (3, 2) and np.all(np.abs(actions) <= 1)


def test_a_checkpoint_refuses_another_scenario_or_role(trained: Path, paper: Scenario, quick: Scenario) -> None:
    final = str(trained / "run" / "pursuer" / "final.zip")
    with pytest.raises(
        PolicyError,
        match="trained on 'quick', which differs from 'paper' in arena.height 8.0 there, "
        "16.0 here; arena.width 8.0 there, 16.0 here; horizon 150 there, 400 here:",
    ):
        resolve_policy(final, "pursuer", paper)
    longer = quick.model_copy(update={"horizon": 200})  # the same name, another game: say what differs
    with pytest.raises(
        PolicyError, match="trained on 'quick', which differs from 'quick' in horizon 150 there, 200 here:"
    ):
        resolve_policy(final, "pursuer", longer)
    copy = Path(final).parent.parent.parent / "loose.zip"  # no run config beside it: names and fingerprints
    copy.write_bytes(Path(final).read_bytes())
    copy.with_suffix(".json").write_text(Path(final).with_suffix(".json").read_text())
    with pytest.raises(
        PolicyError, match=r"trained on scenario 'quick' \(fingerprint \w+\), another game than 'quick'"
    ):
        resolve_policy(str(copy), "pursuer", longer)
    with pytest.raises(PolicyError, match="is a pursuer checkpoint; it cannot play evader"):
        resolve_policy(final, "evader", quick)


def test_damaged_checkpoints_give_clear_errors(trained: Path, tmp_path: Path, quick: Scenario) -> None:
    source = trained / "run" / "pursuer" / "final.zip"
    truncated = tmp_path / "truncated.zip"
    truncated.write_bytes(source.read_bytes()[:500])
    truncated.with_suffix(".json").write_text(source.with_suffix(".json").read_text())
    with pytest.raises(PolicyError, match=r"truncated.zip: not a checkpoint \(damaged or not a zip file\)"):
        resolve_policy(str(truncated), "pursuer", quick)
    orphan = tmp_path / "orphan.zip"
    orphan.write_bytes(source.read_bytes())
    with pytest.raises(PolicyError, match="no metadata file orphan.json"):
        resolve_policy(str(orphan), "pursuer", quick)
    result = runner.invoke(app, ["play", "-p", str(truncated), "-c", "quick"])
    assert result.exit_code == 1 and "Traceback" not in result.output


def test_resume_continues_the_run(trained: Path, monkeypatch) -> None:
    before = json.loads((trained / "run" / "pursuer" / "last.json").read_text())["cpu_seconds"]
    assert before > 0
    clock = iter([100.0])  # the resumed call starts at 100 CPU-s of its process, then has spent 2.5
    monkeypatch.setattr("pecli.rl.train.process_cpu_seconds", lambda: next(clock, 102.5))
    result = invoke(["train", "pursuer", "--zoo", str(trained), "--name", "run", "--resume", "--steps", "1500", "-q"])
    assert result.exit_code == 0, result.output
    meta = json.loads((trained / "run" / "pursuer" / "final.json").read_text())
    assert meta["steps"] == 1500
    assert meta["cpu_seconds"] == pytest.approx(before + 2.5)  # the run's CPU time goes on from where it stopped
    assert (trained / "run" / "command.txt").read_text().count("train pursuer") == 2


def test_resume_keeps_the_opponent_seed_and_settings(trained: Path) -> None:
    base = ["train", "pursuer", "--zoo", str(trained), "--name", "run", "--resume", "-q"]
    for extra, message in (
        (["--opponent", "rash"], "trains with --opponent greedy; a resumed run keeps it"),
        (["--seed", "4"], "trains with --seed 0"),
        (["--set", "batch_size=64"], "only --steps can change when resuming (not batch_size)"),
    ):
        result = invoke([*base, *extra])
        assert result.exit_code == 1 and message in result.output, result.output


def test_overrides_are_read_as_yaml() -> None:
    from pecli.rl.train import parse_overrides

    assert parse_overrides(["steps=1e4", "learning_rate=3e-4", "curriculum.enabled=false", "net_arch=[64, 64]"]) == {
        "steps": 10000,
        "learning_rate": 3e-4,
        "curriculum.enabled": False,
        "net_arch": [64, 64],
    }


def test_an_existing_run_needs_resume(trained: Path) -> None:
    result = train(trained, "--steps", "200")
    assert result.exit_code == 1 and "already exists" in result.output
    missing = runner.invoke(app, ["train", "pursuer", "--zoo", str(trained), "--name", "nope", "--resume"])
    assert missing.exit_code == 1 and "no run 'nope'" in missing.output


def test_ctrl_c_saves_a_resumable_checkpoint(tmp_path: Path, monkeypatch) -> None:
    calls = {"n": 0}
    original = EpisodeStats._on_step

    def interrupt(self) -> bool:
        calls["n"] += 1
        if calls["n"] == 150:
            raise KeyboardInterrupt
        return original(self)

    monkeypatch.setattr(EpisodeStats, "_on_step", interrupt)
    result = train(tmp_path, "--steps", "5000")
    assert result.exit_code == 130
    assert "--resume --name run" in result.output
    role = tmp_path / "run" / "pursuer"
    state = json.loads((role / "resume" / "state.json").read_text())
    assert 0 < json.loads((role / "last.json").read_text())["steps"] == state["steps"] < 5000
    assert state["replay"]["added"] > 0  # the buffer is part of the saved state


def test_bad_settings_are_refused(tmp_path: Path) -> None:
    result = train(tmp_path, "--set", "batch_size=-3")
    assert result.exit_code == 1 and "batch_size" in result.output
    result = train(tmp_path, "--set", "nonsense")
    assert result.exit_code == 1 and "KEY=VALUE" in result.output
    result = runner.invoke(app, ["train", "pursuer", "--opponent", "pure-pursuit", "--zoo", str(tmp_path), "-q"])
    assert result.exit_code == 1 and "plays pursuer, not evader" in result.output
    assert not (tmp_path / "run").exists()  # a run that could not start leaves no folder behind
    blocked = tmp_path / "file"
    blocked.write_text("not a folder")
    result = runner.invoke(app, ["train", "pursuer", "-c", "quick", "--zoo", str(blocked), "--name", "x", "-q", *TINY])
    assert result.exit_code == 1 and "cannot create the run folder" in result.output


class _FakeModel:
    """Just enough of an SB3 model for a callback: an env that records calls, and a logger."""

    def __init__(self) -> None:
        self.calls: list[tuple] = []
        self.logger = type("Logger", (), {"record": lambda *args, **kwargs: None})()

    def get_env(self):
        return self

    def env_method(self, name: str, *args):
        self.calls.append((name, *args))


def test_curriculum_schedule(paper: Scenario) -> None:
    callback = CurriculumCallback(paper, paper.training.curriculum.span(1000))
    env = callback.model = _FakeModel()  # type: ignore[assignment]
    for steps, fov, scale in (
        (0, 2 * math.pi, 0.0),
        (150, (2 * math.pi + 2 * math.pi / 3) / 2, 0.5),
        (300, 2 * math.pi / 3, 1.0),
        (900, 2 * math.pi / 3, 1.0),
    ):
        callback.num_timesteps = steps
        callback._apply()
        name, got_fov, got_scale = env.calls[-1]
        assert name == "set_curriculum"
        assert got_fov == pytest.approx(fov) and got_scale == pytest.approx(scale)


def test_a_curriculum_of_fixed_steps_ignores_the_budget(paper: Scenario) -> None:
    """``curriculum.steps`` spans that many transitions whatever the planned budget (a CPU-budgeted run's
    ceiling), where ``fraction`` stretches with it."""
    from pecli.rl.train import with_overrides

    fixed = with_overrides(paper, {"curriculum.steps": 400}).training.curriculum
    assert [fixed.span(budget) for budget in (1_000, 10**7)] == [400.0, 400.0]
    assert [paper.training.curriculum.span(budget) for budget in (1_000, 10**7)] == [300.0, 3e6]
    callback = CurriculumCallback(paper, fixed.span(10**7))
    env = callback.model = _FakeModel()  # type: ignore[assignment]
    callback.num_timesteps = 400
    callback._apply()
    assert env.calls[-1][1:] == (pytest.approx(2 * math.pi / 3), pytest.approx(1.0))


def test_evaluations_log_and_keep_the_best_checkpoint(tmp_path: Path) -> None:
    result = invoke(
        [
            "train",
            "pursuer",
            "-c",
            "quick",
            "--zoo",
            str(tmp_path),
            "--name",
            "run",
            "-q",
            *TINY,
            "--steps",
            "1200",
            "--set",
            "eval_every=300",
            "--set",
            "eval_episodes=10",
        ]
    )
    assert result.exit_code == 0, result.output
    rows = list(csv.DictReader((tmp_path / "run" / "eval_pursuer.csv").open()))
    assert [int(row["steps"]) for row in rows] == [300, 600, 900, 1200]
    cpu = [float(row["cpu_seconds"]) for row in rows]
    assert cpu == sorted(cpu) and cpu[0] > 0
    rates = [float(row["capture_rate"]) for row in rows]
    best = json.loads((tmp_path / "run" / "pursuer" / "best.json").read_text())
    assert best["eval_capture_rate"] == pytest.approx(max(rates))
    assert best["steps"] == int(rows[rates.index(max(rates))]["steps"])  # the first evaluation that reached it


@pytest.mark.parametrize("maximise, saved", [(True, [0.5, 0.6]), (False, [0.2, 0.1])])
def test_the_best_evaluation_depends_on_the_role(tmp_path: Path, maximise: bool, saved: list[float]) -> None:
    path = tmp_path / "eval.csv"
    path.write_text("steps,cpu_seconds,wall_seconds,capture_rate\n10,1.0,1.0,0.3000\n")  # a resumed run's log
    rates = iter([0.2, 0.5, 0.4, 0.1, 0.6])
    best: list[float] = []
    callback = Evaluation(lambda model: next(rates), every=1, csv_path=path, on_best=best.append, maximise=maximise)
    callback.num_timesteps, callback.model = 20, mock.Mock()  # the model only serves the logger here
    callback._on_training_start()
    for _ in range(5):
        callback.record()
    assert best == saved  # each better than the log's 0.3 and than every earlier one


def test_the_same_seed_trains_the_same_weights(tmp_path: Path) -> None:
    """Training is bit-reproducible on one thread: the same command twice gives the same networks."""
    from pecli.models.checkpoint import read_weights

    for zoo in ("a", "b"):
        assert train(tmp_path / zoo, "--steps", "600").exit_code == 0
    ours, theirs = (read_weights(tmp_path / zoo / "run" / "pursuer" / "final.zip")[0] for zoo in ("a", "b"))
    for key, value in ours["policy"].items():
        assert th.equal(value, theirs["policy"][key]), key


def test_a_resumed_run_forgets_evaluations_past_its_commit(tmp_path: Path) -> None:
    from pecli.rl.evaluations import forget_evaluations_after

    log = tmp_path / "eval_pursuer.csv"
    log.write_text(
        "steps,cpu_seconds,wall_seconds,capture_rate\n100,1.0,1.0,0.3000\n200,2.0,2.0,0.5000\n300,3.0,3.0,0.6\n30"
    )
    forget_evaluations_after(log, 200)  # evaluated at 300 after the commit at 200, then killed mid-line
    assert log.read_text() == "steps,cpu_seconds,wall_seconds,capture_rate\n100,1.0,1.0,0.3000\n200,2.0,2.0,0.5000\n"


def test_an_evaluation_log_is_read_row_by_row_and_only_whole_rows(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    from pecli.rl import evaluations
    from pecli.rl.evaluations import Evaluated, append_evaluation, read_evaluations, start_log

    log = tmp_path / "eval_pursuer.csv"
    start_log(log)
    append_evaluation(log, 100, 1.0, 1.5, 0.25)
    with log.open("a") as handle:  # what a stranger's file, or a kill, can leave
        handle.write("200,nan,2,0.5\n300,3,3,1.5\n-4,1,1,0.5\nx,1,1,0.5\n500,5,5\n600,6,6,0.75\n70")
    assert read_evaluations(log) == [Evaluated(100, 1.0, 1.5, 0.25), Evaluated(600, 6.0, 6.0, 0.75)]
    (tmp_path / "link.csv").symlink_to(log)
    assert read_evaluations(tmp_path / "link.csv") == [] and read_evaluations(tmp_path / "none.csv") == []
    assert read_evaluations(tmp_path) == []  # a folder
    with log.open("a") as handle:
        handle.write("\n700,7,7," + "9" * 200_000 + "\n")  # a field past the csv module's limit
    assert read_evaluations(log)[-1] == Evaluated(600, 6.0, 6.0, 0.75)
    log.write_bytes(b"steps,cpu_seconds,wall_seconds,capture_rate\n" + b"1,1,1,0.5\n" * 10)
    monkeypatch.setattr(evaluations, "MAX_LOG_BYTES", 50)
    assert read_evaluations(log) == []  # too large to be a log


# -- a diverged training stops and writes nothing broken ----------------------------------------------------
def test_a_diverging_run_stops_in_one_line_without_a_final_checkpoint(tmp_path: Path) -> None:
    """A learning rate of 1e30 is finite (strict configs take it) but makes the networks NaN within a few updates."""
    result = train(tmp_path, "--steps", "1000", "--set", "learning_rate=1e30")
    assert result.exit_code == 1, result.output
    errors = [line for line in result.output.splitlines() if line.startswith("error:")]
    assert len(errors) == 1 and "training diverged at step" in errors[0] and "loss is nan" in errors[0]
    role = tmp_path / "run" / "pursuer"
    assert not (role / "final.zip").exists() and not (role / "last.zip").exists()


def tiny_model(quick: Scenario, **settings):
    from pecli.rl.train import TrainJob, make_env, make_model, with_overrides

    scenario = with_overrides(quick, {"n_envs": 2, "net_arch": [8], "buffer_size": 500, **settings})
    job = TrainJob(role="pursuer", scenario=scenario, opponent="greedy", zoo=Path("unused"), name="x")
    return make_model(job, make_env(job, resolve_policy("greedy", "evader", scenario), 0), None)


def test_the_finite_check_stops_training_before_later_callbacks_see_a_broken_actor(quick: Scenario) -> None:
    import torch as th
    from stable_baselines3.common.callbacks import BaseCallback, CallbackList

    from pecli.rl.callbacks import FiniteCheck, TrainingDiverged, non_finite_parameters

    class Poison(BaseCallback):
        def __init__(self, at: int, module: str) -> None:
            super().__init__()
            self.at, self.module = at, module

        def _on_step(self) -> bool:
            if self.num_timesteps >= self.at:
                with th.no_grad():
                    next(getattr(self.model.policy, self.module).parameters()).fill_(math.nan)
            return True

    class Saver(BaseCallback):  # stands for the checkpoints and evaluations after the check
        seen: list[int] = []

        def _on_step(self) -> bool:
            self.seen.append(non_finite_parameters(self.model.policy.actor))
            return True

    model = tiny_model(quick, learning_starts=10_000)  # no updates: the parameters themselves are checked
    saver = Saver()
    with pytest.raises(TrainingDiverged, match=r"step 20: 1 actor parameter tensors hold NaN or inf"):
        model.learn(100, callback=CallbackList([Poison(20, "actor"), FiniteCheck(), saver]))
    assert len(saver.seen) == 9 and not any(saver.seen)
    model = tiny_model(quick, learning_starts=10_000)  # a critic is checked when training ends, before any final save
    with pytest.raises(TrainingDiverged, match="parameter tensors of the policy"):
        model.learn(40, callback=CallbackList([Poison(20, "critic"), FiniteCheck()]))


@pytest.mark.parametrize(("kind", "fits"), [("none", None), ("ukf", False), ("bimdn", True)])
def test_make_learner_gives_the_view_its_belief_and_a_fitter_to_a_learned_one(kind: str, fits: bool | None) -> None:
    from pecli.rl.belief import BeliefVecEnv, FitBelief
    from pecli.rl.train import TrainJob, make_learner, with_overrides
    from pecli.scenario import load_scenario

    scenario = with_overrides(load_scenario("quick"), {"belief": kind, "n_envs": 2})
    job = TrainJob(role="pursuer", scenario=scenario, opponent="greedy", zoo=Path("unused"), name="t")
    env, model, fit = make_learner(job, resolve_policy("greedy", "evader", scenario), seed=0)
    if fits is None:
        assert fit is None and not isinstance(env, BeliefVecEnv)
        return
    assert env.belief is model.policy.actor.features_extractor.belief
    assert isinstance(fit, FitBelief) if fits else fit is None
    assert env.reset()["belief"].shape[0] == 2  # the features go into every observation


def test_a_cpu_budget_stops_the_run_and_resumes_keep_or_replace_it(tmp_path: Path, monkeypatch) -> None:
    ticks = iter(range(1_000_000))  # each reading of the process's CPU time is half a second later
    monkeypatch.setattr("pecli.rl.train.process_cpu_seconds", lambda: 0.5 * next(ticks))
    result = train(tmp_path, "--steps", "100000", "--cpu-minutes", "0.1")
    assert result.exit_code == 0 and "or 0.1 CPU-minutes" in result.output, result.output
    meta = json.loads((tmp_path / "run" / "pursuer" / "final.json").read_text())
    assert 0 < meta["steps"] < 1000 and meta["cpu_seconds"] >= 6.0  # stopped by the budget, long before its steps
    assert json.loads((tmp_path / "run" / "run.json").read_text())["cpu_minutes"] == 0.1
    resume = ["train", "pursuer", "--zoo", str(tmp_path), "--name", "run", "--resume", "-q"]
    assert invoke(resume).exit_code == 0  # the run's own budget, already spent: it stops at once
    again = json.loads((tmp_path / "run" / "pursuer" / "final.json").read_text())
    assert again["steps"] - meta["steps"] <= 4  # one vector step of its 4 games at most
    assert invoke([*resume, "--cpu-minutes", "0.2"]).exit_code == 0
    assert json.loads((tmp_path / "run" / "run.json").read_text())["cpu_minutes"] == 0.2
    assert json.loads((tmp_path / "run" / "pursuer" / "final.json").read_text())["steps"] > again["steps"]
    refused = invoke([*resume, "--cpu-minutes", "nan"])
    assert refused.exit_code == 1 and "--cpu-minutes must be in" in refused.output
