"""Alternating self-play: mixed opponents, pools and their draws, the zoo layout and lineage, resume."""

from __future__ import annotations

import json
import math
import re
import shutil
import sys
from pathlib import Path
from unittest import mock

import numpy as np
import pytest
import torch as th
from typer.testing import CliRunner

from pecli.cli import app
from pecli.policies.heuristics import Greedy
from pecli.policies.mixed import MixedPolicy
from pecli.rl import schedules as schedules_module
from pecli.rl.pool import OpponentPool, predicted_win_rate
from pecli.rl.selfplay import SelfPlay, SelfPlayInterrupted, SelfPlayJob, read_state
from pecli.rl.train import with_overrides
from pecli.scenario import Scenario
from pecli.zoo import read_metadata
from wrappers.frozen_opponent import FrozenOpponentVecEnv

runner = CliRunner()
TINY = {
    "buffer_size": 2000,
    "batch_size": 32,
    "learning_starts": 100,
    "net_arch": [16, 16],
    "n_envs": 4,
    "selfplay.rounds": 2,
    "selfplay.steps_per_round": 240,
}


def invoke(*args: str):
    with mock.patch.object(sys, "argv", ["pecli", *args]):
        return runner.invoke(app, list(args))


class Constant:
    """A pursuer that always plays ``value``."""

    def __init__(self, value: float) -> None:
        self.role, self.value, self.resets = "pursuer", value, []

    def reset(self, n: int, mask: np.ndarray | None = None, seed: int | None = None) -> None:
        self.resets.append(None if mask is None else np.flatnonzero(mask).tolist())

    def act(self, obs: np.ndarray) -> np.ndarray:
        return np.full((len(obs), 2), self.value)


# -- mixed opponents ---------------------------------------------------------------------------
def test_each_game_is_played_by_the_member_drawn_for_it() -> None:
    mixed = MixedPolicy("pursuer", [Constant(-0.5), Constant(0.5)], ["a", "b"])
    mixed.reset(64, seed=3)
    actions = mixed.act(np.zeros((64, 11)))
    expected = np.where(mixed.assignment == 0, -0.5, 0.5)
    assert np.array_equal(actions[:, 0], expected) and set(mixed.game_labels) == {"a", "b"}


def test_draws_follow_the_weights_and_the_seed() -> None:
    def draws(seed: int) -> np.ndarray:
        mixed = MixedPolicy("pursuer", [Constant(0), Constant(1), Constant(2)], ["a", "b", "c"], weights=[6, 3, 1])
        mixed.reset(20_000, seed=seed)
        return mixed.assignment.copy()

    first = draws(1)
    assert np.array_equal(first, draws(1)) and not np.array_equal(first, draws(2))
    assert np.allclose(np.bincount(first) / first.size, [0.6, 0.3, 0.1], atol=0.015)


def test_a_restart_redraws_only_the_restarted_games_and_tells_their_new_member() -> None:
    members = [Constant(0), Constant(1)]
    mixed = MixedPolicy("pursuer", members, ["a", "b"], weights=[1, 0])
    mixed.reset(6, seed=0)
    assert (mixed.assignment == 0).all()
    mixed.weights = [0, 1]
    mask = np.array([False, True, False, False, True, False])
    mixed.reset(6, mask=mask)
    assert mixed.assignment.tolist() == [0, 1, 0, 0, 1, 0]
    assert members[1].resets[-1] == [1, 4]


def test_mixed_policies_refuse_bad_members_and_weights(quick: Scenario) -> None:
    with pytest.raises(ValueError, match="must play pursuer"):
        MixedPolicy("pursuer", [Greedy(quick, "evader")], ["g"])
    with pytest.raises(ValueError, match="weights"):
        MixedPolicy("pursuer", [Constant(0)], ["a"], weights=[-1])


def test_the_training_view_names_the_opponent_of_each_finished_game(quick: Scenario) -> None:
    mixed = MixedPolicy("evader", [Greedy(quick, "evader")], ["greedy"])
    env = FrozenOpponentVecEnv(quick, "pursuer", mixed, n=4, seed=0, history=False)
    env.reset()
    seen = []
    for _ in range(200):
        _, _, dones, infos = env.step(np.zeros((4, 2)))
        seen += [info["opponent"] for info in infos if "captured" in info]
    assert seen and set(seen) == {"greedy"}


