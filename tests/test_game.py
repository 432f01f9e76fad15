"""The batched game: capture, timeout, rewards, walls, observations, seeding, batching, auto-reset."""

from __future__ import annotations

import math

import numpy as np
import pytest
from conftest import all_scenarios

from pecli.game import Game
from pecli.game.observation import ObservationCodec
from pecli.scenario import Scenario

STILL = np.zeros((1, 2))


def paper_state(pursuer_xy, evader_xy, yaw=0.0, speed=0.0):
    """A 9-number paper state: car (x, y, delta, v, psi) then point mass (x, y, vx, vy)."""
    return np.array([[*pursuer_xy, 0.0, speed, yaw, *evader_xy, 0.0, 0.0]])


def test_capture_ends_the_game_with_the_capture_reward(paper: Scenario) -> None:
    game = Game(paper, n=1, seed=0)
    game.set_state(paper_state((0.0, 0.0), (0.55, 0.0), speed=1.0))  # 0.1 m per step towards the evader
    result = game.step(STILL, STILL)
    assert result.captured[0] and result.done[0] and not result.timed_out[0]
    assert result.rewards["pursuer"][0] == paper.reward.capture
    assert result.rewards["evader"][0] == -paper.reward.capture
    assert result.steps[0] == 1


def test_step_reward_is_time_and_distance(paper: Scenario) -> None:
    game = Game(paper, n=1, seed=0)
    game.set_state(paper_state((0.0, 0.0), (3.0, 4.0)))
    result = game.step(STILL, STILL)
    assert result.rewards["pursuer"][0] == pytest.approx(-(1.0 + 5.0))
    assert result.rewards["evader"][0] == pytest.approx(6.0)
    assert not result.done[0]


def test_timeout_at_the_horizon(paper: Scenario) -> None:
    game = Game(paper, n=1, seed=0)
    game.set_state(paper_state((-5.0, 0.0), (5.0, 0.0)), t=paper.horizon - 1)
    result = game.step(STILL, STILL)
    assert result.timed_out[0] and result.done[0] and not result.captured[0]
    assert result.rewards["pursuer"][0] == -paper.reward.capture
    assert result.steps[0] == paper.horizon


def test_capture_on_the_last_step_counts_as_capture(paper: Scenario) -> None:
    game = Game(paper, n=1, seed=0)
    game.set_state(paper_state((0.0, 0.0), (0.3, 0.0)), t=paper.horizon - 1)
    result = game.step(STILL, STILL)
    assert result.captured[0] and not result.timed_out[0]


def test_walls_keep_players_inside(paper: Scenario) -> None:
    game = Game(paper, n=64, seed=1)
    rng = np.random.default_rng(0)
    for _ in range(300):
        game.step(rng.uniform(-1, 1, (64, 2)), np.tile([1.0, 1.0], (64, 1)))
    state = game.state()
    assert np.all(np.abs(state[:, [0, 5]]) <= 8.0) and np.all(np.abs(state[:, [1, 6]]) <= 8.0)


def test_finished_games_freeze(paper: Scenario) -> None:
    game = Game(paper, n=2, seed=0)
    game.set_state(np.vstack([paper_state((0, 0), (0.3, 0)), paper_state((-5, 0), (5, 0), speed=1.0)]))
    first = game.step(np.zeros((2, 2)), np.zeros((2, 2)))
    assert first.captured.tolist() == [True, False]
    frozen = game.state()[0].copy()
    second = game.step(np.ones((2, 2)), np.ones((2, 2)))
    np.testing.assert_array_equal(game.state()[0], frozen)
    assert second.rewards["pursuer"][0] == 0.0 and not second.done[0]
    assert game.t.tolist() == [1, 2]


