"""What a learned player remembers between steps: a frame stack and the belief's history window.

Both keep one entry per game and restart it for the games a caller resets. The training view
(``wrappers``) and a learned :class:`~pecli.policies.Policy` at play time use these same
classes, so a policy sees at play time exactly what it saw in training.
"""

from __future__ import annotations

import numpy as np


class FrameStack:
    """The last ``k`` observations of each game, oldest first, flattened: ``(n, k * dim)``.

    A game that (re)starts has its stack filled with its first observation.
    """

    def __init__(self, n: int, dim: int, k: int) -> None:
        self.n, self.dim, self.k = n, dim, k
        self.frames = np.zeros((n, k, dim), dtype=np.float32)

    def reset(self, obs: np.ndarray, mask: np.ndarray | None = None) -> np.ndarray:
        """Fill the stacks of all games, or of the games in ``mask``, with ``obs`` ``(n, dim)``."""
        if mask is None:
            self.frames[:] = obs[:, None, :]
        else:
            self.frames[mask] = obs[mask][:, None, :]
        return self.get()

    def push(self, obs: np.ndarray, mask: np.ndarray | None = None) -> np.ndarray:
        """Append ``obs`` ``(n, dim)`` to every game's stack, or to those in ``mask``; returns the stacks."""
        rows = slice(None) if mask is None else np.asarray(mask, dtype=bool)
        if self.k > 1:
            self.frames[rows, :-1] = self.frames[rows, 1:]
        self.frames[rows, -1] = obs[rows]
        return self.get()

    def get(self) -> np.ndarray:
        return self.frames.reshape(self.n, self.k * self.dim).copy()


class HistoryWindow:
    """The belief network's input: the last ``length`` observations of each game, every ``stride``-th.

    With the paper's 200 steps and stride 10 that is 20 observations at 1 Hz, oldest first,
    the newest being the current one. Steps before a game's start are zeros.
    Shape of :meth:`get`: ``(n, samples * dim)`` with ``samples = ceil(length / stride)``.
    """

    def __init__(self, n: int, dim: int, length: int = 200, stride: int = 10) -> None:
        self.n, self.dim, self.length, self.stride = n, dim, length, stride
        self.samples = -(-length // stride)
        self.buffer = np.zeros((n, length, dim), dtype=np.float32)
        self.cursor = 0  # next write position; every push writes all games, so one cursor serves all
        # positions back from the newest entry, oldest first: (samples-1)*stride, ..., stride, 0
        self._back = np.arange(self.samples - 1, -1, -1) * stride

    @property
    def shape(self) -> tuple[int, int]:
        """``(samples, dim)``: the window of one game before flattening."""
        return self.samples, self.dim

    def reset(self, obs: np.ndarray, mask: np.ndarray | None = None) -> np.ndarray:
        """Forget the past of all games, or of the games in ``mask``, and record their first ``obs``."""
        rows = slice(None) if mask is None else np.asarray(mask, dtype=bool)
        self.buffer[rows] = 0.0
        self.buffer[rows, (self.cursor - 1) % self.length] = obs[rows]
        return self.get()

    def push(self, obs: np.ndarray) -> np.ndarray:
        """Record ``obs`` ``(n, dim)`` as every game's newest observation; returns the windows."""
        self.buffer[:, self.cursor] = obs
        self.cursor = (self.cursor + 1) % self.length
        return self.get()

    def get(self) -> np.ndarray:
        index = (self.cursor - 1 - self._back) % self.length
        return self.buffer[:, index].reshape(self.n, self.samples * self.dim)