# -- pools -------------------------------------------------------------------------------------
def pool() -> OpponentPool:
    p = OpponentPool("evader")
    p.add("greedy", "greedy", 0)
    p.add("rash", "rash", 0)
    p.add("evader-r001", "evader/round-001.zip", 1)
    return p


def test_latest_uniform_and_unknown_strategies() -> None:
    p = pool()
    assert p.weights("latest").tolist() == [0, 0, 1]
    assert np.allclose(p.weights("uniform"), 1 / 3)
    baselines = OpponentPool("evader")
    baselines.add("greedy", "greedy", 0)
    baselines.add("rash", "rash", 0)
    assert np.allclose(baselines.weights("latest"), 0.5)  # the baselines are one generation
    with pytest.raises(ValueError, match="unknown opponent sampling"):
        p.weights("best")


def test_pfsp_favours_the_opponents_that_win() -> None:
    p = pool()
    assert np.allclose(p.weights("pfsp"), 1 / 3)  # no records: the prior 0.5 for everyone
    for _ in range(30):
        p.observe("greedy", entry_won=False)
        p.observe("rash", entry_won=True)
    w = p.weights("pfsp", power=2, prior_episodes=10)
    assert w[1] > w[2] > w[0] > 0  # rash wins, the new one is unknown, greedy always loses but is not starved
    assert math.isclose(w.sum(), 1)
    p.decay(0.5)
    assert p.entry("rash").episodes == 15 and p.entry("rash").wins == 15


def test_pfsp_priors_come_from_ratings() -> None:
    assert math.isclose(predicted_win_rate(1500, 1500), 0.5)
    assert predicted_win_rate(1700, 1500) > 0.75
    w = pool().weights("pfsp", priors={"greedy": 0.9, "rash": 0.1, "evader-r001": 0.5})
    assert w[0] > w[2] > w[1]


def test_pools_round_trip_through_json() -> None:
    p = pool()
    p.observe("rash", True)
    assert OpponentPool.from_dict(json.loads(json.dumps(p.to_dict()))) == p


# -- the loop ----------------------------------------------------------------------------------
def job(quick: Scenario, zoo: Path, name: str, **overrides) -> SelfPlayJob:
    return SelfPlayJob(with_overrides(quick, {**TINY, **overrides}), zoo, name, seed=1, progress=False)


@pytest.fixture(scope="module")
def finished(quick: Scenario, tmp_path_factory) -> tuple[Path, list[str]]:
    zoo = tmp_path_factory.mktemp("zoo")
    lines: list[str] = []
    SelfPlay(job(quick, zoo, "sp"), report=lines.append).run()
    return zoo / "sp", lines


def test_a_tiny_self_play_writes_rounds_with_their_lineage(finished: tuple[Path, list[str]]) -> None:
    run, lines = finished
    for role in ("pursuer", "evader"):
        for r in (1, 2):
            assert (run / role / f"round-00{r}.zip").is_file()
        state = json.loads((run / role / "resume" / "state.json").read_text())  # the learner's durable state
        assert state["extra"]["round"] == 2 and state["replay"]["added"] > 0
    assert len(lines) == 2 and lines[0].startswith("round 1/2: pursuer captures")
    p1, e1, p2 = (
        read_metadata(run / path) for path in ("pursuer/round-001.zip", "evader/round-001.zip", "pursuer/round-002.zip")
    )
    assert (p1.round, p1.parent, p2.round, p2.parent) == (1, "", 2, "pursuer/round-001.zip")
    assert [o["name"] for o in p1.opponents] == ["greedy", "random-walk", "rash"]  # the baselines
    assert [o["name"] for o in e1.opponents] == ["pure-pursuit", "random-walk", "pursuer-r001"]  # already the new one
    assert [o["name"] for o in p2.opponents][-1] == "evader-r001"
    assert sum(o["episodes"] for o in p1.opponents) == p1.episodes > 0
    assert p2.episodes == p1.episodes + sum(o["episodes"] for o in p2.opponents)  # cumulative, like steps
    assert p2.steps == 2 * p1.steps == 2 * 240  # one learner for the whole run
    assert p1.opponent == "selfplay:pfsp"
    state = read_state(type("R", (), {"path": run, "name": "sp"})())
    assert [(t.round, t.role) for t in state.turns] == [(1, "pursuer"), (1, "evader"), (2, "pursuer"), (2, "evader")]


