"""``pecli tune``: search training settings with Optuna, each trial trained within a CPU-time budget.

A trial draws its settings from the search space (:mod:`pecli.rl.search_space`), trains a pursuer or an
evader against a frozen opponent (or both by self-play) until it has used ``cpu_minutes`` of CPU time,
and evaluates its learner ``evaluations`` times along the way against a fixed set of opponents, on
evaluation seeds no training game uses. Each evaluation is reported to Optuna, whose pruner (median
or successive halving) stops hopeless trials early; the last one is the trial's score: the capture
rate for a pursuer, the escape rate for an evader, their mean in self-play. With ``repeats`` R > 1 a
trial trains R times on different seeds, one after the other, and scores the mean of their last
evaluations, so that settings which learn on one seed and fail on another rank below settings that
learn on every seed. A new study's first trial is the config's own settings (as far as the search
space can express them): the baseline.

The study lives in an Optuna storage (SQLite by default), with its settings in the study's user
attributes: ``--resume`` continues it, on this machine or another, and several processes (``--jobs``
or machines sharing a database) run trials together. A trial killed mid-way is found by its missing
heartbeat and run again with the same settings.
"""

from __future__ import annotations

import logging
import math
import multiprocessing
import os
import shutil
import socket
import time
import warnings
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import optuna
import torch as th
from stable_baselines3.common.callbacks import BaseCallback, CallbackList

from pecli.errors import PecliError
from pecli.locks import process_alive
from pecli.match import play_match
from pecli.policies import resolve_policy
from pecli.policies.learned import LearnedPolicy
from pecli.policies.registry import builtin_names, recorded_policy
from pecli.rl.callbacks import CurriculumCallback
from pecli.rl.search_space import config_point, parse_space, suggest
from pecli.rl.train import TrainJob, checkpoint_meta, make_learner, with_overrides
from pecli.roles import ROLES, Role, opponent_of
from pecli.scenario import Scenario, scenario_from_dict

# heartbeats, the stale-trial retry and multivariate TPE are flagged experimental by Optuna
warnings.filterwarnings("ignore", category=optuna.exceptions.ExperimentalWarning)
optuna.logging.set_verbosity(optuna.logging.WARNING)


class _NoInterruptReport(logging.Filter):
    """Drop Optuna's two lines on a trial stopped by Ctrl-C (its traceback, then "failed with value None"): the
    command says it was interrupted, and the trial runs again on ``--resume``."""

    def __init__(self) -> None:
        super().__init__()
        self.interrupted: str | None = None  # the "Trial N " of the interrupt just dropped

    def filter(self, record: logging.LogRecord) -> bool:
        message = record.getMessage()
        if record.exc_info and isinstance(record.exc_info[1], KeyboardInterrupt):
            self.interrupted = " ".join(message.split(" ")[:2]) + " "
            return False
        if self.interrupted is not None and message.startswith(self.interrupted + "failed with value"):
            self.interrupted = None
            return False
        return True


logging.getLogger("optuna.study._optimize").addFilter(_NoInterruptReport())

EVAL_SEED = 7_000_003  # evaluation games: no training run starts its games from this seed
WORKER_ATTR = "worker"  # a trial's user attribute: the host and PID of the process that runs it
HEARTBEAT_S = 30  # a running trial tells the storage it is alive this often ...
GRACE_S = 120  # ... and is taken as killed (and run again) when it has not for this long
PRUNERS = ("median", "halving", "none")
STARTUP_TRIALS = 5  # random trials before TPE models the scores (a study of CPU-minute trials is short)


@dataclass
class TuneSettings:
    """A study's settings, stored with it (so that ``--resume`` and other machines run the same study)."""

    what: str  # pursuer, evader or selfplay
    scenario: dict[str, Any]  # the config the trials start from (model_dump)
    space: dict[str, Any]  # the search space (validated)
    opponent: str | None  # the frozen opponent (pursuer, evader)
    eval_opponents: list[str]  # what the learner is scored against
    cpu_minutes: float
    evaluations: int = 6
    eval_episodes: int = 200
    pruner: str = "median"
    seed: int = 0
    repeats: int = 1  # training runs (seeds) per trial; the score is the mean of theirs
    space_text: str = field(default="", repr=False)

    @property
    def budget_s(self) -> float:
        """The CPU budget of one training run (a trial has ``repeats`` of them)."""
        return 60.0 * self.cpu_minutes


