"""Matches: the paper's metrics, determinism and paired start states."""

from __future__ import annotations

import numpy as np
import pytest

from pecli.match import Behaviour, MatchResult, play_match
from pecli.policies import resolve_policy
from pecli.policies.heuristics import PurePursuit
from pecli.policies.windowed import WindowedPolicy
from pecli.scenario import Scenario


def test_metrics_by_hand() -> None:
    result = MatchResult(
        captured=np.array([True, True, False, False]), steps=np.array([100, 300, 400, 400]), horizon=400
    )
    np.testing.assert_allclose(result.time_to_capture, [0.25, 0.75, 1.0, 1.0])
    assert result.capture_rate == 0.5
    assert result.time_to_capture_mean == pytest.approx(0.75)
    # population std of (0.25, 0.75, 1, 1): mean 0.75, squared deviations 0.25, 0, 0.0625, 0.0625
    assert result.time_to_capture_std == pytest.approx(np.sqrt(0.375 / 4))
    assert result.summary() == {
        "capture_rate": 0.5,
        "time_to_capture_mean": pytest.approx(0.75),
        "time_to_capture_std": pytest.approx(np.sqrt(0.375 / 4)),
        "episodes": 4,
    }


def test_a_timeout_counts_one_even_if_steps_are_fewer() -> None:
    result = MatchResult(captured=np.array([False]), steps=np.array([10]), horizon=400)
    assert result.time_to_capture_mean == 1.0


def play(scenario: Scenario, evader: str, seed: int, episodes: int = 64, record: int = 0):
    return play_match(
        scenario,
        resolve_policy("pure-pursuit", "pursuer", scenario),
        resolve_policy(evader, "evader", scenario),
        episodes=episodes,
        seed=seed,
        record=record,
    )


def test_matches_are_deterministic_under_a_seed(quick: Scenario) -> None:
    a, _ = play(quick, "random-walk", seed=3)
    b, _ = play(quick, "random-walk", seed=3)
    c, _ = play(quick, "random-walk", seed=4)
    np.testing.assert_array_equal(a.steps, b.steps)
    np.testing.assert_array_equal(a.captured, b.captured)
    assert not np.array_equal(a.steps, c.steps)


def test_pairings_share_start_states(quick: Scenario) -> None:
    _, greedy = play(quick, "greedy", seed=8, episodes=16, record=16)
    _, rash = play(quick, "rash", seed=8, episodes=16, record=16)
    np.testing.assert_array_equal(greedy.pursuer[0], rash.pursuer[0])
    np.testing.assert_array_equal(greedy.evader[0], rash.evader[0])


def test_recording_matches_the_outcome(quick: Scenario) -> None:
    result, recording = play(quick, "greedy", seed=1, episodes=32, record=5)
    assert recording is not None
    assert recording.pursuer.shape[1:] == (5, 5) and recording.evader.shape[1:] == (5, 4)
    assert recording.pursuer.shape[0] == int(result.steps.max()) + 1
    for i in range(5):
        end = recording.steps[i]
        gap = np.hypot(*(recording.pursuer[end, i, :2] - recording.evader[end, i, :2]))
        assert (gap <= quick.capture_distance) == recording.captured[i]


def test_pure_pursuit_vs_greedy_is_a_contest(quick: Scenario) -> None:
    greedy, _ = play(quick, "greedy", seed=0, episodes=200)
    assert 0.1 < greedy.capture_rate < 0.9
    assert 0.0 < greedy.time_to_capture_mean <= 1.0


class Counting(WindowedPolicy):
    """A learned evader stand-in: one fixed action, and a count of the games it decides for."""

    def __init__(self, scenario: Scenario) -> None:
        super().__init__("evader", scenario, frame_skip=2, frame_stack=1, history_length=None, history_stride=1)
        self.decided = 0

    def _decide(self, stack, history, draws, due):
        self.decided += len(stack)
        return np.tile([0.3, -0.2], (len(stack), 1))


def test_learned_players_skip_games_that_have_ended(quick: Scenario) -> None:
    skipping, playing = Counting(quick), Counting(quick)
    playing.end = None  # a player without the hint decides for every game until the last one ends
    first, _ = play_match(quick, PurePursuit(quick, "pursuer"), skipping, episodes=64, seed=3)
    second, _ = play_match(quick, PurePursuit(quick, "pursuer"), playing, episodes=64, seed=3)
    assert np.array_equal(first.captured, second.captured) and np.array_equal(first.steps, second.steps)
    assert first.captured.any() and skipping.decided < playing.decided
    assert skipping.decided == sum(-(-int(t) // 2) for t in first.steps)  # one decision per 2 steps of play


def test_behaviour_says_how_the_evader_plays(quick: Scenario) -> None:
    pursuer = resolve_policy("pure-pursuit", "pursuer", quick)
    seen = {}
    for name in ("hider", "greedy"):
        result, recording = play_match(quick, pursuer, resolve_policy(name, "evader", quick), 40, seed=0, record=40)
        seen[name] = Behaviour.of(recording)
        assert seen[name].caught == result.capture_rate
        assert 0 <= seen[name].seen <= 1 and 0 <= seen[name].sees <= 1 and seen[name].distance > 0
        assert 0 <= seen[name].wall <= min(quick.arena.half)
        escaped = np.flatnonzero(~recording.captured)
        picked = recording.games(escaped)
        assert picked.pursuer.shape[1] == len(escaped) and not picked.captured.any()
    assert seen["hider"].speed_unseen < seen["hider"].speed_seeing  # it sits still until it sees the pursuer
    assert seen["greedy"].wall < seen["hider"].wall  # greedy flees straight away from it, into the walls


def test_play_behaviour_prints_it_and_joins_the_json() -> None:
    import json

    from typer.testing import CliRunner

    from pecli.cli import app

    result = CliRunner().invoke(
        app, ["play", "-p", "pure-pursuit", "-e", "hider", "-c", "quick", "-n", "8", "--behaviour", "--json"]
    )
    assert result.exit_code == 0, result.output
    record = json.loads(result.stdout)
    assert record["episodes"] == 8 and set(record["behaviour"]) == {
        "caught",
        "seen",
        "sees",
        "speed_unseen",
        "speed_seeing",
        "distance",
        "wall",
    }
    refused = CliRunner().invoke(app, ["play", "-c", "quick", "-n", "20000", "--behaviour"])
    assert refused.exit_code == 1 and "at most 10,000" in refused.output


def test_a_player_that_acts_nan_ends_the_match_in_one_line(quick: Scenario) -> None:
    from pecli.errors import PolicyError

    class Damaged(PurePursuit):
        def act(self, obs: dict) -> np.ndarray:
            action = super().act(obs)
            action[0] = np.nan
            return action

    evader = resolve_policy("greedy", "evader", quick)
    with pytest.raises(PolicyError, match="the pursuer played a NaN or infinite action at step 1"):
        play_match(quick, Damaged(quick, "pursuer"), evader, episodes=4)
