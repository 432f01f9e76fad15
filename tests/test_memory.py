"""Frame stack and history window: what a learned player remembers."""

from __future__ import annotations

import numpy as np

from pecli.game.memory import FrameStack, HistoryWindow


def obs_at(step: int, n: int = 3, dim: int = 2) -> np.ndarray:
    """Observations whose every entry is the step number (game i adds i / 10)."""
    return np.full((n, dim), float(step), dtype=np.float32) + np.arange(n, dtype=np.float32)[:, None] / 10


def test_frame_stack_fills_pushes_and_masks() -> None:
    stack = FrameStack(n=3, dim=2, k=2)
    first = stack.reset(obs_at(0))
    np.testing.assert_allclose(first[0], [0, 0, 0, 0])
    pushed = stack.push(obs_at(1))
    np.testing.assert_allclose(pushed[1], [0.1, 0.1, 1.1, 1.1])
    masked = stack.push(obs_at(2), mask=np.array([True, False, False]))
    np.testing.assert_allclose(masked[0], [1, 1, 2, 2])
    np.testing.assert_allclose(masked[1], [0.1, 0.1, 1.1, 1.1])
    restarted = stack.reset(obs_at(9), mask=np.array([False, True, False]))
    np.testing.assert_allclose(restarted[1], [9.1] * 4)
    np.testing.assert_allclose(restarted[2], [0.2, 0.2, 1.2, 1.2])


def test_history_samples_every_stride_oldest_first() -> None:
    window = HistoryWindow(n=3, dim=2, length=200, stride=10)
    assert window.shape == (20, 2)
    window.reset(obs_at(0))
    for step in range(1, 250):
        out = window.push(obs_at(step))
    rows = out.reshape(3, 20, 2)
    np.testing.assert_allclose(rows[0, :, 0], np.arange(249 - 190, 250, 10))  # 59, 69, ..., 249
    np.testing.assert_allclose(rows[2, -1], [249.2, 249.2], rtol=1e-6)


def test_history_before_the_start_is_zero_and_restarts_per_game() -> None:
    window = HistoryWindow(n=3, dim=2, length=50, stride=10)
    window.reset(obs_at(0))
    for step in range(1, 25):
        window.push(obs_at(step))
    rows = window.get().reshape(3, 5, 2)
    # newest 24; samples 40, 30, 20, 10 and 0 steps back: -16 and -6 are before the start
    np.testing.assert_allclose(rows[0, :, 0], [0.0, 0.0, 4.0, 14.0, 24.0])
    window.reset(obs_at(100), mask=np.array([False, True, False]))
    rows = window.push(obs_at(25)).reshape(3, 5, 2)
    np.testing.assert_allclose(rows[1, :, 0], [0.0, 0.0, 0.0, 0.0, 25.1], rtol=1e-6)  # game 1 forgot its past
    np.testing.assert_allclose(rows[0, :, 0], [0.0, 0.0, 5.0, 15.0, 25.0])
    assert window.reset(obs_at(7))[0, -2:].tolist() == [7.0, 7.0]  # a reset records the first observation
