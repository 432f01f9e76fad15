"""The simultaneous schedule (the paper's MADDPG): both learners in the same games, both learning every step."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
import torch as th

from pecli.rl import durable as durable_module
from pecli.rl import schedules as schedules_module
from pecli.rl.selfplay import SelfPlay, SelfPlayInterrupted, SelfPlayJob, read_state
from pecli.rl.train import with_overrides
from pecli.scenario import Scenario
from pecli.zoo import read_metadata
from wrappers.simultaneous import SimultaneousGame

TINY = {
    "buffer_size": 2000,
    "batch_size": 32,
    "learning_starts": 100,
    "net_arch": [16, 16],
    "n_envs": 4,
    "checkpoint_every": 4,
    "selfplay.rounds": 2,
    "selfplay.steps_per_round": 320,
    "selfplay.schedule": "simultaneous",
}
BIMDN = {
    "belief": "bimdn",
    "belief_settings.hidden": 8,
    "belief_settings.fc": 8,
    "belief_settings.buffer_size": 400,
    "belief_settings.warmup": 40,
    "belief_settings.batch_size": 16,
    "belief_settings.update_every": 2,
}


def job(quick: Scenario, zoo: Path, **overrides) -> SelfPlayJob:
    return SelfPlayJob(with_overrides(quick, {**TINY, **overrides}), zoo, "sim", seed=3, progress=False)


def committed(run: Path, role: str) -> tuple[dict, dict[str, np.ndarray]]:
    """A learner's durable record and its replay rows, oldest first."""
    directory = run / role / "resume"
    record = json.loads((directory / "state.json").read_text())
    rows: dict[str, dict[int, np.ndarray]] = {}
    for chunk in record["replay"]["chunks"]:  # consecutive files share a row: the newer one's copy counts
        with np.load(directory / chunk["file"]) as data:
            for key in data.files:
                rows.setdefault(key, {}).update(zip(range(chunk["start"], chunk["end"]), data[key]))
    return record, {key: np.stack([by_row[i] for i in sorted(by_row)]) for key, by_row in rows.items()}


def test_the_faces_step_the_same_games_once_both_have_acted(quick: Scenario) -> None:
    games = SimultaneousGame(quick, n=3, seed=0)
    first = {role: face.reset() for role, face in games.faces.items()}
    assert np.array_equal(first["pursuer"]["state"], first["evader"]["state"])  # one set of games
    games.faces["pursuer"].step_async(np.ones((3, 2)))
    with pytest.raises(RuntimeError, match="both faces must step_async"):
        games.faces["pursuer"].step_wait()
    games.faces["evader"].step_async(-np.ones((3, 2)))
    (p_obs, p_reward, p_done, _), (e_obs, e_reward, e_done, _) = (
        games.faces[r].step_wait() for r in ("pursuer", "evader")
    )
    assert np.array_equal(p_reward, -e_reward) and np.array_equal(p_done, e_done)  # zero-sum, the same games
    assert games.game.t[0] == quick.training.frame_skip  # both held their actions for frame_skip steps
    again = games.faces["pursuer"].reset()  # a new reset, not the old games
    assert not np.array_equal(again["state"], p_obs["state"])


