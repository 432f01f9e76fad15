"""n-step returns for Dict observations: sums, discounts, episode ends, the ring's newest row,
abandoned games, training."""

from __future__ import annotations

import numpy as np
import pytest
from gymnasium import spaces
from stable_baselines3.common.buffers import DictReplayBuffer

from pecli.models.buffers import NStepDictReplayBuffer, end_episodes
from pecli.policies import resolve_policy
from pecli.rl.durable import Ring, _read_chunks, replay_arrays, write_chunk
from pecli.rl.train import TrainJob, make_env, make_model, with_overrides
from pecli.scenario import Scenario

GAMMA = 0.5
SPACE = spaces.Dict({"obs": spaces.Box(-np.inf, np.inf, (1,), np.float32)})
ACTIONS = spaces.Box(-1, 1, (2,), np.float32)


def filled(
    n_step: int,
    rows: int,
    size: int = 16,
    done: set[int] = frozenset(),
    timeout: set[int] = frozenset(),
    buffer_class: type = NStepDictReplayBuffer,
) -> DictReplayBuffer:
    """A one-env buffer whose row ``t`` has observation ``t``, next observation ``t + 0.5`` and reward ``t + 1``."""
    kwargs = {"n_step": n_step, "gamma": GAMMA} if buffer_class is NStepDictReplayBuffer else {}
    buffer = buffer_class(size, SPACE, ACTIONS, device="cpu", n_envs=1, **kwargs)
    for t in range(rows):
        infos = [{"TimeLimit.truncated": t in timeout}]
        buffer.add(
            {"obs": np.array([[t]], np.float32)},
            {"obs": np.array([[t + 0.5]], np.float32)},
            np.zeros((1, 2), np.float32),
            np.array([t + 1.0]),
            np.array([t in done or t in timeout]),
            infos,
        )
    return buffer


def sample(buffer: DictReplayBuffer, start: int):
    return buffer._get_samples(np.array([start]))


def test_a_return_sums_discounted_rewards_and_bootstraps_after_n_rows() -> None:
    s = sample(filled(3, rows=10), 2)
    assert s.rewards.item() == pytest.approx(3 + GAMMA * 4 + GAMMA**2 * 5)
    assert s.discounts.item() == pytest.approx(GAMMA**3)
    assert s.next_observations["obs"].item() == pytest.approx(4.5) and s.dones.item() == 0
    assert s.observations["obs"].item() == 2


def test_a_return_stops_at_a_termination_and_does_not_bootstrap() -> None:
    s = sample(filled(3, rows=10, done={3}), 2)
    assert s.rewards.item() == pytest.approx(3 + GAMMA * 4)
    assert s.discounts.item() == pytest.approx(GAMMA**2)
    assert s.next_observations["obs"].item() == pytest.approx(3.5) and s.dones.item() == 1


def test_a_return_stops_at_a_truncation_and_bootstraps_from_its_last_observation() -> None:
    s = sample(filled(3, rows=10, timeout={2}), 2)
    assert s.rewards.item() == pytest.approx(3)
    assert s.discounts.item() == pytest.approx(GAMMA)
    assert s.next_observations["obs"].item() == pytest.approx(2.5) and s.dones.item() == 0


def test_the_newest_row_ends_a_return_so_it_never_runs_into_unwritten_or_oldest_rows() -> None:
    s = sample(filled(3, rows=5), 3)  # rows 0..4 written; from 3 only rows 3 and 4 exist
    assert s.rewards.item() == pytest.approx(4 + GAMMA * 5) and s.discounts.item() == pytest.approx(GAMMA**2)
    full = filled(3, rows=20, size=8)  # a full ring: the newest row is 3, the oldest 4
    s = sample(full, 3)
    assert s.rewards.item() == pytest.approx(20) and s.next_observations["obs"].item() == pytest.approx(19.5)
    s = sample(full, 7)  # wraps around the end of the ring to rows 0 and 1
    assert s.rewards.item() == pytest.approx(16 + GAMMA * 17 + GAMMA**2 * 18)


def test_one_step_samples_exactly_as_sb3s_dict_buffer() -> None:
    ours, sb3 = filled(1, rows=10, done={4}), filled(1, rows=10, done={4}, buffer_class=DictReplayBuffer)
    rows = np.arange(10)
    np.random.seed(0)
    a = ours._get_samples(rows)
    np.random.seed(0)
    b = sb3._get_samples(rows)
    for x, y in ((a.rewards, b.rewards), (a.dones, b.dones), (a.next_observations["obs"], b.next_observations["obs"])):
        assert np.array_equal(x.numpy(), y.numpy())


def test_abandoned_games_end_returns_and_one_step_samples_do_not_change() -> None:
    buffer = filled(3, rows=5)
    end_episodes(buffer)  # a new turn: the games of row 4 are gone
    buffer.add(
        {"obs": np.array([[9.0]], np.float32)},
        {"obs": np.array([[9.5]], np.float32)},
        np.zeros((1, 2), np.float32),
        np.array([10.0]),
        np.array([False]),
        [{}],
    )
    s = sample(buffer, 3)
    assert s.rewards.item() == pytest.approx(4 + GAMMA * 5) and s.discounts.item() == pytest.approx(GAMMA**2)
    assert s.next_observations["obs"].item() == pytest.approx(4.5) and s.dones.item() == 0  # bootstraps
    one_step, sb3 = filled(1, rows=5, done={2}), filled(1, rows=5, done={2}, buffer_class=DictReplayBuffer)
    end_episodes(one_step)
    a, b = one_step._get_samples(np.arange(5)), sb3._get_samples(np.arange(5))
    assert np.array_equal(a.dones.numpy(), b.dones.numpy()) and np.array_equal(a.rewards.numpy(), b.rewards.numpy())


def test_a_row_marked_after_a_save_is_saved_again_with_the_next_rows(tmp_path) -> None:
    buffer = filled(3, rows=4)
    ring = write_chunk(tmp_path, "replay", replay_arrays(buffer), Ring(buffer.buffer_size), 4)
    end_episodes(buffer)  # row 3, already on disk unmarked
    buffer.add(
        {"obs": np.array([[4.0]], np.float32)},
        {"obs": np.array([[4.5]], np.float32)},
        np.zeros((1, 2), np.float32),
        np.array([5.0]),
        np.array([False]),
        [{}],
    )
    ring = write_chunk(tmp_path, "replay", replay_arrays(buffer), ring, 5)
    restored = filled(3, rows=0)
    _read_chunks(tmp_path, ring, replay_arrays(restored))
    assert restored.dones[3, 0] == 1 and restored.timeouts[3, 0] == 1 and restored.dones[4, 0] == 0
    assert np.array_equal(restored.rewards[:5, 0], [1, 2, 3, 4, 5])


@pytest.mark.parametrize("algo", ["td3", "crossq"])
def test_a_learner_trains_with_n_step_returns(quick: Scenario, tmp_path, algo: str) -> None:
    tiny = {"buffer_size": 500, "batch_size": 16, "learning_starts": 50, "net_arch": [16, 16], "n_envs": 4}
    scenario = with_overrides(quick, {**tiny, "algo": algo, "n_step": 3})
    job = TrainJob(role="pursuer", scenario=scenario, opponent="greedy", zoo=tmp_path, name="n3")
    model = make_model(job, make_env(job, resolve_policy("greedy", "evader", scenario), seed=0), tensorboard=None)
    model.learn(120)
    assert model.replay_buffer.n_step == 3 and model.replay_buffer.gamma == scenario.training.gamma
    assert model.replay_buffer.sample(8).discounts is not None