@pytest.mark.parametrize("scenario", all_scenarios(), ids=lambda s: f"{s.name}-{s.observation_frame}")
def test_observations_lie_in_minus_one_one(scenario: Scenario) -> None:
    n = 256
    game = Game(scenario, n=n, seed=3, auto_reset=True)
    rng = np.random.default_rng(1)
    obs = game.reset()
    for _ in range(300):
        for role in obs:
            assert obs[role].shape == (n, game.obs_dim[role]) and obs[role].dtype == np.float32
            assert np.all(np.abs(obs[role]) <= 1.0), role
        result = game.step(rng.choice([-1.0, 1.0], (n, 2)), rng.uniform(-1, 1, (n, 2)))
        obs = result.obs
    assert np.all(np.abs(game.normalised_state()) <= 1.0)


@pytest.mark.parametrize("scenario", all_scenarios(), ids=lambda s: f"{s.name}-{s.observation_frame}")
def test_decode_recovers_the_world(scenario: Scenario) -> None:
    game = Game(scenario, n=128, seed=5)
    rng = np.random.default_rng(2)
    for _ in range(40):
        result = game.step(rng.uniform(-1, 1, (128, 2)), rng.uniform(-1, 1, (128, 2)))
    state = game.state()
    kp = game.dynamics["pursuer"].state_dim
    for role, own, opp in (("pursuer", state[:, :kp], state[:, kp:]), ("evader", state[:, kp:], state[:, :kp])):
        view = ObservationCodec(scenario, role).decode(result.obs[role])
        np.testing.assert_allclose(view.own_pos, own[:, :2], atol=1e-5)
        seen = result.seen[role]
        assert np.array_equal(view.seen, seen)
        # positions survive float32 to ~1e-6 of the normaliser (arena or sensing range)
        np.testing.assert_allclose(view.opp_pos[seen], opp[seen, :2], atol=1e-4)
        assert np.all(view.opp_pos[~seen] == view.opp_pos[~seen])  # finite


def test_observation_layout_world_frame(paper: Scenario) -> None:
    scenario = paper.model_copy(update={"observation_frame": "world"})
    game = Game(scenario, n=1, seed=0)
    obs = game.set_state(paper_state((4.0, -2.0), (5.0, -2.0), yaw=0.0, speed=1.25))["pursuer"][0]
    expected = [0.5, -0.25, 0.0, 0.5, 0.0, 5 / 8, -0.25, 0.0, 0.0, 1.0, 0.0]
    np.testing.assert_allclose(obs, expected, atol=1e-7)
    hidden = game.set_state(paper_state((4.0, -2.0), (3.0, -2.0), yaw=0.0))["pursuer"][0]  # behind: unseen
    np.testing.assert_allclose(hidden[5:10], [0, 0, 0, 0, -1])


def test_observation_layout_own_frame(paper: Scenario) -> None:
    game = Game(paper, n=1, seed=0)
    # the car faces +y; the evader 3 m ahead of it appears straight ahead in the body frame (+x)
    obs = game.set_state(paper_state((0.0, 0.0), (0.0, 3.0), yaw=math.pi / 2))["pursuer"][0]
    np.testing.assert_allclose(obs[5:7], [3.0 / 6.0, 0.0], atol=1e-7)
    assert obs[9] == 1.0


def test_same_seed_same_games_different_seed_different(paper: Scenario) -> None:
    def rollout(seed: int) -> np.ndarray:
        game = Game(paper, n=32, seed=seed, auto_reset=True)
        rng = np.random.default_rng(0)
        frames = []
        for _ in range(450):
            frames.append(game.step(rng.uniform(-1, 1, (32, 2)), rng.uniform(-1, 1, (32, 2))).obs["pursuer"])
        return np.stack(frames)

    assert np.array_equal(rollout(11), rollout(11))
    assert not np.array_equal(rollout(11), rollout(12))


def test_reset_with_the_same_seed_repeats_start_states(paper: Scenario) -> None:
    game = Game(paper, n=16, seed=4)
    first = game.state()
    game.reset()
    assert not np.array_equal(game.state(), first)  # the next episode
    game.reset(seed=4)
    assert np.array_equal(game.state(), first)