@dataclass
class Worker:
    """What one process needs to run trials: the study and where its scratch files go."""

    storage: str
    study: str
    total: int  # the study ends when this many trials are complete or pruned
    folder: Path  # scratch space of this study's trials (self-play runs)
    device: str = "cpu"
    seed: int = 0  # the sampler's seed of this process
    report: Callable[[str], None] = print


def sqlite_url(path: Path) -> str:
    """The Optuna storage URL of an SQLite file."""
    return f"sqlite:///{path}"


def open_storage(url: str) -> optuna.storages.RDBStorage:
    """The RDB storage at ``url`` with heartbeats, so that a killed trial is run again."""
    if url.startswith("sqlite:///"):
        Path(url.removeprefix("sqlite:///")).parent.mkdir(parents=True, exist_ok=True)
    engine = {"connect_args": {"timeout": 60}} if url.startswith("sqlite") else {}
    try:
        return optuna.storages.RDBStorage(
            url,
            engine_kwargs=engine,
            heartbeat_interval=HEARTBEAT_S,
            grace_period=GRACE_S,
            heartbeat_stale_trial_callback=optuna.storages.RetryHeartbeatStaleTrialCallback(max_retry=2),
        )
    except Exception as exc:  # SQLAlchemy raises many kinds for a bad URL or an unreachable server
        raise PecliError(f"cannot open the study storage '{url}': {type(exc).__name__}: {exc}") from None


def make_pruner(name: str, evaluations: int) -> optuna.pruners.BasePruner:
    """``median``: stop a trial whose evaluation is below the median of earlier trials at the same point
    (after 4 trials, not at the first two evaluations); ``halving``: successive halving; ``none``."""
    if name == "median":
        return optuna.pruners.MedianPruner(n_startup_trials=4, n_warmup_steps=min(2, evaluations - 1))
    if name == "halving":
        return optuna.pruners.SuccessiveHalvingPruner(min_resource=min(2, evaluations))
    if name == "none":
        return optuna.pruners.NopPruner()
    raise PecliError(f"unknown pruner '{name}' (known: {', '.join(PRUNERS)})")


def new_study(settings: TuneSettings, storage: str, name: str) -> optuna.Study:
    """A new study holding ``settings``; :class:`PecliError` if ``storage`` has one of that name."""
    store = open_storage(storage)
    if name in {s.study_name for s in optuna.get_all_study_summaries(store, include_best_trial=False)}:
        raise PecliError(f"study '{name}' exists in {storage}: continue it with --resume, or pick another --study")
    study = optuna.create_study(study_name=name, storage=store, direction="maximize")
    study.set_user_attr("settings", asdict(settings))
    objective = Objective(settings, Path("."))
    study.enqueue_trial(config_point(objective.space, objective.base.training), user_attrs={"baseline": True})
    return study


def load_study(storage: str, name: str) -> optuna.Study:
    """The stored study ``name``; :class:`PecliError` if there is none."""
    store = open_storage(storage)
    if name not in {s.study_name for s in optuna.get_all_study_summaries(store, include_best_trial=False)}:
        raise PecliError(f"no study '{name}' in {storage}")
    return optuna.load_study(study_name=name, storage=store)


def stored_settings(study: optuna.Study) -> TuneSettings:
    """The settings a study was created with; :class:`PecliError` for a study ``pecli tune`` did not make."""
    data = study.user_attrs.get("settings")
    if not isinstance(data, dict):
        raise PecliError(f"study '{study.study_name}' was not made by pecli tune (no settings)")
    try:
        settings = TuneSettings(**data)
    except TypeError as exc:
        raise PecliError(f"study '{study.study_name}': damaged settings ({exc})") from None
    if (
        not isinstance(settings.opponent, str | None)
        or not isinstance(settings.eval_opponents, list)
        or not all(isinstance(spec, str) for spec in settings.eval_opponents)
    ):
        raise PecliError(f"study '{study.study_name}': damaged settings (opponents are not policy strings)")
    for spec in [settings.opponent or "", *settings.eval_opponents]:  # the study's storage may come from elsewhere
        if spec:
            recorded_policy(spec, None, f"study '{study.study_name}'")
    return settings