def test_runs_play_as_one_uniform_mixture(finished: tuple[Path, list[str]], quick: Scenario, tmp_path: Path) -> None:
    from pecli.policies import resolve_policy, stored_scenario

    run, _ = finished
    other = tmp_path / "at@2" / "other"  # an @ inside a path is no weight
    shutil.copytree(run, other)
    mixture = resolve_policy(f"mix:{run},{other}", "pursuer", quick, seed=0)
    assert isinstance(mixture, MixedPolicy) and mixture.names == [str(run), str(other)]
    assert mixture.weights.tolist() == [0.5, 0.5]
    swapped = resolve_policy(f"mix:{other} , {run}", "pursuer", quick, seed=0)
    assert swapped.identity == mixture.identity  # a tournament's cache knows the mixture by its members' content
    assert stored_scenario(f"mix:{run},{other}").fingerprint() == quick.fingerprint()
    played = invoke("play", "-p", f"mix:{run},{other}", "-e", f"mix:{run}/evader/average.zip,greedy", "-n", "8")
    assert played.exit_code == 0, played.output
    weighed = resolve_policy(f"mix:{run}@3,{other}", "pursuer", quick, seed=0)  # drawn in 3 games of 4
    assert weighed.weights.tolist() == [0.75, 0.25] and weighed.identity != mixture.identity
    assert resolve_policy(f"mix:{other}@0.5, {run}@1.5", "pursuer", quick, seed=0).identity == weighed.identity
    assert resolve_policy(f"mix:{run}@2,{other}@2", "pursuer", quick, seed=0).identity == mixture.identity
    copied = tmp_path / "run@3"  # a folder whose name ends in @3 is that folder, not a weight
    shutil.copytree(run, copied)
    assert resolve_policy(f"mix:{run},{copied}", "pursuer", quick, seed=0).names == [str(run), str(copied)]


@pytest.mark.parametrize(
    "members, message",
    [
        ("", "separated by commas"),
        ("{run},", "separated by commas"),
        ("{run},{run}", "twice"),
        ("{run}@2,{run}", "twice"),
        ("{run}@0,greedy", "must lie between"),
        ("{run}@nan,greedy", "must lie between"),
        ("{run}@1e-9,greedy", "must lie between"),
        ("{run}@two,greedy", "must be a number"),
        ("@2,{run}", "before the @"),
        ("{run},nash:x", "does not nest"),
        ("{run}/..", "cannot play pursuer"),
        ("{run}/pursuer/nothere.zip", "not there"),
        ("{run},os:system", "imports no code"),
        ("{run},greedy", "plays evader"),
    ],
)
def test_a_bad_mixture_is_refused_in_one_line(
    finished: tuple[Path, list[str]], quick: Scenario, members: str, message: str
) -> None:
    from pecli.errors import PolicyError
    from pecli.policies import resolve_policy

    run, _ = finished
    with pytest.raises(PolicyError, match=message):
        resolve_policy("mix:" + members.format(run=run), "pursuer", quick, seed=0)


def parameters(path: Path) -> th.Tensor:
    from stable_baselines3 import TD3

    return th.cat([p.flatten() for p in TD3.load(path).policy.parameters()])


def test_a_run_hands_over_the_mean_of_its_last_rounds(quick: Scenario, tmp_path: Path) -> None:
    SelfPlay(job(quick, tmp_path, "sp", **{"curriculum.enabled": False})).run()  # 2 rounds, no curriculum: both
    run = tmp_path / "sp"
    for role in ("pursuer", "evader"):
        rounds = [run / role / f"round-00{r}.zip" for r in (1, 2)]
        meta = read_metadata(run / role / "average.zip")
        assert meta.averaged == [str(path) for path in rounds]
        assert (meta.role, meta.round) == (role, 2)
        mean = (parameters(rounds[0]) + parameters(rounds[1])) / 2
        assert th.allclose(parameters(run / role / "average.zip"), mean, atol=1e-6)
        assert not th.allclose(mean, parameters(rounds[1]))  # the rounds differ: the mean is not the last one


