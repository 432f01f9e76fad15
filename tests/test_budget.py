"""A self-play run's CPU budget: whole rounds only, exploiters counted, one rule for selfplay and experiments."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from pecli.experiment import load_experiment
from pecli.experiment.runs import SELFPLAY_STATE, run_progress
from pecli.records import Turn
from pecli.rl.budget import budget_reached, cpu_through, scheduled_turns, whole_rounds
from pecli.rl.pool import OpponentPool
from pecli.rl.state import SelfPlayState
from pecli.zoo import RESUME_DIR

LEAGUE = load_experiment("strength-small").runs()[0]  # no exploiters, 150 rounds planned
EXPLOITERS = LEAGUE.scenario.training.selfplay.model_copy(  # an evader exploiter every round once 1 CPU-h is spent
    update={"league_exploiter_every": 1, "league_exploiter_after": 1.0, "league_exploiter_roles": ["evader"]}
)


def turn(round: int, role: str, cpu: float, learner: str = "main") -> dict:
    return {"round": round, "role": role, "cpu_seconds": cpu, "learner": learner}


def state_record(turns: list[dict]) -> dict:
    """A valid ``selfplay.json`` holding ``turns`` (their other fields made up)."""
    full = [
        Turn(
            round=t["round"],
            role=t["role"],
            steps=0,
            episodes=0,
            captures=0,
            cpu_seconds=float(t["cpu_seconds"]),
            checkpoint=f"{'exploiter-' * (t['learner'] == 'exploiter')}{t['role']}/round-{t['round']:03d}.zip",
            opponents=1,
            learner=t["learner"],
        )
        for t in turns
    ]
    pools = {role: OpponentPool(role) for role in ("pursuer", "evader")}
    return SelfPlayState(seed=0, curriculum_steps=0, pools=pools, turns=full).to_dict()


WHOLE = [turn(1, "pursuer", 1000), turn(1, "evader", 1000), turn(2, "pursuer", 1000), turn(2, "evader", 1000)]


@pytest.mark.parametrize(
    ("turns", "rounds", "spent", "reached"),
    [
        ([], 0, 0, False),
        (WHOLE, 2, 4000, True),  # 4000 CPU-s after round 2, over a budget of one hour
        (WHOLE[:3], 1, 2000, False),  # round 2 half-played: its pursuer's 1000 s do not end the run
        (WHOLE[:2] + [turn(2, "pursuer", 2000)], 1, 2000, False),  # not even when they pass the budget
        (WHOLE[:2] + [turn(1, "evader", 2000, "exploiter")], 1, 4000, True),  # an exploiter's turn counts
        ([turn(1, "pursuer", 1000), turn(1, "evader", 9000, "exploiter")], 0, 0, False),  # but is no main turn
        ([turn(2, "pursuer", 9000), turn(2, "evader", 9000)], 0, 0, False),  # rounds count from round 1
    ],
)
def test_only_whole_rounds_count(turns: list[dict], rounds: int, spent: float, reached: bool, tmp_path: Path) -> None:
    settings = LEAGUE.scenario.training.selfplay
    assert whole_rounds(turns, settings) == rounds and cpu_through(turns, rounds) == spent
    assert budget_reached(turns, 1.0, settings) is reached and not budget_reached(turns, None, settings)
    run = LEAGUE.model_copy(update={"cpu_hours": 1.0})  # the experiment's status decides alike
    (tmp_path / run.name).mkdir()
    (tmp_path / run.name / SELFPLAY_STATE).write_text(json.dumps(state_record(turns)))
    progress = run_progress(run, tmp_path)
    assert progress.done is reached and progress.round == rounds


@pytest.mark.parametrize("damage", [{"steps": "x"}, {"cpu_seconds": -1.0}, {"steps": 10**20}])
def test_a_damaged_learner_record_counts_as_none_in_the_progress(damage: dict, tmp_path: Path) -> None:
    resume = tmp_path / LEAGUE.name / "pursuer" / RESUME_DIR
    resume.mkdir(parents=True)
    (resume / "state.json").write_text(json.dumps({"steps": 4000, "cpu_seconds": 12.5, "model": "m.zip"}))
    assert (run_progress(LEAGUE, tmp_path).steps, run_progress(LEAGUE, tmp_path).cpu_seconds) == (4000, 12.5)
    (resume / "state.json").write_text(json.dumps({"steps": 4000, "cpu_seconds": 12.5, **damage}))
    assert (run_progress(LEAGUE, tmp_path).steps, run_progress(LEAGUE, tmp_path).cpu_seconds) == (0, 0.0)


def test_a_round_is_whole_once_its_scheduled_exploiters_trained() -> None:
    assert scheduled_turns(EXPLOITERS, WHOLE, 2) == [("main", "pursuer"), ("main", "evader")]  # 2000 s before it
    assert scheduled_turns(EXPLOITERS, WHOLE, 3)[-1] == ("exploiter", "evader")  # 4000 s before it
    played = WHOLE + [turn(3, "pursuer", 1000), turn(3, "evader", 1000)]
    assert whole_rounds(played, EXPLOITERS) == 2 and not budget_reached(played, 1.5, EXPLOITERS)  # 4000 s < 1.5 h
    played.append(turn(3, "evader", 1000, "exploiter"))
    assert whole_rounds(played, EXPLOITERS) == 3 and budget_reached(played, 1.5, EXPLOITERS)  # 7000 s
