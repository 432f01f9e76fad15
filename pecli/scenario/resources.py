"""What a scenario will allocate when it trains, estimated and bounded before anything is allocated."""

from __future__ import annotations

from typing import Any

from pecli.errors import ConfigError
from pecli.scenario.schema import CarAgent, PointMassAgent, Scenario
from pecli.scenario.values import MAX_GAMES

MEMORY_LIMIT = 64 * 2**30  # bytes one training process may plan to allocate (memory_estimate)


def _size(size: int) -> str:
    """``~1,144 GiB``, ``~3.1 GiB``, ``~220 MiB``."""
    if size >= 10 * 2**30:
        return f"~{size / 2**30:,.0f} GiB"
    return f"~{size / 2**30:.2g} GiB" if size >= 2**30 else f"~{size / 2**20:.3g} MiB"


def _state_dim(agent: CarAgent | PointMassAgent) -> int:
    return 5 if agent.kind == "car" else 4  # (s_x, s_y, delta, v, psi) or (s_x, s_y, v_x, v_y)


def _mlp_parameters(sizes: list[int]) -> int:
    return sum(a * b + b for a, b in zip(sizes, sizes[1:]))


def memory_estimate(scenario: Scenario) -> dict[str, int]:
    """Roughly the bytes one learner of ``scenario`` allocates, by the setting that decides each part
    (``pecli selfplay`` holds two learners in one process: about twice this).

    ``training.n_envs``: the batched games with their frame stacks and history windows (about 1.5 KiB
    per game besides the windows, measured); ``training.buffer_size``: SB3's replay buffer (float32
    observations and next observations, actions, rewards, flags); ``training.belief_settings.buffer_size``:
    a learned belief's (window, position) pairs; ``training.net_arch``: actor and critics with their
    targets, gradients, Adam moments and one batch's activations; ``training.belief_settings.hidden``:
    the BiMDN's LSTM and one batch's activations.
    """
    t, b = scenario.training, scenario.training.belief_settings
    kp, ke = _state_dim(scenario.pursuer), _state_dim(scenario.evader)
    dim = kp + ke + 2  # one observation row: own state, opponent state, seen flag, time
    belief = t.belief != "none"
    window = -(-t.history_length // t.history_stride)
    features = (2 * b.samples if t.belief == "bimdn-mixed" else 2) if belief else 0
    obs = t.frame_stack * dim + (window * dim + features if belief else 0)
    transition = 2 * (obs + kp + ke + 1 + 2) + 2 + 3  # obs and next obs (+ state, opp_action), action, flags
    per_game = 1536 + 4 * dim * (2 * t.frame_stack + (t.history_length + 2 * window if belief else 0))
    critics = 2 if t.algo == "td3" else 1
    actor = _mlp_parameters([t.frame_stack * dim + features, *t.net_arch, 2])
    critic = _mlp_parameters([obs + kp + ke + 1 + 2 + 2, *t.net_arch, 1])
    activations = 2 * t.batch_size * sum(t.net_arch) * (1 + critics)  # forward and backward
    estimate = {
        "training.n_envs": t.n_envs * per_game,
        "training.buffer_size": 4 * t.buffer_size * transition,
        "training.net_arch": 4 * (5 * (actor + critics * critic) + activations),
    }
    if t.belief in ("bimdn", "bimdn-mixed", "image"):
        lstm = 2 * 4 * b.hidden * (dim + b.hidden + 2)  # two directions, four gates
        estimate["training.belief_settings.buffer_size"] = 4 * b.buffer_size * (window * dim + 3)
        estimate["training.belief_settings.hidden"] = 4 * (5 * lstm + 12 * b.batch_size * window * 2 * b.hidden)
    return estimate


_UNITS = {
    "training.n_envs": "games",
    "training.buffer_size": "transitions",
    "training.belief_settings.buffer_size": "pairs",
    "training.belief_settings.hidden": "LSTM units",
}


def check_resources(scenario: Scenario, source: str = "<dict>") -> None:
    """:class:`ConfigError` when ``scenario`` would make a training process allocate implausibly much
    (more than :data:`MAX_GAMES` games, or more than :data:`MEMORY_LIMIT` by :func:`memory_estimate`)."""
    estimate = memory_estimate(scenario)
    n_envs = scenario.training.n_envs
    if n_envs > MAX_GAMES:
        raise ConfigError(
            f"{source}: training.n_envs: {n_envs} games need {_size(estimate['training.n_envs'])}; "
            f"one process steps at most {MAX_GAMES} games"
        )
    total = sum(estimate.values())
    if total > MEMORY_LIMIT:
        key = max(estimate, key=estimate.__getitem__)
        value: Any = scenario.training
        for part in key.split(".")[1:]:
            value = getattr(value, part)
        what = f"{value} {_UNITS[key]}" if key in _UNITS else str(value)
        raise ConfigError(
            f"{source}: {key}: {what} need {_size(estimate[key])} (a training process of this "
            f"scenario needs {_size(total)} in all; the limit is {_size(MEMORY_LIMIT)})"
        )
