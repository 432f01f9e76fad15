"""Train one role with an SB3 algorithm (TD3, DDPG, SAC, TQC or CrossQ) against a frozen opponent, into a zoo run.

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

from pecli.belief.model import LEARNED_KINDS, features_dim
from pecli.errors import PecliError
from pecli.match import play_match
from pecli.models.algorithms import (
    algorithm_kwargs,
    get_algorithm,
    optimizer_kwargs,
    policy_kwargs,
    torch_device,
)
from pecli.models.checkpoint import restore_model
from pecli.models.extractors import BeliefExtractor
from pecli.policies import resolve_policy
from pecli.policies.base import Policy
from pecli.policies.learned import LearnedPolicy
from pecli.policies.mix import player_label
from pecli.progress import PeriodicLines
from pecli.rl.belief import BeliefBuffer, BeliefVecEnv, FitBelief
from pecli.rl.callbacks import (
    CpuBudget,
    CurriculumCallback,
    EpisodeStats,
    Evaluation,
    FiniteCheck,
    ProgressDisplay,
    every_episodes,
)
from pecli.rl.durable import DurableState
from pecli.rl.evaluations import evaluation_log, forget_evaluations_after
from pecli.roles import DEFAULT_OPPONENT, Role, opponent_of
from pecli.scenario import Scenario, scenario_from_dict
from pecli.text import cpu_time
from pecli.zoo import BEST, FINAL, LAST, RESUME_DIR, CheckpointMeta, Run, safe_run_name
from wrappers.frozen_opponent import FrozenOpponentVecEnv


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
        except RecursionError:
            raise PecliError(f"--set {key.strip()}: the value is nested too deeply") from None
        except ValueError:  # an integer of more digits than Python converts
            raise PecliError(f"--set {key.strip()}: the number has too many digits") from None
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
    ``cpu_budget`` ends the run at that many CPU seconds even before ``steps``; ``warm_start`` gives a new run
    the weights and optimiser states of a checkpoint written by the same network (a best response started from
    a player that already knows the game, :mod:`pecli.exploit`).
    """

    role: Role
    scenario: Scenario
    opponent: str
    zoo: Path
    name: str
    seed: int = 0
    resume: bool = False
    progress: bool = True
    log_every: float | None = None  # seconds between plain progress lines (a log's, when there is no bar); None: none
    curriculum_steps: int | None = None
    device: str = "cpu"  # where the networks train: cpu, cuda or auto (checkpoints always load on the CPU)
    cpu_budget: float | None = None  # CPU seconds of the run (all its processes) at which it stops, steps or not
    eval_opponent: str | None = None  # whom evaluations play (default: DEFAULT_OPPONENT of the role)
    eval_cpu_every: float | None = None  # evaluate every so many CPU seconds instead of every eval_every steps
    warm_start: Path | None = None  # a checkpoint of this role and network whose weights a new run starts from


def _job_record(job: TrainJob) -> dict[str, Any]:
    """What ``run.json`` keeps of a ``pecli train`` run for its resumes."""
    record: dict[str, Any] = {"command": "train", "role": job.role, "opponent": job.opponent, "seed": job.seed}
    if job.cpu_budget is not None:
        record["cpu_minutes"] = job.cpu_budget / 60.0
    return record


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
        policy_kwargs=policy_kwargs(t),
        belief_kwargs=belief_kwargs(job) if t.belief != "none" else None,
    )