def run_workers(worker: Worker, jobs: int) -> None:
    """Run trials in ``jobs`` processes (this one and ``jobs - 1`` children), one torch thread each."""
    os.environ["OMP_NUM_THREADS"] = "1"  # inherited by the children before they import torch
    context = multiprocessing.get_context("spawn")
    children = [
        context.Process(
            target=_child,
            args=(Worker(worker.storage, worker.study, worker.total, worker.folder, worker.device, worker.seed + j),),
            daemon=False,
        )
        for j in range(1, jobs)
    ]
    for child in children:
        child.start()
    try:
        optimize(worker)
    except BaseException:
        for child in children:
            child.terminate()  # their running trials are found stale and run again on --resume
        raise
    finally:
        for child in children:
            child.join()


def _child(worker: Worker) -> None:
    worker.report = lambda line: print(line, flush=True)
    try:
        optimize(worker)
    except KeyboardInterrupt:
        pass


def _finished(study: optuna.Study) -> int:
    states = (optuna.trial.TrialState.COMPLETE, optuna.trial.TrialState.PRUNED)
    return len(study.get_trials(deepcopy=False, states=states))


def optimize(worker: Worker) -> None:
    """Run trials of the study in this process until it has ``worker.total`` complete or pruned ones."""
    th.set_num_threads(1)
    store = open_storage(worker.storage)
    probe = optuna.load_study(study_name=worker.study, storage=store)
    settings = stored_settings(probe)
    study = optuna.load_study(
        study_name=worker.study,
        storage=store,
        # multivariate TPE over groups of parameters that appear together (those of one algorithm);
        # constant liar keeps parallel workers from sampling the same point
        sampler=optuna.samplers.TPESampler(
            seed=worker.seed, n_startup_trials=STARTUP_TRIALS, multivariate=True, group=True, constant_liar=True
        ),
        pruner=make_pruner(settings.pruner, settings.evaluations),
    )
    for number in reclaim_dead_trials(study):
        worker.report(f"trial {number} was running in a process that is gone: marked failed, and run again")
    left = worker.total - _finished(study)
    if left <= 0:
        return
    states = (optuna.trial.TrialState.COMPLETE, optuna.trial.TrialState.PRUNED)
    objective = Objective(settings, worker.folder, worker.device)
    study.optimize(
        objective,
        n_trials=left,
        catch=(PecliError, ValueError, RuntimeError),  # a failed trial, not a failed study
        callbacks=[optuna.study.MaxTrialsCallback(worker.total, states=states), _reporter(worker.report)],
    )


def reclaim_dead_trials(study: optuna.Study) -> list[int]:
    """Fail the study's running trials whose worker ran on this machine and is gone (killed, or the machine
    restarted), and queue each again (as Optuna does for a trial whose heartbeat stopped, at most twice per trial,
    without waiting out its grace period); returns their numbers. Trials run elsewhere wait for their
    heartbeat's grace period."""
    host, reclaimed = socket.gethostname(), []
    retry = optuna.storages.RetryHeartbeatStaleTrialCallback(max_retry=2)
    for trial in study.get_trials(deepcopy=False, states=(optuna.trial.TrialState.RUNNING,)):
        worker = trial.user_attrs.get(WORKER_ATTR)
        if not isinstance(worker, dict) or worker.get("host") != host or not isinstance(worker.get("pid"), int):
            continue
        if worker["pid"] != os.getpid() and process_alive(worker["pid"]):
            continue
        try:
            study._storage.set_trial_state_values(trial._trial_id, optuna.trial.TrialState.FAIL)
        except RuntimeError:  # it finished or failed meanwhile (another worker reclaimed it)
            continue
        retry(study, study._storage.get_trial(trial._trial_id))
        reclaimed.append(trial.number)
    return reclaimed