@pytest.mark.parametrize("belief", ["none", "bimdn"])
def test_both_learners_learn_from_the_same_steps(quick: Scenario, tmp_path: Path, belief: str) -> None:
    lines: list[str] = []
    SelfPlay(job(quick, tmp_path, **(BIMDN if belief == "bimdn" else {})), report=lines.append).run()
    run = tmp_path / "sim"
    assert len(lines) == 2 and "pursuer captures" in lines[1]
    turns = read_state(type("R", (), {"path": run, "name": "sim"})()).turns
    assert [(t.round, t.role, t.steps) for t in turns] == [
        (1, "pursuer", 320),
        (1, "evader", 320),
        (2, "pursuer", 640),
        (2, "evader", 640),
    ]
    for role, other in (("pursuer", "evader"), ("evader", "pursuer")):
        meta = read_metadata(run / role / "round-002.zip")
        assert meta.opponent == "selfplay:simultaneous" and meta.parent == f"{role}/round-001.zip"
        assert meta.opponents[0]["name"] == f"{other}-learner"
    (_, pursuer), (_, evader) = committed(run, "pursuer"), committed(run, "evader")
    # the critic of each learner reads what the other did at that step: MADDPG's centralised critic
    assert np.array_equal(pursuer["obs.opp_action"], evader["actions"])
    assert np.array_equal(evader["obs.opp_action"], pursuer["actions"])
    assert np.array_equal(pursuer["rewards"], -evader["rewards"]) and np.abs(pursuer["actions"]).sum() > 0
    cut = 320 // TINY["n_envs"] - 1  # round 1's last row: round 2 started new games
    assert np.all(pursuer["dones"][cut] == 1)  # returns stop there
    cut_short = np.any(pursuer["next_obs.opp_action"][cut] != 0, axis=-1)  # games still on, not ended there
    assert cut_short.any() and np.all(pursuer["timeouts"][cut][cut_short] == 1)  # a truncation: still bootstraps
    ended = pursuer["dones"].astype(bool)
    ended[cut] = False
    assert np.all(pursuer["next_obs.opp_action"][ended] == 0)  # nothing follows an episode's end


def test_a_round_stopped_inside_resumes_there_the_same_way_twice(quick: Scenario, tmp_path: Path, monkeypatch) -> None:
    calls = {"n": 0}
    original = schedules_module.learn_simultaneously

    def interrupted(models, steps, callbacks):
        calls["n"] += 1
        if calls["n"] == 2:  # round 2, part way

            class Stop(schedules_module.EpisodeStats):
                def _on_step(self) -> bool:
                    if self.num_timesteps > 480:
                        raise KeyboardInterrupt
                    return True

            callbacks["evader"].append(Stop())
        return original(models, steps, callbacks)

    monkeypatch.setattr(schedules_module, "learn_simultaneously", interrupted)
    with pytest.raises(SelfPlayInterrupted):
        SelfPlay(job(quick, tmp_path)).run()
    monkeypatch.undo()
    run = tmp_path / "sim"
    record, _ = committed(run, "pursuer")
    assert record["extra"]["round"] == 2 and 320 < record["steps"] < 640
    shutil.copytree(run, tmp_path / "copy" / "sim")
    for zoo in (tmp_path, tmp_path / "copy"):
        resumed = job(quick, zoo)
        resumed.resume = True
        SelfPlay(resumed).run()
    for role in ("pursuer", "evader"):
        ours, theirs = (
            th.cat([p.flatten() for p in _policy(zoo / "sim" / role / "round-002.zip")])
            for zoo in (tmp_path, tmp_path / "copy")
        )
        assert th.equal(ours, theirs)
        assert read_metadata(run / role / "round-002.zip").steps == 640


def _policy(path: Path) -> list[th.Tensor]:
    from pecli.models.checkpoint import read_weights

    return list(read_weights(path)[0]["policy"].values())


def test_a_stop_while_committing_counts_the_rounds_cpu_once(quick: Scenario, tmp_path: Path, monkeypatch) -> None:
    ticks = iter(range(1, 1000))  # a CPU clock that advances one second per reading
    monkeypatch.setattr(
        schedules_module, "time", type("Clock", (), {"process_time": staticmethod(lambda: next(ticks))})
    )
    original = durable_module.DurableState.save

    def stopped_once(self, *args, **kwargs):  # Ctrl-C lands while the evader's state is being written
        if self.directory.parent.name == "evader" and not getattr(stopped_once, "done", False):
            stopped_once.done = True
            raise KeyboardInterrupt
        return original(self, *args, **kwargs)

    monkeypatch.setattr(durable_module.DurableState, "save", stopped_once)
    with pytest.raises(SelfPlayInterrupted):
        SelfPlay(job(quick, tmp_path)).run()
    spent = next(ticks) - 2  # the clock's last reading (by the commit after the stop) less its first (round start)
    counted = sum(committed(tmp_path / "sim", role)[0]["extra"]["cpu_seconds"] for role in ("pursuer", "evader"))
    assert counted == pytest.approx(spent)