def test_rounds_begun_in_the_curriculum_are_not_averaged(quick: Scenario, tmp_path: Path) -> None:
    # quick's curriculum spans 30 % of each learner's planned transitions: 216 of 3 x 240, inside round 1 only
    SelfPlay(job(quick, tmp_path, "sp", **{"selfplay.rounds": 3, "selfplay.average_last": 3})).run()
    for role in ("pursuer", "evader"):
        averaged = read_metadata(tmp_path / "sp" / role / "average.zip").averaged
        assert averaged == [str(tmp_path / "sp" / role / f"round-00{r}.zip") for r in (2, 3)]
        shown = invoke("zoo", "rounds", str(tmp_path / "sp"), role)  # the same rounds as one mixed player
        assert shown.exit_code == 0 and shown.stdout.strip() == "mix:" + ",".join(averaged)
        weighed = invoke("zoo", "rounds", str(tmp_path / "sp"), role, "--weight", "3")  # 3 shared by the 2 rounds
        assert weighed.stdout.strip() == "mix:" + ",".join(f"{path}@1.5" for path in averaged)
    assert "must lie between" in invoke("zoo", "rounds", str(tmp_path / "sp"), role, "--weight", "0").output
    played = invoke("play", "-p", shown.stdout.strip().replace("evader", "pursuer"), "-e", shown.stdout.strip())
    assert played.exit_code == 0, played.output
    refused = invoke("zoo", "rounds", str(tmp_path / "sp" / "pursuer"), "pursuer")
    assert refused.exit_code == 1 and "is not a self-play run (no selfplay.json)" in refused.output
    with mock.patch("pecli.policies.mix.MAX_MEMBERS", 1):  # a mixture pecli would refuse is not printed
        refused = invoke("zoo", "rounds", str(tmp_path / "sp"), "pursuer")
    assert refused.exit_code == 1 and "mix: takes at most 1 players, got 2" in refused.output
    outside = tmp_path / "elsewhere.zip"
    (tmp_path / "sp" / "pursuer" / "round-003.zip").rename(outside)
    (tmp_path / "sp" / "pursuer" / "round-003.zip").symlink_to(outside)  # a stranger's run, linking out of itself
    refused = invoke("zoo", "rounds", str(tmp_path / "sp"), "pursuer")
    assert refused.exit_code == 1 and "round-003.zip leads out of the run" in refused.output


@pytest.mark.parametrize("last", [0, 1])
def test_the_average_spans_average_last_rounds_and_catches_up_on_resume(
    quick: Scenario, tmp_path: Path, last: int
) -> None:
    SelfPlay(job(quick, tmp_path, "sp", **{"selfplay.average_last": last})).run()
    average = tmp_path / "sp" / "pursuer" / "average.zip"
    if last == 0:
        assert not average.exists()
        shown = invoke("zoo", "rounds", str(tmp_path / "sp"), "pursuer")
        assert shown.exit_code == 1 and "hands over no average (its selfplay.average_last is 0)" in shown.output
        return
    assert read_metadata(average).averaged == [str(tmp_path / "sp" / "pursuer" / "round-002.zip")]
    assert th.equal(parameters(average), parameters(tmp_path / "sp" / "pursuer" / "round-002.zip"))
    average.unlink()  # as if stopped after round 2 was recorded, before its average was written
    shown = invoke("zoo", "rounds", str(tmp_path / "sp"), "pursuer")
    assert shown.exit_code == 0 and "average.zip is not yet the mean of these rounds" in shown.stderr
    resumed = job(quick, tmp_path, "sp", **{"selfplay.average_last": last})
    resumed.resume = True
    loop = SelfPlay(resumed)
    loop.run()  # nothing left to train: only the averages are written
    assert loop.averages() == {role: tmp_path / "sp" / role / "average.zip" for role in ("pursuer", "evader")}
    assert read_metadata(average).averaged == [str(tmp_path / "sp" / "pursuer" / "round-002.zip")]