def belief_kwargs(job: TrainJob) -> dict[str, Any]:
    """Keyword arguments of the actor's :class:`BeliefModel` for this job."""
    t, b = job.scenario.training, job.scenario.training.belief_settings
    window_length = -(-t.history_length // t.history_stride)  # observations in the window
    dim = _obs_dim(job.scenario, job.role)
    return {
        "kind": t.belief,
        "window": [window_length, dim],
        "scenario": job.scenario.model_dump(mode="json"),
        "role": job.role,
        "hidden": b.hidden,
        "fc": b.fc,
        "components": b.components,
        "samples": b.samples,
        "frame": job.scenario.observation_frame,
    }


def _obs_dim(scenario: Scenario, role: Role) -> int:
    from pecli.game.observation import ObservationCodec

    return ObservationCodec(scenario, role).dim


def make_env(job: TrainJob, opponent: Any, seed: int, view: Any = None) -> Any:
    """The batched learner view against ``opponent`` (or the given ``view``, such as one face of a
    :class:`~wrappers.simultaneous.SimultaneousGame`); with a belief, wrapped so that transitions
    carry its features."""
    t = job.scenario.training
    with_belief = t.belief != "none"
    if view is None:
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
    algorithm = get_algorithm(t.algo)
    kwargs: dict[str, Any] = {**policy_kwargs(t), "optimizer_kwargs": optimizer_kwargs(t)}
    if t.belief != "none":
        kwargs.update(
            features_extractor_class=BeliefExtractor, features_extractor_kwargs={"belief": belief_kwargs(job)}
        )
    return algorithm.cls(
        algorithm.policy,
        env,
        learning_rate=t.learning_rate,
        buffer_size=t.buffer_size,
        learning_starts=t.learning_starts,
        batch_size=t.batch_size,
        gamma=t.gamma,
        train_freq=(t.train_freq, "step"),
        gradient_steps=t.gradient_steps,
        policy_kwargs=kwargs,
        tensorboard_log=None if tensorboard is None else str(tensorboard),
        seed=job.seed,
        device=torch_device(job.device),
        verbose=0,
        **algorithm_kwargs(t),
    )


def attach_belief(job: TrainJob, env: Any, model: Any) -> FitBelief | None:
    """Give the learner view of ``make_env`` the actor's belief (its features go into every transition) and return
    the callback that fits it, for a learned belief; ``None`` where there is nothing to fit."""
    if not isinstance(env, BeliefVecEnv):
        return None
    belief = model.policy.actor.features_extractor.belief
    env.set_belief(belief)
    if not belief.learned or env.buffer is None:
        return None
    return FitBelief(belief, env.buffer, job.scenario.training.belief_settings, job.scenario.arena.half)


def make_learner(
    job: TrainJob, opponent: Any, seed: int, tensorboard: Path | None = None, view: Any = None
) -> tuple[Any, Any, FitBelief | None]:
    """The learner's batched view (:func:`make_env`), its fresh model (:func:`make_model`) and the callback that
    fits its belief (:func:`attach_belief`; ``None`` where nothing is fitted), built in the order they need."""
    env = make_env(job, opponent, seed, view=view)
    model = make_model(job, env, tensorboard)
    return env, model, attach_belief(job, env, model)


def play_live(job: TrainJob, model: Any, opponent: Policy, episodes: int, seed: int) -> float:
    """The capture rate of ``episodes`` games between the live ``model`` (playing ``job.role``, without exploration
    noise) and ``opponent``; the model's policy is left in evaluation mode (SB3 sets it back when it trains)."""
    learner = LearnedPolicy(model.policy.actor, job.role, job.scenario, checkpoint_meta(job, model, 0))
    players = (learner, opponent) if job.role == "pursuer" else (opponent, learner)
    model.policy.set_training_mode(False)
    result, _ = play_match(job.scenario, *players, episodes=episodes, seed=seed)
    return result.capture_rate


def evaluator(job: TrainJob, opponent: str) -> Callable[[Any], float]:
    """A function that plays the live model against ``opponent`` and returns the capture rate."""

    def evaluate(model: Any) -> float:
        other = resolve_policy(opponent, opponent_of(job.role), job.scenario, seed=job.seed)
        return play_live(job, model, other, job.scenario.training.eval_episodes, 10_000 + job.seed)

    return evaluate


def process_cpu_seconds() -> float:
    """CPU time of this process (all threads), s: what a run's ``cpu_seconds`` count."""
    return time.process_time()


def resume_seed(seed: int, steps: int) -> int:
    """The seed a run resumed at ``steps`` continues with: new start states and noise, still reproducible."""
    return int(np.random.SeedSequence([seed, steps]).generate_state(1)[0] % 2**31)


def train(
    job: TrainJob, on_start: Callable[[Run], None] | None = None, report: Callable[[str], None] = lambda line: None
) -> Path:
    """Run ``job``; returns the final checkpoint.

    At every checkpoint the learner's durable state (:mod:`pecli.rl.durable`) is committed, so a run
    stopped in any way resumes (``job.resume``) from its newest checkpoint. Ctrl-C (or SIGTERM, which
    the CLI turns into one) commits the state of the moment and raises :class:`TrainingInterrupted`.
    """
    cpu_start = process_cpu_seconds()
    t = job.scenario.training
    th.set_num_threads(t.torch_threads)
    opponent = resolve_policy(job.opponent, opponent_of(job.role), job.scenario, seed=job.seed)
    if job.resume:
        run = Run.open(job.zoo, job.name)
        durable = DurableState(run.role_dir(job.role) / RESUME_DIR)
        record = durable.read()
        if record is None:
            _start_over(run, job, durable, report)
    else:
        Run.check_new(job.zoo, job.name)
        run, durable, record = None, None, None
    env, model, fit = make_learner(
        job, opponent, job.seed if record is None else resume_seed(job.seed, record.steps), job.zoo / job.name / "tb"
    )
    if run is None:
        run = Run.create(
            job.zoo,
            job.name,
            job.scenario,
            _job_record(job),
        )
        durable = DurableState(run.role_dir(job.role) / RESUME_DIR)
    else:
        run.log_command()
        if job.cpu_budget is not None:  # a budget given on resume becomes the run's
            run.write_job({**(run.job() or {}), **_job_record(job)})
    episodes, cpu_before = 0, 0.0
    if record is None and job.warm_start is not None:
        restore_model(model, job.warm_start)
    if record is not None:
        durable.restore(record, model, fit)
        model.set_random_seed(resume_seed(job.seed, record.steps))
        episodes, cpu_before = record.episodes, record.cpu_seconds
        forget_evaluations_after(evaluation_log(run.path, job.role), record.steps)
    if on_start is not None:
        on_start(run)

    def cpu_seconds() -> float:  # the run's CPU time: the stopped processes' (from the record) and this call's
        return cpu_before + process_cpu_seconds() - cpu_start

    def meta_now(episodes: int) -> CheckpointMeta:
        return checkpoint_meta(job, model, episodes, cpu_seconds())

    def commit(episodes: int, *names: str) -> Path:
        """Commit the durable state and publish its model as the checkpoints ``names`` and ``last``."""
        meta = meta_now(episodes)
        source = durable.save(model, fit, episodes, meta.cpu_seconds or 0.0)
        paths = [run.publish(source, job.role, name, meta) for name in (*names, LAST)]
        return paths[0]

    stats = EpisodeStats(episodes=episodes)
    every = t.checkpoint_every  # a checkpoint is named after the last boundary it passed
    stats.listeners.append(
        every_episodes(every, episodes, lambda total: commit(total, Run.episode_name(total // every * every)))
    )
    lines = None
    if job.log_every is not None:
        lines = PeriodicLines(
            job.name,
            t.steps,
            report,
            unit="steps",
            every=job.log_every,
            details=lambda: cpu_time(cpu_seconds(), job.cpu_budget),
        )
    callbacks = [
        FiniteCheck(),
        stats,
        ProgressDisplay(
            stats, t.steps, f"{job.role} vs {player_label(job.opponent)}", enabled=job.progress, lines=lines
        ),
    ]
    if t.curriculum.enabled and job.role == "pursuer":  # the paper's curriculum eases the pursuer's task
        schedule = job.curriculum_steps or t.steps
        curriculum = CurriculumCallback(job.scenario, t.curriculum.span(schedule))
        curriculum.apply_to(env, model.num_timesteps)  # the games SB3 starts before any callback runs
        callbacks.insert(0, curriculum)
    if fit is not None:
        callbacks.append(fit)
    if job.cpu_budget is not None:
        callbacks.insert(0, CpuBudget(cpu_seconds, job.cpu_budget))
    if t.eval_every or job.eval_cpu_every:
        eval_opponent = job.eval_opponent or DEFAULT_OPPONENT[job.role]

        def save_best(rate: float) -> None:
            meta = meta_now(stats.episodes)
            meta.eval_capture_rate = round(rate, 4)
            run.save(model, job.role, BEST, meta)

        def reported(steps: int, cpu: float, rate: float) -> None:
            report(
                f"{job.name}: {steps:,} steps, {cpu_time(cpu, job.cpu_budget)}, capture rate vs "
                f"{player_label(eval_opponent)}: {rate:.2f}"
            )

        callbacks.append(
            Evaluation(
                evaluator(job, eval_opponent),
                t.eval_every,
                evaluation_log(run.path, job.role),
                cpu_seconds,
                save_best,
                maximise=job.role == "pursuer",
                cpu_every=job.eval_cpu_every,
                on_record=reported,
            )
        )

    remaining = t.steps - model.num_timesteps
    try:
        if remaining > 0:
            model.learn(
                remaining,
                callback=CallbackList(callbacks),
                reset_num_timesteps=record is None,
                tb_log_name=job.role,
            )
    except KeyboardInterrupt:
        raise TrainingInterrupted(commit(stats.episodes)) from None
    finally:
        logger = getattr(model, "_logger", None)
        if logger is not None:
            logger.close()
    return commit(stats.episodes, FINAL)


def _start_over(run: Run, job: TrainJob, durable: DurableState, report: Callable[[str], None]) -> None:
    """A run with no durable state (it stopped before its first checkpoint): start it again from scratch,
    in the same folder, after clearing what the stopped attempt left. A run written by an older pecli
    (``last.zip`` and pickled buffers, no durable state) is refused: its progress would be lost."""
    if run.checkpoint(job.role, LAST).is_file():
        raise PecliError(
            f"run '{job.name}' was written by an older pecli (it has no {job.role}/{RESUME_DIR}/ state), "
            "which this one cannot resume; its checkpoints still play (with --trust): start a new run"
        )
    durable.clear()
    evaluation_log(run.path, job.role).unlink(missing_ok=True)
    report(f"run '{job.name}' stopped before its first checkpoint: nothing to resume, starting it over")


def default_run_name(what: str, scenario: Scenario, seed: int) -> str:
    """``<scenario>-<what>-s<seed>-<yyyymmdd-hhmmss>``, ``what`` a role or ``selfplay``."""
    return safe_run_name(f"{scenario.name}-{what}-s{seed}-{time.strftime('%Y%m%d-%H%M%S')}")
