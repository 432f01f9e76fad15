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
from pecli.belief.model import LEARNED_KINDS, features_dim
from pecli.rl.belief import BeliefBuffer, BeliefVecEnv, FitBelief
from pecli.rl.callbacks import CurriculumCallback, EpisodeStats, Evaluation, FiniteCheck, ProgressDisplay
from pecli.rl.extractors import BeliefExtractor
from pecli.rl.policies import CentralCriticPolicy
from pecli.roles import Role, opponent_of
from pecli.scenario import Scenario, scenario_from_dict
from pecli.zoo import BEST, FINAL, LAST, CheckpointMeta, Run, read_metadata, safe_run_name
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
    """``["steps=1e4", "curriculum.enabled=false"]`` → ``{"steps": 10000, "curriculum.enabled": False}``.

    Values are read as YAML; a number in exponent form that is whole (``1e4``) becomes an integer.
    """
    overrides: dict[str, Any] = {}
    for item in items:
        key, sep, text = item.partition("=")
        if not sep or not key.strip():
            raise PecliError(f"--set takes KEY=VALUE, got '{item}'")
        try:
            value = yaml.safe_load(text)
        except yaml.YAMLError:
            value = text
        if isinstance(value, str):
            try:
                number = float(value)
            except ValueError:
                pass
            else:
                value = int(number) if number.is_integer() else number
        overrides[key.strip()] = value
    return overrides


class TrainingInterrupted(Exception):
    """Training stopped on Ctrl-C (or SIGTERM) after saving ``checkpoint`` for ``--resume``."""

    def __init__(self, checkpoint: Path) -> None:
        super().__init__(str(checkpoint))
        self.checkpoint = checkpoint


@dataclass
class TrainJob:
    """Everything one ``pecli train`` needs.

    ``curriculum_steps`` is the budget the curriculum is scheduled over: the run's original budget,
    so that a resumed run with a larger ``--steps`` continues the schedule instead of rewinding it.
    """

    role: Role
    scenario: Scenario
    opponent: str
    zoo: Path
    name: str
    seed: int = 0
    resume: bool = False
    progress: bool = True
    curriculum_steps: int | None = None


def checkpoint_meta(job: TrainJob, model: Any, episodes: int, cpu_seconds: float | None = None) -> CheckpointMeta:
    """The metadata written beside a checkpoint of ``model`` after ``episodes`` episodes and ``cpu_seconds``."""
    t = job.scenario.training
    return CheckpointMeta(
        role=job.role,
        steps=int(model.num_timesteps),
        episodes=episodes,
        algo=t.algo,
        belief=t.belief,
        scenario=job.scenario.name,
        scenario_hash=job.scenario.fingerprint(),
        opponent=job.opponent,
        frame_skip=t.frame_skip,
        frame_stack=t.frame_stack,
        history_length=t.history_length,
        history_stride=t.history_stride,
        run=job.name,
        seed=job.seed,
        cpu_seconds=None if cpu_seconds is None else round(cpu_seconds, 2),
    )