BIMDN = {
    "belief": "bimdn",
    "belief_settings.hidden": 8,
    "belief_settings.fc": 8,
    "belief_settings.buffer_size": 400,
    "belief_settings.warmup": 40,
    "belief_settings.batch_size": 16,
    "belief_settings.update_every": 2,
}


@pytest.mark.parametrize("case", ["mid-curriculum", "bimdn", "commit-window"])
def test_an_interrupted_run_resumes_inside_its_turn(quick: Scenario, tmp_path: Path, monkeypatch, case: str) -> None:
    """Stopped while the evader trains in round 2 (the curriculum still running, or a learned belief): the
    turn goes on from the commit made at the stop, the same way from a copy of it. Stopped after the
    pursuer's round-2 state was committed but before selfplay.json named the turn: nothing is trained
    again, and the run ends exactly as if never stopped."""
    settings = {"curriculum.fraction": 1.0, **(BIMDN if case == "bimdn" else {})}
    SelfPlay(job(quick, tmp_path / "ref", "sp", **settings)).run()
    reference = tmp_path / "ref" / "sp"
    if case == "commit-window":
        original_save = SelfPlay.save_state

        def stop_before_commit(self: SelfPlay) -> None:
            if len(self.state.turns) == 3:  # (2, pursuer) is written but not yet committed
                raise KeyboardInterrupt
            original_save(self)

        monkeypatch.setattr(SelfPlay, "save_state", stop_before_commit)
        expected = (2, "pursuer")
    else:
        started: list[str] = []

        class Interrupting(schedules_module.PoolTracker):
            def _on_step(self) -> bool:
                if self.pool.role == "pursuer" and started.count("evader") == 2 and self.num_timesteps > 300:
                    raise KeyboardInterrupt  # round 2, while the evader trains
                return super()._on_step()

            def _on_training_start(self) -> None:
                started.append("evader" if self.pool.role == "pursuer" else "pursuer")

        monkeypatch.setattr(schedules_module, "PoolTracker", Interrupting)
        expected = (2, "evader")
    with pytest.raises(SelfPlayInterrupted) as stop:
        SelfPlay(job(quick, tmp_path, "sp", **settings)).run()
    assert (stop.value.round, stop.value.role) == expected
    assert not (tmp_path / "sp" / "evader" / "round-002.zip").exists()
    monkeypatch.undo()
    if case != "commit-window":
        committed = json.loads((tmp_path / "sp" / "evader" / "resume" / "state.json").read_text())
        assert committed["extra"]["round"] == 2 and committed["steps"] > committed["extra"]["start_steps"]  # kept
        shutil.copytree(tmp_path / "sp", tmp_path / "copy" / "sp")

    for zoo in [tmp_path] + ([tmp_path / "copy"] if case != "commit-window" else []):
        resumed = job(quick, zoo, "sp", **settings)
        resumed.resume = True
        SelfPlay(resumed).run()
    for role in ("pursuer", "evader"):
        final = read_metadata(tmp_path / "sp" / role / "round-002.zip")
        assert final.steps == read_metadata(reference / role / "round-002.zip").steps  # the budget, not more
        if case == "commit-window":
            assert th.equal(
                parameters(tmp_path / "sp" / role / "round-002.zip"), parameters(reference / role / "round-002.zip")
            )
        else:  # reproducible from the commit
            assert th.equal(
                parameters(tmp_path / "sp" / role / "round-002.zip"),
                parameters(tmp_path / "copy" / "sp" / role / "round-002.zip"),
            )
    turns = read_state(type("R", (), {"path": tmp_path / "sp", "name": "sp"})()).turns
    assert [(t.round, t.role) for t in turns] == [(1, "pursuer"), (1, "evader"), (2, "pursuer"), (2, "evader")]