def _reporter(report: Callable[[str], None]) -> Callable[[optuna.Study, optuna.trial.FrozenTrial], None]:
    def after(study: optuna.Study, trial: optuna.trial.FrozenTrial) -> None:
        score = trial.value if trial.value is not None else trial.intermediate_values.get(trial.last_step or 0)
        shown = "-" if score is None else f"{score:.3f}"
        cpu = trial.user_attrs.get("cpu_seconds", math.nan) / 60
        params = ", ".join(f"{k}={_short(v)}" for k, v in trial.params.items())
        try:
            best = f"best {study.best_value:.3f} (trial {study.best_trial.number})"
        except ValueError:
            best = "no complete trial yet"
        report(f"trial {trial.number} {trial.state.name.lower()}: {shown} in {cpu:.1f} CPU-min [{params}]; {best}")

    return after


def _short(value: Any) -> str:
    return f"{value:.3g}" if isinstance(value, float) else str(value)


class Objective:
    """One trial: draw settings, train within the CPU budget, report evaluations, return the last."""

    def __init__(self, settings: TuneSettings, folder: Path, device: str = "cpu") -> None:
        self.settings, self.folder, self.device = settings, folder, device
        self.scenario = scenario_from_dict(settings.scenario, source="the study's config")
        self.space = parse_space(settings.space, "the study's search space")
        self.base = with_overrides(self.scenario, self.space.fixed, source="the study's fixed settings")

    def __call__(self, trial: optuna.Trial) -> float:
        trial.set_user_attr(WORKER_ATTR, {"host": socket.gethostname(), "pid": os.getpid()})  # who runs it
        overrides = suggest(trial, self.space, self.base.training)
        trial.set_user_attr("overrides", overrides)
        scenario = with_overrides(self.scenario, overrides, source=f"trial {trial.number}")
        s = self.settings
        train = self._selfplay if s.what == "selfplay" else self._one_role
        # the steps one run reports: its evaluations, or in self-play one per round (at most its rounds)
        stride = max(s.evaluations, scenario.training.selfplay.rounds) if s.what == "selfplay" else s.evaluations
        scores: list[float] = []
        start = time.process_time()
        try:
            for i in range(s.repeats):
                seed = s.seed + trial.number * s.repeats + i  # trial n's seeds: no other trial of the study uses them
                scores.append(
                    train(
                        trial,
                        scenario,
                        seed,
                        Clock(time.process_time(), s.budget_s, s.evaluations),
                        _Reporter(trial, scores, stride),
                    )
                )
        finally:
            trial.set_user_attr("cpu_seconds", round(time.process_time() - start, 2))
            trial.set_user_attr("scores", scores)
        return float(sum(scores) / len(scores))

    # -- one role against a frozen opponent ------------------------------------------------------------------
    def _one_role(self, trial: optuna.Trial, scenario: Scenario, seed: int, clock: Clock, report: _Reporter) -> float:
        role: Role = self.settings.what  # type: ignore[assignment]
        job = TrainJob(
            role=role,
            scenario=scenario,
            opponent=self.settings.opponent or "",
            zoo=self.folder,
            name=f"trial-{trial.number}",
            seed=seed,
            progress=False,
            device=self.device,
        )
        t = scenario.training
        opponent = resolve_policy(job.opponent, opponent_of(role), scenario, seed=seed)
        env, model, fit = make_learner(job, opponent, seed)
        callbacks: list[BaseCallback] = [] if fit is None else [fit]
        if t.curriculum.enabled and role == "pursuer":
            curriculum = CurriculumCallback(scenario, t.curriculum.span(t.steps))
            curriculum.apply_to(env, 0)
            callbacks.insert(0, curriculum)

        def evaluate(k: int) -> float:
            score = self.score(scenario, {role: (job, model)})
            report(k, score)
            return score

        budget = Budget(clock, evaluate)
        model.learn(t.steps, callback=CallbackList([*callbacks, budget]))
        return budget.finish()

    # -- both roles by self-play ---------------------------------------------------------------------------
    def _selfplay(self, trial: optuna.Trial, scenario: Scenario, seed: int, clock: Clock, report: _Reporter) -> float:
        from pecli.rl.selfplay import SelfPlay, SelfPlayJob

        folder = self.folder / f"trial-{trial.number}-{seed}"
        shutil.rmtree(folder, ignore_errors=True)  # a trial run again after a kill starts afresh
        loop = SelfPlay(
            SelfPlayJob(
                scenario=scenario, zoo=self.folder, name=folder.name, seed=seed, progress=False, device=self.device
            )
        )
        last: list[float] = []

        def after_round(r: int) -> bool:
            learners = {role: (loop.learners[role].train_job, loop.learners[role].model) for role in ROLES}
            k = clock.due()
            last.append(self.score(scenario, learners))
            report(k, last[-1])
            return not clock.spent()

        try:
            loop.run(after_round=after_round)
        finally:
            shutil.rmtree(folder, ignore_errors=True)
        return last[-1]

    # -- evaluation ----------------------------------------------------------------------------------------
    def score(self, scenario: Scenario, learners: dict[Role, tuple[TrainJob, Any]]) -> float:
        """The mean over learners and opponents of the learner's win rate: capture for a pursuer, escape for
        an evader; ``eval_episodes`` games each on the held-apart evaluation seeds."""
        s = self.settings
        rates = []
        for role, (job, model) in learners.items():
            learner = LearnedPolicy(model.policy.actor, role, scenario, checkpoint_meta(job, model, 0))
            for name in s.eval_opponents if s.what != "selfplay" else builtin_names(opponent_of(role)):
                other = resolve_policy(name, opponent_of(role), scenario, seed=EVAL_SEED)
                players = (learner, other) if role == "pursuer" else (other, learner)
                result, _ = play_match(scenario, *players, episodes=s.eval_episodes, seed=EVAL_SEED)
                rates.append(result.capture_rate if role == "pursuer" else 1.0 - result.capture_rate)
        return float(sum(rates) / len(rates))