def belief_kwargs(job: TrainJob) -> dict[str, Any]:
    """Keyword arguments of the actor's :class:`BeliefModel` for this job."""
    t, b = job.scenario.training, job.scenario.training.belief_settings
    window_length = -(-t.history_length // t.history_stride)  # observations in the window
    dim = _obs_dim(job.scenario, job.role)
    return {
        "kind": t.belief, "window": (window_length, dim), "scenario": job.scenario.model_dump(mode="json"),
        "role": job.role, "hidden": b.hidden, "fc": b.fc, "components": b.components, "samples": b.samples,
        "frame": job.scenario.observation_frame,
    }


def _obs_dim(scenario: Scenario, role: Role) -> int:
    from pecli.game.observation import ObservationCodec

    return ObservationCodec(scenario, role).dim


def make_env(job: TrainJob, opponent: Any, seed: int) -> FrozenOpponentVecEnv | BeliefVecEnv:
    """The batched learner view; with a belief, wrapped so that transitions carry its features."""
    t = job.scenario.training
    with_belief = t.belief != "none"
    view = FrozenOpponentVecEnv(job.scenario, job.role, opponent, n=t.n_envs, seed=seed, history=with_belief)
    if not with_belief:
        return view
    buffer = None
    if t.belief in LEARNED_KINDS:
        window = view.observation_space["history"].shape[0]
        buffer = BeliefBuffer(t.belief_settings.buffer_size, window, seed=seed)
    return BeliefVecEnv(view, features_dim(t.belief, t.belief_settings.samples), buffer)


def make_model(job: TrainJob, env: FrozenOpponentVecEnv | BeliefVecEnv, tensorboard: Path | None) -> Any:
    """A fresh SB3 model with the paper's hyperparameters from the scenario's training section."""
    t = job.scenario.training
    policy_kwargs: dict[str, Any] = {"net_arch": list(t.net_arch)}
    if t.belief != "none":
        policy_kwargs.update(features_extractor_class=BeliefExtractor, features_extractor_kwargs={"belief": belief_kwargs(job)})
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
        policy_kwargs=policy_kwargs,
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
        learner = LearnedPolicy(model.policy.actor, job.role, scenario, checkpoint_meta(job, model, 0))
        other = resolve_policy(opponent, opponent_of(job.role), scenario, seed=job.seed)
        players = (learner, other) if job.role == "pursuer" else (other, learner)
        model.policy.set_training_mode(False)
        result, _ = play_match(scenario, *players, episodes=t.eval_episodes, seed=10_000 + job.seed)
        return result.capture_rate

    return evaluate


def process_cpu_seconds() -> float:
    """CPU time of this process (all threads), s: what a run's ``cpu_seconds`` count."""
    return time.process_time()


def resume_seed(seed: int, steps: int) -> int:
    """The seed a run resumed at ``steps`` continues with: new start states and noise, still reproducible."""
    return int(np.random.SeedSequence([seed, steps]).generate_state(1)[0] % 2**31)


def train(job: TrainJob, on_start: Callable[[Run], None] | None = None) -> Path:
    """Run ``job``; returns the final checkpoint.

    Ctrl-C saves ``last`` with the replay buffer and raises :class:`TrainingInterrupted`.
    """
    cpu_start = process_cpu_seconds()
    t = job.scenario.training
    th.set_num_threads(t.torch_threads)
    opponent = resolve_policy(job.opponent, opponent_of(job.role), job.scenario, seed=job.seed)
    if job.resume:
        run = Run.open(job.zoo, job.name)
        last = run.checkpoint(job.role, LAST)
        if not last.is_file():
            raise PecliError(f"run '{job.name}' has no {job.role}/{LAST}.zip to resume from")
        meta = read_metadata(last)
        seed = resume_seed(job.seed, meta.steps)
        env = make_env(job, opponent, seed)
        model = algorithm_class(t.algo).load(last, env=env, device="cpu", tensorboard_log=str(run.path / "tb"))
        model.set_random_seed(seed)
        run.log_command()
        episodes, cpu_before = meta.episodes, meta.cpu_seconds or 0.0
    else:
        Run.check_new(job.zoo, job.name)
        env = make_env(job, opponent, job.seed)
        model = make_model(job, env, job.zoo / job.name / "tb")
        run = Run.create(job.zoo, job.name, job.scenario)
        episodes, cpu_before = 0, 0.0
    belief = None
    if isinstance(env, BeliefVecEnv):
        belief = model.policy.actor.features_extractor.belief
        env.set_belief(belief)
    if on_start is not None:
        on_start(run)

    def cpu_seconds() -> float:  # the run's CPU time: the stopped processes' (from the checkpoint) and this call's
        return cpu_before + process_cpu_seconds() - cpu_start

    def meta_now(episodes: int) -> CheckpointMeta:
        return checkpoint_meta(job, model, episodes, cpu_seconds())

    stats = EpisodeStats(episodes=episodes)
    next_checkpoint = (episodes // t.checkpoint_every + 1) * t.checkpoint_every

    def checkpoint(total: int) -> None:
        nonlocal next_checkpoint
        while total >= next_checkpoint:
            run.save(model, job.role, Run.episode_name(next_checkpoint), meta_now(total))
            next_checkpoint += t.checkpoint_every

    stats.listeners.append(checkpoint)
    callbacks = [FiniteCheck(), stats, ProgressDisplay(stats, t.steps, f"{job.role} vs {job.opponent}", enabled=job.progress)]
    if t.curriculum.enabled and job.role == "pursuer":  # the paper's curriculum eases the pursuer's task
        schedule = job.curriculum_steps or t.steps
        curriculum = CurriculumCallback(job.scenario, schedule, t.curriculum.fraction)
        curriculum.apply_to(env, model.num_timesteps)  # the games SB3 starts before any callback runs
        callbacks.insert(0, curriculum)
    fit = None
    if belief is not None and belief.learned and env.buffer is not None:
        fit = FitBelief(belief, env.buffer, t.belief_settings, job.scenario.arena.half)
        callbacks.append(fit)
    if job.resume:
        run.load_replay_buffer(model, job.role, fit)
    if t.eval_every:
        eval_opponent = DEFAULT_OPPONENT[job.role]

        def save_best(rate: float) -> None:
            meta = meta_now(stats.episodes)
            meta.eval_capture_rate = round(rate, 4)
            run.save(model, job.role, BEST, meta)

        callbacks.append(Evaluation(evaluator(job, eval_opponent), t.eval_every, run.path / f"eval_{job.role}.csv",
                                    cpu_seconds, save_best, maximise=job.role == "pursuer"))

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
        last = run.save(model, job.role, LAST, meta_now(stats.episodes))
        run.save_replay_buffer(model, job.role, fit)
        raise TrainingInterrupted(last) from None
    finally:
        logger = getattr(model, "_logger", None)
        if logger is not None:
            logger.close()
    run.save(model, job.role, LAST, meta_now(stats.episodes))
    run.save_replay_buffer(model, job.role, fit)
    return run.save(model, job.role, FINAL, meta_now(stats.episodes))


def default_run_name(what: str, scenario: Scenario, seed: int) -> str:
    """``<scenario>-<what>-s<seed>-<yyyymmdd-hhmmss>``, ``what`` a role or ``selfplay``."""
    return safe_run_name(f"{scenario.name}-{what}-s{seed}-{time.strftime('%Y%m%d-%H%M%S')}")