def test_pfsp_priors_come_from_the_zoos_tournament_by_role(finished: tuple[Path, list[str]]) -> None:
    run, _ = finished
    resumed = SelfPlayJob(read_config(run), run.parent, run.name, seed=1, resume=True, progress=False)
    loop = SelfPlay(resumed)
    ratings = [
        {"name": "p2", "role": "pursuer", "spec": str(run / "pursuer" / "round-002.zip"), "elo": 1600.0, "stderr": 1},
        {"name": "rw", "role": "evader", "spec": "random-walk", "elo": 1200.0, "stderr": 1},  # the evader random-walk
        {"name": "g", "role": "evader", "spec": "greedy", "elo": 1800.0, "stderr": 1},
    ]
    (run.parent / "tournament").mkdir(exist_ok=True)
    results = {"episodes_per_seed": 4, "seeds": [0], "pairings": [], "ratings": ratings}
    (run.parent / "tournament" / "results.json").write_text(json.dumps(results))
    priors = loop.opponents.priors("pursuer", loop.state)
    assert priors["greedy"] == pytest.approx(predicted_win_rate(1800, 1600)) and priors["greedy"] > 0.5
    assert priors["random-walk"] == pytest.approx(predicted_win_rate(1200, 1600))
    assert "random-walk" not in loop.opponents.priors("evader", loop.state)  # a pursuer random-walk was never rated
    (run.parent / "tournament" / "results.json").unlink()


def read_config(run: Path) -> Scenario:
    from pecli.zoo import Run

    return Run(run).scenario()


def test_the_curriculum_spans_the_first_rounds_for_both_learners(quick: Scenario, tmp_path: Path) -> None:
    knobs: list[tuple[float, ...]] = []
    loop = SelfPlay(job(quick, tmp_path, "sp", **{"curriculum.fraction": 1.0}))
    games = lambda: [loop.learners[role].env.core.game for role in ("pursuer", "evader")]  # noqa: E731
    loop.report = lambda line: knobs.append(
        tuple(x for g in games() for x in (g.fov["pursuer"], g.speed_scale["evader"]))
    )
    loop.run()
    final = quick.pursuer.sensor.fov
    half = 2 * math.pi + (final - 2 * math.pi) * 0.5
    assert knobs[0] == pytest.approx((half, 0.5, half, 0.5), rel=0.02)  # halfway after round 1, in both games
    assert knobs[1] == pytest.approx((final, 1.0, final, 1.0))


# -- the command -------------------------------------------------------------------------------
def test_the_command_runs_and_refuses_what_it_cannot_do(tmp_path: Path) -> None:
    args = [
        "selfplay",
        "-c",
        "quick",
        "--zoo",
        str(tmp_path),
        "--name",
        "cli",
        "--rounds",
        "1",
        "--steps-per-round",
        "120",
        "--opponents",
        "uniform",
        "-q",
        *[x for key, value in TINY.items() if not key.startswith("selfplay") for x in ("--set", f"{key}={value}")],
    ]
    result = invoke(*args)
    assert result.exit_code == 0, result.output
    assert "round 1/1" in result.output and (tmp_path / "cli" / "evader" / "round-001.zip").is_file()
    assert f"to hand over: {tmp_path / 'cli' / 'pursuer' / 'average.zip'} (its last round)" in result.output.replace(
        "\n", ""
    )
    assert "already exists" in invoke(*args).output
    common = ["selfplay", "--zoo", str(tmp_path), "--resume", "-q"]
    result = invoke(*common, "--name", "cli", "--opponents", "pfsp")
    assert result.exit_code == 1 and "only --rounds can change" in result.output
    result = invoke(*common, "--name", "nope")
    assert result.exit_code == 1 and "no run 'nope'" in result.output
    for bad in ("abc", "null", "true"):  # refused as a setting, not compared with the rounds played
        result = invoke(*common, "--name", "cli", "--set", f"selfplay.rounds={bad}")
        assert result.exit_code == 1 and "selfplay.rounds" in result.output and "internal" not in result.output
    result = invoke(*common)
    assert result.exit_code == 1 and "--resume needs the --name" in result.output
    (tmp_path / "cli" / "selfplay.json").write_text("{")
    result = invoke(*common, "--name", "cli")
    assert result.exit_code == 1 and "damaged self-play state" in result.output
    (tmp_path / "cli" / "selfplay.json").unlink()
    result = invoke(*common, "--name", "cli")
    assert result.exit_code == 1 and "not a self-play run" in result.output


