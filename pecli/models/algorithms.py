"""The off-policy algorithms pecli trains with, each paired with its centralised-critic policy class.

    spec = get_algorithm("td3")
    model = spec.cls(spec.policy, env, policy_kwargs={**policy_kwargs(training), ...}, **algorithm_kwargs(training))

Every checkpoint records :func:`policy_kwargs` in its metadata, so that its networks can be rebuilt
from pecli's own JSON and the weights alone (nothing in a checkpoint is unpickled).

| name | class | actor |
| --- | --- | --- |
| td3, ddpg | Stable-Baselines3 TD3, DDPG | deterministic, Gaussian exploration noise |
| sac | Stable-Baselines3 SAC | squashed Gaussian; plays its mean |
| tqc | sb3-contrib TQC (quantile critics) | squashed Gaussian; plays its mean |
| crossq | sb3-contrib CrossQ (batch renormalisation, no target networks) | squashed Gaussian; plays its mean |
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
import torch as th
from sb3_contrib import TQC, CrossQ
from stable_baselines3 import DDPG, SAC, TD3
from stable_baselines3.common.noise import NormalActionNoise
from torch import nn

from pecli.errors import PecliError, PolicyError
from pecli.models.buffers import ConcatDictReplayBuffer, NStepDictReplayBuffer
from pecli.models.policies import (
    CentralCriticCrossQPolicy,
    CentralCriticPolicy,
    CentralCriticSACPolicy,
    CentralCriticTQCPolicy,
)

if TYPE_CHECKING:
    from pecli.scenario import Training


@dataclass(frozen=True)
class Algorithm:
    """One algorithm: its SB3 class, its policy class with a centralised critic, and how its actor plays.

    Args:
        name: what ``training.algo`` and ``--algo`` call it.
        cls: the SB3 algorithm class.
        policy: its policy class, whose critic reads the privileged state and the opponent's action.
        stochastic: the actor samples its actions while learning; it plays its deterministic action.
    """

    name: str
    cls: type
    policy: type
    stochastic: bool = False


ALGORITHMS: dict[str, Algorithm] = {
    "td3": Algorithm("td3", TD3, CentralCriticPolicy),
    "ddpg": Algorithm("ddpg", DDPG, CentralCriticPolicy),
    "sac": Algorithm("sac", SAC, CentralCriticSACPolicy, stochastic=True),
    "tqc": Algorithm("tqc", TQC, CentralCriticTQCPolicy, stochastic=True),
    "crossq": Algorithm("crossq", CrossQ, CentralCriticCrossQPolicy, stochastic=True),
}


def get_algorithm(name: str) -> Algorithm:
    """The algorithm called ``name``; :class:`PolicyError` if there is none."""
    if name not in ALGORITHMS:
        raise PolicyError(f"unknown algorithm '{name}' (known: {', '.join(ALGORITHMS)})")
    return ALGORITHMS[name]


def policy_kwargs(training: Training) -> dict[str, Any]:
    """The policy's keyword arguments that ``training`` decides, JSON-able; the feature extractor (the
    belief) is added by the caller. Recorded in every checkpoint's metadata.

    Arguments an algorithm sets behind the policy's back are spelled out (DDPG's single critic), as are
    the defaults that decide the networks' shapes (critics, quantiles), so that a later SB3 release
    with other defaults still rebuilds the same networks.
    """
    kwargs: dict[str, Any] = {"net_arch": list(training.net_arch), "n_critics": 1 if training.algo == "ddpg" else 2}
    if training.algo == "tqc":
        kwargs["n_quantiles"] = 25
    return kwargs


def optimizer_kwargs(training: Training) -> dict[str, Any]:
    """Adam's keyword arguments for actor and critics: the fused kernel, one call for all parameters (on
    CPU about 20 % less time per TD3 gradient step than torch's default per-tensor loop, measured by
    ``benchmarks/bench_train.py optimizer``), and CrossQ's own betas (sb3-contrib sets them only when no
    optimiser arguments are given)."""
    kwargs: dict[str, Any] = {"fused": True}
    if training.algo == "crossq":
        kwargs["betas"] = (0.5, 0.999)
    return kwargs


def algorithm_kwargs(training: Training) -> dict[str, Any]:
    """The algorithm's keyword arguments beyond those all of them share (learning rate, buffer, batch, ...)."""
    buffer = {
        "replay_buffer_class": ConcatDictReplayBuffer if training.algo == "crossq" else NStepDictReplayBuffer,
        "replay_buffer_kwargs": {"n_step": training.n_step, "gamma": training.gamma},
    }
    if training.algo == "crossq":  # no target networks, so no tau
        return buffer
    if get_algorithm(training.algo).stochastic:
        return {**buffer, "tau": training.tau}
    noise = NormalActionNoise(np.zeros(2), training.action_noise * np.ones(2))
    return {**buffer, "tau": training.tau, "action_noise": noise}


def deterministic_actor(actor: nn.Module) -> nn.Module:
    """The network from an SB3 actor's features to the action it plays, in [-1, 1]: ``(B, F) -> (B, 2)``.

    TD3's and DDPG's ``mu`` already ends in tanh; a squashed-Gaussian actor (SAC, TQC, CrossQ) plays the
    tanh of its mean, ``tanh(mu(latent_pi(features)))``, which is SB3's ``predict(deterministic=True)``.
    """
    if hasattr(actor, "latent_pi"):
        return nn.Sequential(actor.latent_pi, actor.mu, nn.Tanh())
    return actor.mu


def torch_device(name: str) -> th.device:
    """``cpu``, ``cuda`` (or ``cuda:N``) or ``auto`` (CUDA when there is one, as in SB3) as a torch device;
    :class:`PecliError` for a CUDA device this machine does not have."""
    if name == "auto":
        return th.device("cuda" if th.cuda.is_available() else "cpu")
    try:
        device = th.device(name)
    except RuntimeError:
        raise PecliError(f"unknown device '{name}' (use cpu, cuda or auto)") from None
    if device.type == "cuda":
        if not th.cuda.is_available():
            raise PecliError(
                f"--device {name}: this machine has no CUDA device that torch can use "
                f"(torch {th.__version__}); use --device cpu or auto"
            )
        if device.index is not None and device.index >= th.cuda.device_count():
            raise PecliError(f"--device {name}: this machine has {th.cuda.device_count()} CUDA device(s)")
    elif device.type != "cpu":
        raise PecliError(f"unsupported device '{name}' (use cpu, cuda or auto)")
    return device
