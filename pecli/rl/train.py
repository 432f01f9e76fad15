"""Train one role with SB3 TD3/DDPG against a frozen opponent, into a zoo run.

The whole loop in one place: build the batched view, the centralised-critic model and the
callbacks, learn, and write checkpoints. Interrupting (Ctrl-C) saves ``last`` with its replay
buffer; ``resume=True`` continues from there with the same schedule.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch as th
import yaml
from stable_baselines3.common.callbacks import CallbackList
from stable_baselines3.common.noise import NormalActionNoise

from pecli.errors import PecliError
from pecli.match import play_match
from pecli.policies import resolve_policy
from pecli.policies.learned import LearnedPolicy, algorithm_class
from pecli.rl.callbacks import CurriculumCallback, EpisodeStats, Evaluation, ProgressDisplay
from pecli.rl.policies import CentralCriticPolicy
from pecli.roles import Role, opponent_of
from pecli.scenario import Scenario, scenario_from_dict
from pecli.zoo import FINAL, LAST, REPLAY_BUFFER, CheckpointMeta, Run, read_metadata
from wrappers.frozen_opponent import FrozenOpponentVecEnv

DEFAULT_OPPONENT: dict[Role, str] = {"pursuer": "greedy", "evader": "pure-pursuit"}


def with_overrides(scenario: Scenario, overrides: dict[str, Any], source: str = "--set") -> Scenario:
    """The scenario with training settings replaced, e.g. ``{"steps": 10000, "curriculum.enabled": False}``."""
    data = scenario.model_dump(mode="json")
    for key, value in overrides.items():
        node = data["training"]
        *parents, leaf = key.split(".")
        for parent in parents:
            if not isinstance(node.get(parent), dict):
                raise PecliError(f"{source}: training has no section '{parent}' (in '{key}')")
            node = node[parent]
        node[leaf] = value
    return scenario_from_dict(data, source=source)


def parse_overrides(items: list[str]) -> dict[str, Any]:
    """``["steps=1e4", "curriculum.enabled=false"]`` → ``{"steps": 10000.0, ...}`` (values read as YAML)."""
    overrides: dict[str, Any] = {}
    for item in items:
        key, sep, text = item.partition("=")
        if not sep or not key.strip():
            raise PecliError(f"--set takes KEY=VALUE, got '{item}'")
        try:
            value = yaml.safe_load(text)
        except yaml.YAMLError:
            value = text
        if isinstance(value, float) and value.is_integer() and "." not in text and "e" in text.lower():
            value = int(value)  # 1e5 means a count here
        overrides[key.strip()] = value
    return overrides


@dataclass
class TrainJob:
    """Everything one ``pecli train`` needs."""

    role: Role
    scenario: Scenario
    opponent: str
    zoo: Path
    name: str
    seed: int = 0
    resume: bool = False
    progress: bool = True


def _meta(job: TrainJob, model: Any, episodes: int) -> CheckpointMeta:
    t = job.scenario.training
    return CheckpointMeta(
        role=job.role,
        steps=int(model.num_timesteps),
        episodes=episodes,
        algo=t.algo,
        belief="none",
        scenario=job.scenario.name,
        scenario_hash=job.scenario.fingerprint(),
        opponent=job.opponent,
        frame_skip=t.frame_skip,
        frame_stack=t.frame_stack,
        history_length=t.history_length,
        history_stride=t.history_stride,
        run=job.name,
        seed=job.seed,
    )


def make_model(job: TrainJob, env: FrozenOpponentVecEnv, tensorboard: Path | None) -> Any:
    """A fresh SB3 model with the paper's hyperparameters from the scenario's training section."""
    t = job.scenario.training
    return algorithm_class(t.algo)(
        CentralCriticPolicy,
        env,
        learning_rate=t.learning_rate,
        buffer_size=t.buffer_size,
        learning_starts=t.learning_starts,
        batch_size=t.batch_size,
        tau=t.tau,
        gamma=t.gamma,
        train_freq=(t.train_freq, "step"),
        gradient_steps=t.gradient_steps,
        action_noise=NormalActionNoise(np.zeros(2), t.action_noise * np.ones(2)),
        policy_kwargs={"net_arch": list(t.net_arch)},
        tensorboard_log=None if tensorboard is None else str(tensorboard),
        seed=job.seed,
        device="cpu",
        verbose=0,
    )


def evaluator(job: TrainJob, opponent: str) -> Callable[[Any], float]:
    """A function that plays the live model against ``opponent`` and returns the capture rate."""
    t = job.scenario.training
    scenario = job.scenario

    def evaluate(model: Any) -> float:
        learner = LearnedPolicy(model.policy.actor, job.role, scenario, _meta(job, model, 0))
        other = resolve_policy(opponent, opponent_of(job.role), scenario, seed=job.seed)
        players = (learner, other) if job.role == "pursuer" else (other, learner)
        model.policy.set_training_mode(False)
        result, _ = play_match(scenario, *players, episodes=t.eval_episodes, seed=10_000 + job.seed)
        return result.capture_rate

    return evaluate


def train(job: TrainJob, on_start: Callable[[Run], None] | None = None) -> Path:
    """Run ``job``; returns the final checkpoint. Ctrl-C saves ``last`` and re-raises ``KeyboardInterrupt``."""
    t = job.scenario.training
    th.set_num_threads(t.torch_threads)
    opponent = resolve_policy(job.opponent, opponent_of(job.role), job.scenario, seed=job.seed)
    env = FrozenOpponentVecEnv(job.scenario, job.role, opponent, n=t.n_envs, seed=job.seed)

    if job.resume:
        run = Run.open(job.zoo, job.name)
        run.log_command()
        last = run.checkpoint(job.role, LAST)
        if not last.is_file():
            raise PecliError(f"run '{job.name}' has no {job.role}/{LAST}.zip to resume from")
        episodes = read_metadata(last).episodes
        model = algorithm_class(t.algo).load(last, env=env, device="cpu", tensorboard_log=str(run.path / "tb"))
        buffer = run.role_dir(job.role) / REPLAY_BUFFER
        if buffer.is_file():
            model.load_replay_buffer(buffer)
    else:
        run = Run.create(job.zoo, job.name, job.scenario)
        episodes = 0
        model = make_model(job, env, run.path / "tb")
    if on_start is not None:
        on_start(run)

    stats = EpisodeStats(episodes=episodes)
    next_checkpoint = (episodes // t.checkpoint_every + 1) * t.checkpoint_every

    def checkpoint(total: int) -> None:
        nonlocal next_checkpoint
        while total >= next_checkpoint:
            run.save(model, job.role, Run.episode_name(next_checkpoint), _meta(job, model, total))
            next_checkpoint += t.checkpoint_every

    stats.listeners.append(checkpoint)
    callbacks = [stats, ProgressDisplay(stats, t.steps, f"{job.role} vs {job.opponent}", enabled=job.progress)]
    if t.curriculum.enabled:
        callbacks.insert(0, CurriculumCallback(job.scenario, t.steps, t.curriculum.fraction))
    if t.eval_every:
        eval_opponent = DEFAULT_OPPONENT[job.role]
        callbacks.append(Evaluation(evaluator(job, eval_opponent), t.eval_every, run.path / f"eval_{job.role}.csv"))

    remaining = t.steps - model.num_timesteps
    try:
        if remaining > 0:
            model.learn(
                remaining,
                callback=CallbackList(callbacks),
                reset_num_timesteps=not job.resume,
                tb_log_name=job.role,
            )
    except KeyboardInterrupt:
        run.save(model, job.role, LAST, _meta(job, model, stats.episodes))
        run.save_replay_buffer(model, job.role)
        raise
    run.save(model, job.role, LAST, _meta(job, model, stats.episodes))
    run.save_replay_buffer(model, job.role)
    return run.save(model, job.role, FINAL, _meta(job, model, stats.episodes))


def default_run_name(role: Role, scenario: Scenario, seed: int) -> str:
    """``<scenario>-<role>-s<seed>-<yyyymmdd-hhmmss>``."""
    return f"{scenario.name}-{role}-s{seed}-{time.strftime('%Y%m%d-%H%M%S')}"