def test_a_cpu_budget_stops_the_run_and_the_run_keeps_it(tmp_path: Path) -> None:
    args = [
        "selfplay",
        "-c",
        "quick",
        "--zoo",
        str(tmp_path),
        "--name",
        "cpu",
        "--rounds",
        "3",
        "--steps-per-round",
        "120",
        "-q",
        *[x for key, value in TINY.items() if not key.startswith("selfplay") for x in ("--set", f"{key}={value}")],
    ]
    state_file = tmp_path / "cpu" / "selfplay.json"
    result = invoke(*args, "--cpu-hours", "1e-9")  # any round reaches it
    assert result.exit_code == 0, result.output
    assert "or 1e-09 CPU-h, whichever comes first, on quick" in result.output
    assert re.search(r"round 1/3: .* CPU-s; run [0-9.]+ of 0\.00000\d+ CPU-s\)", result.output)  # what is used
    assert re.search(r"budget reached: [0-9.]+ of 0\.00000\d+ CPU-s after round 1", result.output)
    assert "round 2/3" not in result.output
    assert "to hand over" in result.output and json.loads(state_file.read_text())["cpu_hours"] == 1e-9
    resume = ["selfplay", "--zoo", str(tmp_path), "--name", "cpu", "--resume", "-q"]
    (tmp_path / "cpu" / "pursuer" / "average.zip").unlink()  # as if stopped before writing it
    result = invoke(*resume)  # the run keeps its budget
    assert result.exit_code == 0, result.output
    assert (tmp_path / "cpu" / "pursuer" / "average.zip").is_file()  # caught up, with nothing trained
    assert (
        "nothing to train: a larger --cpu-hours continues the run" in result.output and "to hand over" in result.output
    )
    assert not (tmp_path / "cpu" / "pursuer" / "round-002.zip").exists()
    result = invoke(*resume, "--cpu-hours", "1000")  # a new budget replaces it: on to the ceiling of rounds
    assert result.exit_code == 0 and "round 3/3" in result.output and "budget reached" not in result.output
    assert re.search(r"or 1000 CPU-h \([0-9.]+ CPU-s used\)", result.output)
    assert json.loads(state_file.read_text())["cpu_hours"] == 1000
    result = invoke(*resume)
    assert "nothing to train: a larger --rounds continues the run" in result.output
    assert max(t["round"] for t in json.loads(state_file.read_text())["turns"]) == 3
    for bad in ("0", "-1", "nan", "inf", "20000"):
        result = invoke(*resume, "--cpu-hours", bad)
        assert (
            result.exit_code == 1
            and "--cpu-hours must be a number of hours above 0 and at most 10,000" in result.output
        )


def test_a_diverging_self_play_stops_without_writing_its_round(tmp_path: Path) -> None:
    sets = {**{k: v for k, v in TINY.items() if not k.startswith("selfplay")}, "learning_rate": "1e30"}
    result = invoke(
        "selfplay",
        "-c",
        "quick",
        "--zoo",
        str(tmp_path),
        "--name",
        "nan",
        "--rounds",
        "1",
        "--steps-per-round",
        "400",
        "-q",
        *[x for k, v in sets.items() for x in ("--set", f"{k}={v}")],
    )
    assert result.exit_code == 1 and "training diverged at step" in result.output, result.output
    assert not list((tmp_path / "nan").rglob("*.zip"))


def test_what_each_run_hands_over_is_listed_by_name(finished: tuple[Path, list[str]]) -> None:
    from pecli.experiment.compare import handed_over

    run, _ = finished
    found = handed_over(run.parent)
    assert list(found) == ["sp"] and found["sp"].round == 2 and found["sp"].cpu_hours > 0
    assert found["sp"].pursuer == run / "pursuer" / "average.zip" and found["sp"].evader.is_file()


