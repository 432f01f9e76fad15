"""A self-play run's CPU budget: whole rounds only, exploiters counted, one rule for selfplay and experiments."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from pecli.experiment import load_experiment
from pecli.experiment.runs import SELFPLAY_STATE, run_progress
from pecli.rl.budget import budget_reached, cpu_through, whole_rounds
from pecli.rl.selfplay import SelfPlayState, Turn


def turn(round: int, role: str, cpu: float, learner: str = "main") -> dict:
    return {"round": round, "role": role, "cpu_seconds": cpu, "learner": learner}


WHOLE = [turn(1, "pursuer", 1000), turn(1, "evader", 1000), turn(2, "pursuer", 1000), turn(2, "evader", 1000)]


@pytest.mark.parametrize(("turns", "rounds", "spent", "reached"), [
    ([], 0, 0, False),
    (WHOLE, 2, 4000, True),  # 4000 CPU-s after round 2, over a budget of one hour
    (WHOLE[:3], 1, 2000, False),  # round 2 half-played: its pursuer's 1000 s do not end the run
    (WHOLE[:2] + [turn(1, "evader", 2000, "exploiter")], 1, 4000, True),  # an exploiter's turn counts
    ([turn(2, "pursuer", 9000), turn(2, "evader", 9000)], 0, 0, False),  # rounds count from round 1
])
def test_only_whole_rounds_count(turns: list[dict], rounds: int, spent: float, reached: bool, tmp_path: Path) -> None:
    assert whole_rounds(turns) == rounds and cpu_through(turns, rounds) == spent
    assert budget_reached(turns, 1.0) is reached and not budget_reached(turns, None)
    # a self-play run's own state and the experiment's status decide alike
    state = SelfPlayState(seed=0, curriculum_steps=0, pools={}, cpu_hours=1.0,
                          turns=[Turn(steps=0, episodes=0, captures=0, checkpoint="", opponents=0,
                                      **{key: t[key] for key in ("round", "role", "learner")}, cpu_seconds=t["cpu_seconds"])
                                 for t in turns])
    assert state.budget_reached() is reached and state.whole_rounds() == rounds
    run = load_experiment("strength-small").runs()[0].model_copy(update={"cpu_hours": 1.0})  # 150 rounds planned
    (tmp_path / run.name).mkdir()
    (tmp_path / run.name / SELFPLAY_STATE).write_text(json.dumps({"turns": turns}))
    progress = run_progress(run, tmp_path)
    assert progress.done is reached and progress.round == rounds
