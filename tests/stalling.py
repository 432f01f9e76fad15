"""A test helper policy (``stalling:StallingEvader``): its pairing keeps a tournament worker busy until it is killed."""

from __future__ import annotations

import time

import numpy as np


class StallingEvader:
    role = "evader"

    def __init__(self, scenario=None, seed=None) -> None:
        pass

    def reset(self, n: int, mask=None, seed=None) -> None:
        pass

    def act(self, obs: np.ndarray) -> np.ndarray:
        time.sleep(600)
        return np.zeros((len(obs), 2))