class _Reporter:
    """Tells Optuna a trial's evaluations; raises :class:`optuna.TrialPruned` if the pruner stops the trial.

    Evaluation ``k`` (1 to ``stride``) of the trial's run ``i`` (``i`` earlier runs scored in ``scores``)
    is step ``i * stride + k``, and its value is the mean of the earlier runs' scores and this
    evaluation, so that the last value reported is the trial's score and trials compare step by step."""

    def __init__(self, trial: optuna.Trial, scores: list[float], stride: int) -> None:
        self.trial, self.scores, self.stride = trial, scores, stride

    def __call__(self, k: int, score: float) -> None:
        i = len(self.scores)
        value = (sum(self.scores) + score) / (i + 1)
        self.trial.report(value, i * self.stride + k)
        if self.trial.should_prune():
            raise optuna.TrialPruned(f"run {i + 1}, evaluation {k}: {score:.3f} (mean {value:.3f})")


class Clock:
    """A trial's CPU-time budget, cut into ``evaluations`` equal parts: evaluation ``k`` (1..K) is due after
    ``k / K`` of it."""

    def __init__(self, start: float, budget_s: float, evaluations: int) -> None:
        self.start, self.budget_s, self.evaluations = start, budget_s, evaluations
        self.done = 0  # evaluations made

    def used(self) -> float:
        return time.process_time() - self.start

    def spent(self) -> bool:
        return self.used() >= self.budget_s

    def is_due(self) -> bool:
        return self.done < self.evaluations and self.used() >= (self.done + 1) * self.budget_s / self.evaluations

    def due(self) -> int:
        """The step of the next evaluation (and count it made)."""
        self.done += 1
        return self.done


class Budget(BaseCallback):
    """Evaluates whenever the clock says so; stops ``learn`` once the CPU budget is spent."""

    def __init__(self, clock: Clock, evaluate: Callable[[int], float]) -> None:
        super().__init__()
        self.clock, self.evaluate = clock, evaluate
        self.last: float | None = None

    def _on_step(self) -> bool:
        if self.clock.is_due():
            self.last = self.evaluate(self.clock.due())
        return not self.clock.spent()

    def finish(self) -> float:
        """The trial's score: the evaluation at the end of the budget (made now if training ended sooner)."""
        if self.last is None or self.clock.done < self.clock.evaluations:
            self.last = self.evaluate(self.clock.evaluations)
            self.clock.done = self.clock.evaluations
        return self.last