def test_experiment_compare_plays_a_run_against_its_fork(finished: tuple[Path, list[str]], tmp_path: Path) -> None:
    run, _ = finished
    fork = CliRunner().invoke(app, ["zoo", "fork", str(run), "--to", str(tmp_path / "arm")])
    assert fork.exit_code == 0, fork.output
    result = CliRunner().invoke(
        app,
        [
            "experiment",
            "compare",
            "--arms",
            f"control={run.parent}",
            "--arms",
            f"forked={tmp_path / 'arm'}",
            "-n",
            "4",
            "--workers",
            "1",
            "--out",
            str(tmp_path / "cmp"),
        ],
    )
    assert result.exit_code == 0, result.output
    rows = [
        line for line in result.stdout.splitlines() if line.startswith("| control |") or line.startswith("| forked")
    ]
    assert len(rows) == 2 and all("| sp | 2 |" in row for row in rows)
    assert rows[0].split("|")[4:8] == rows[1].split("|")[4:8]  # the same weights: one player, the same games
    assert "- forked" in result.stdout and "a paired test needs 2 runs" in result.stdout
    assert "the league recipe's targets" in result.stdout  # a tiny run meets none of them, or says so
    averaged = CliRunner().invoke(
        app,
        ["experiment", "compare", "--arms", f"a={tmp_path / 'arm'}", "--average", "2", "-n", "4", "-w", "1"]
        + ["--out", str(tmp_path / "cmp2")],
    )
    assert averaged.exit_code == 0, averaged.output
    assert sorted(p.name for p in (tmp_path / "arm" / "report" / "average").glob("*.zip")) == [
        "sp-evader-001-002.zip",
        "sp-pursuer-001-002.zip",
    ]


def test_generations_play_every_round_against_every_round(finished: tuple[Path, list[str]], tmp_path: Path) -> None:
    run = tmp_path / "sp"
    shutil.copytree(finished[0], run)
    result = CliRunner().invoke(app, ["zoo", "generations", str(run), "-n", "4", "--json"])
    assert result.exit_code == 0, result.output
    data = json.loads(result.stdout)
    assert data["pursuers"] == ["pure-pursuit", "g1", "g2"] and data["evaders"] == ["greedy", "g1", "g2"]
    assert np.array(data["capture_rates"]).shape == (3, 3)
    assert data["pursuer_progress"] is None  # no evader generation has two pursuer generations after it
    assert data["evader_progress"] in (0.0, 0.5, 1.0)  # the one pair: generations 1 and 2 against pursuer 1
    assert (run / "generations" / "generations.png").is_file()
    for where in (run / "pursuer", tmp_path / "missing"):
        refused = CliRunner().invoke(app, ["zoo", "generations", str(where)])
        assert refused.exit_code == 1 and "is not a run folder" in refused.output, refused.output
    from pecli.rl.generations import generation_checkpoints

    assert [p.stem for p in generation_checkpoints(run, every=2)["evader"]] == ["round-002"]  # the last kept
    for suffix in (".zip", ".json"):  # a round that repeats an earlier one's bytes plays once, as the first
        shutil.copy(run / "pursuer" / f"round-001{suffix}", run / "pursuer" / f"round-003{suffix}")
    again = CliRunner().invoke(app, ["zoo", "generations", str(run), "-n", "4", "--json"])
    assert again.exit_code == 0, again.output
    assert json.loads(again.stdout)["pursuers"] == ["pure-pursuit", "g1", "g2"]


def test_progress_counts_later_generations_beating_older_opponents() -> None:
    from pecli.rl.generations import Generations, progress_share

    assert progress_share(np.array([np.nan, 0.2, 0.5, 0.9]), later_than=0) == 1.0  # every later one does better
    assert progress_share(np.array([np.nan, 0.9, 0.5, 0.2]), later_than=0) == 0.0
    assert progress_share(np.array([np.nan, 0.5, 0.5]), later_than=0) == 0.5  # a tie counts half
    assert math.isnan(progress_share(np.array([np.nan, 0.5]), later_than=0))
    improving = np.array([[0.5, 0.5, 0.5, 0.5], [0.5, 0.2, 0.1, 0.05], [0.5, 0.6, 0.3, 0.2], [0.5, 0.9, 0.7, 0.4]])
    labels = {"pursuer": ["pp", "g1", "g2", "g3"], "evader": ["greedy", "g1", "g2", "g3"]}
    pursuer, evader = Generations(labels, improving, 10).progress()  # type: ignore[arg-type]
    assert pursuer == 1.0 and evader == 1.0  # each generation beats what came before it better than its elders did
