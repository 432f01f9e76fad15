"""Counter-based random numbers for start states.

Game slot ``i`` in its ``k``-th episode under seed ``s`` always starts from the same state,
whatever the batch size, the policies, or the order in which other games end. That makes a
batch of N games equal to N single games, and gives every pairing in a tournament the same
start states (a paired comparison). The generator is SplitMix64 applied to a mix of the
counters, vectorised over games.
"""

from __future__ import annotations

import numpy as np

_GOLDEN = np.uint64(0x9E3779B97F4A7C15)
_M1 = np.uint64(0xBF58476D1CE4E5B9)
_M2 = np.uint64(0x94D049BB133111EB)
_SLOT = np.uint64(0xD6E8FEB86659FD93)
_EPISODE = np.uint64(0xA0761D6478BD642F)


def _splitmix64(z: np.ndarray) -> np.ndarray:
    z = z + _GOLDEN
    z = (z ^ (z >> np.uint64(30))) * _M1
    z = (z ^ (z >> np.uint64(27))) * _M2
    return z ^ (z >> np.uint64(31))


def counter_uniform(seed: int, slots: np.ndarray, episodes: np.ndarray, draws: int) -> np.ndarray:
    """Uniform numbers in [0, 1), shape ``(draws, len(slots))``, a pure function of the counters."""
    with np.errstate(over="ignore"):
        base = _splitmix64(
            np.uint64(seed % 2**64)
            ^ _splitmix64(slots.astype(np.uint64) * _SLOT ^ episodes.astype(np.uint64) * _EPISODE)
        )
        counters = base[None, :] + np.arange(1, draws + 1, dtype=np.uint64)[:, None] * _GOLDEN
        bits = _splitmix64(counters)
    return (bits >> np.uint64(11)).astype(np.float64) * (1.0 / 2**53)


def fresh_seed() -> int:
    """A seed drawn from the operating system's entropy."""
    entropy = np.random.SeedSequence().entropy
    assert isinstance(entropy, int)  # drawn from the OS, it is one number
    return entropy % 2**63