def test_start_states_do_not_depend_on_batch_size(paper: Scenario) -> None:
    big = Game(paper, n=50, seed=9).state()
    small = Game(paper, n=7, seed=9).state()
    np.testing.assert_array_equal(big[:7], small)


def test_start_states_are_valid(paper: Scenario) -> None:
    state = Game(paper, n=4000, seed=2).state()
    distance = np.hypot(state[:, 5] - state[:, 0], state[:, 6] - state[:, 1])
    assert distance.min() > paper.capture_distance
    assert np.all(np.abs(state[:, [0, 1, 5, 6]]) <= 8.0)
    np.testing.assert_array_equal(state[:, [2, 3, 7, 8]], 0.0)  # still, wheels straight
    assert state[:, 4].min() < -3.0 and state[:, 4].max() > 3.0  # yaw covers [-pi, pi)


@pytest.mark.parametrize("name", ["paper", "car_vs_car", "point_mass"])
def test_a_batch_of_n_equals_n_single_games(name: str) -> None:
    from pecli.scenario import load_scenario

    scenario = load_scenario(name)
    n, steps = 12, 200
    rng = np.random.default_rng(4)
    batch = Game(scenario, n=n, seed=0)
    singles = [Game(scenario, n=1, seed=0) for _ in range(n)]
    start = Game(scenario, n=n, seed=77).state()
    batch.set_state(start)
    for i, game in enumerate(singles):
        game.set_state(start[i : i + 1])
    for _ in range(steps):
        pa, ea = rng.uniform(-1.1, 1.1, (n, 2)), rng.uniform(-1.1, 1.1, (n, 2))
        result = batch.step(pa, ea)
        for i, game in enumerate(singles):
            single = game.step(pa[i : i + 1], ea[i : i + 1])
            for role in ("pursuer", "evader"):
                np.testing.assert_array_equal(single.obs[role][0], result.obs[role][i])
                assert single.rewards[role][0] == result.rewards[role][i]
            assert single.done[0] == result.done[i]
    np.testing.assert_array_equal(batch.state(), np.vstack([g.state() for g in singles]))


def test_auto_reset_restarts_finished_games_and_reports_final_observation(paper: Scenario) -> None:
    game = Game(paper, n=2, seed=0, auto_reset=True)
    game.set_state(np.vstack([paper_state((0, 0), (0.3, 0)), paper_state((-5, 0), (5, 0))]))
    before = game.state()
    result = game.step(np.zeros((2, 2)), np.zeros((2, 2)))
    assert result.done.tolist() == [True, False]
    assert result.final_obs is not None and result.final_state is not None
    np.testing.assert_allclose(result.final_state[0, [0, 5]], before[0, [0, 5]])
    assert game.t.tolist() == [0, 1]
    assert not np.array_equal(game.state()[0], result.final_state[0])  # a fresh start
    np.testing.assert_array_equal(result.obs["pursuer"][0], game.observe()["pursuer"][0])
    assert result.obs["pursuer"][0, -1] == 0.0  # time index restarted


def test_curriculum_knobs(paper: Scenario) -> None:
    game = Game(paper, n=1, seed=0)
    state = paper_state((0.0, 0.0), (-3.0, 0.0), yaw=0.0)  # the evader is behind the car
    assert game.set_state(state)["pursuer"][0, 9] == -1.0
    game.fov["pursuer"] = 2 * math.pi
    assert game.set_state(state)["pursuer"][0, 9] == 1.0
    game.speed_scale["evader"] = 0.0
    game.step(STILL, np.ones((1, 2)))
    np.testing.assert_allclose(game.state()[0, 5:9], [-3.0, 0.0, 0.0, 0.0])


def test_bad_actions_are_refused(paper: Scenario) -> None:
    game = Game(paper, n=3, seed=0)
    with pytest.raises(ValueError, match="shape"):
        game.step(np.zeros((2, 2)), np.zeros((3, 2)))
