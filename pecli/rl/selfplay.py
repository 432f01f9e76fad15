"""Alternating self-play: each round trains the pursuer against the evader pool, then the evader
against the pursuer pool, and adds each new checkpoint to its side's pool.

Both learners live for the whole run: their networks, optimisers and replay buffers carry over
from round to round. Each side's pool starts with the heuristic baselines. Within a turn, every
batched game draws its opponent from the pool when it starts (:class:`~pecli.policies.mixed.MixedPolicy`),
so one batch holds many opponents at once.

A run in the zoo::

    zoo/<run>/
        config.yaml, command.txt, versions.json, tb/     as for ``pecli train``
        selfplay.json                the state: pools and their records, finished turns, seeds
        pursuer/round-001.zip/.json  the pursuer after round 1, with its lineage in the metadata
        pursuer/resume/              the pursuer's durable state (pecli.rl.durable): model, optimisers, buffers
        evader/...

Each learner commits its durable state every ``checkpoint_every`` episodes of its turn, with the
turn's progress (steps, opponent records), and at the end of the turn; then ``selfplay.json``
records the finished turn. A run stopped in any way resumes inside the turn it was in, from the
learner's newest commit: at most one checkpoint interval is lost.
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
import torch as th
from stable_baselines3.common.callbacks import CallbackList

from pecli.errors import PecliError
from pecli.io import atomic_write_json
from pecli.policies import resolve_policy
from pecli.policies.base import Policy
from pecli.policies.mixed import MixedPolicy
from pecli.policies.registry import builtin_names
from pecli.rl.belief import BeliefVecEnv, FitBelief
from pecli.rl.callbacks import CurriculumCallback, PoolTracker, RoundDisplay
from pecli.rl.pool import OpponentPool, predicted_win_rate
from pecli.rl.durable import DurableState
from pecli.rl.train import TrainJob, checkpoint_meta, make_env, make_model, resume_seed
from pecli.roles import ROLES, Role, opponent_of
from pecli.scenario import Scenario
from pecli.zoo import RESUME_DIR, Run, tournament_ratings

STATE_FILE = "selfplay.json"


class SelfPlayInterrupted(Exception):
    """Self-play stopped (Ctrl-C, SIGTERM) in ``round``, while ``role`` trained; finished turns are saved."""

    def __init__(self, round: int, role: Role) -> None:
        super().__init__(f"round {round}, {role}")
        self.round, self.role = round, role


@dataclass
class SelfPlayJob:
    """Everything one ``pecli selfplay`` needs; the rounds and their sizes are in ``scenario.training.selfplay``."""

    scenario: Scenario
    zoo: Path
    name: str
    seed: int = 0
    resume: bool = False
    progress: bool = True


@dataclass
class Turn:
    """One side's training in one round."""

    round: int
    role: Role
    steps: int  # the learner's total transitions at the end of the turn
    episodes: int
    captures: int
    cpu_seconds: float
    checkpoint: str  # run-relative
    opponents: int  # entries in the opponents' pool during the turn

    @property
    def capture_rate(self) -> float:
        return self.captures / self.episodes if self.episodes else float("nan")


@dataclass
class SelfPlayState:
    """What ``selfplay.json`` holds."""

    seed: int
    curriculum_steps: int  # the span the curriculum is scheduled over (fixed when the run starts)
    pools: dict[str, OpponentPool]
    turns: list[Turn] = field(default_factory=list)

    def done(self, round: int, role: Role) -> bool:
        return any(t.round == round and t.role == role for t in self.turns)

    def latest(self, role: Role) -> Turn | None:
        mine = [t for t in self.turns if t.role == role]
        return mine[-1] if mine else None

    def to_dict(self) -> dict[str, Any]:
        return {
            "seed": self.seed,
            "curriculum_steps": self.curriculum_steps,
            "pools": {role: pool.to_dict() for role, pool in self.pools.items()},
            "turns": [asdict(t) for t in self.turns],
        }

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> SelfPlayState:
        return cls(
            seed=int(data["seed"]),
            curriculum_steps=int(data["curriculum_steps"]),
            pools={role: OpponentPool.from_dict(pool) for role, pool in data["pools"].items()},
            turns=[Turn(**{key: value for key, value in t.items() if key in Turn.__dataclass_fields__}) for t in data["turns"]],
        )


def read_state(run: Run) -> SelfPlayState:
    """The state of a self-play run; :class:`PecliError` if it has none or it is damaged."""
    path = run.path / STATE_FILE
    if not path.is_file():
        raise PecliError(f"run '{run.name}' is not a self-play run (no {STATE_FILE}): resume it with `pecli train`")
    try:
        return SelfPlayState.from_dict(json.loads(path.read_text()))
    except (json.JSONDecodeError, KeyError, TypeError, ValueError) as exc:
        raise PecliError(f"{path}: damaged self-play state ({type(exc).__name__}: {exc})") from None


def turn_seed(seed: int, round: int, role: Role) -> int:
    """The seed of one turn: fixed by the run's seed, so a resumed run plays the turns it would have."""
    return int(np.random.SeedSequence([seed, round, ROLES.index(role)]).generate_state(1)[0] % 2**31)


def checkpoint_name(round: int) -> str:
    """The name of a learner's checkpoint after ``round``: ``round-003``."""
    return f"round-{round:03d}"


def initial_state(scenario: Scenario, seed: int) -> SelfPlayState:
    """Pools holding the baselines of each role: generation 0."""
    sp = scenario.training.selfplay
    pools = {role: OpponentPool(role) for role in ROLES}
    for role in ROLES:
        for name in builtin_names(role):
            pools[role].add(name, name, generation=0)
    return SelfPlayState(seed=seed, curriculum_steps=sp.rounds * sp.steps_per_round, pools=pools)


class Learner:
    """One side of self-play: its SB3 model, its batched view, its durable state and the callbacks that outlive a turn."""

    def __init__(self, job: SelfPlayJob, role: Role, placeholder: Policy, run: Run, state: SelfPlayState) -> None:
        """Build the learner of ``role`` afresh, or from its durable state when it has one."""
        self.role = role
        self.train_job = TrainJob(role=role, scenario=job.scenario, opponent="selfplay", zoo=job.zoo, name=job.name,
                                  seed=job.seed)
        self.env = make_env(self.train_job, placeholder, job.seed)
        t = job.scenario.training
        self.model = make_model(self.train_job, self.env, run.path / "tb")
        self.callbacks: list[Any] = []
        self.curriculum: CurriculumCallback | None = None
        if t.curriculum.enabled:
            self.curriculum = CurriculumCallback(job.scenario, state.curriculum_steps, t.curriculum.fraction)
            self.callbacks.append(self.curriculum)
        self.fit: FitBelief | None = None
        if isinstance(self.env, BeliefVecEnv):
            belief = self.model.policy.actor.features_extractor.belief
            self.env.set_belief(belief)
            if belief.learned and self.env.buffer is not None:
                self.fit = FitBelief(belief, self.env.buffer, t.belief_settings, job.scenario.arena.half)
                self.callbacks.append(self.fit)
        self.durable = DurableState(run.role_dir(role) / RESUME_DIR)
        record = self.durable.read()
        if record is not None:
            self.durable.restore(record, self.model, self.fit)
        elif state.latest(role) is not None:
            raise PecliError(f"run '{run.name}' was written by an older pecli (its {role} has no {RESUME_DIR}/ state), "
                             "which this one cannot resume; its checkpoints still play (with --trust)")
        else:
            self.durable.clear()  # what a stop before the first commit left

    def progress(self, round: int) -> dict[str, Any] | None:
        """The committed progress of the learner's turn in ``round`` (``None`` if it has none)."""
        record = self.durable.record
        if record is None or record.extra.get("round") != round:
            return None
        return record.extra


class SelfPlay:
    """Runs a :class:`SelfPlayJob`; :meth:`run` returns the last checkpoint of each side."""

    def __init__(self, job: SelfPlayJob, report: Callable[[str], None] = lambda line: None) -> None:
        self.job = job
        self.report = report
        self.scenario = job.scenario
        self.settings = job.scenario.training.selfplay
        if job.resume:
            self.run_dir = Run.open(job.zoo, job.name)
            self.state = read_state(self.run_dir)
            self.run_dir.log_command()
            if self.run_dir.scenario() != job.scenario:  # more rounds: the run's config says so from now on
                self.run_dir.write_config(job.scenario)
        else:
            Run.check_new(job.zoo, job.name)
            self.state = initial_state(job.scenario, job.seed)
            self.run_dir = Run.create(job.zoo, job.name, job.scenario, {"command": "selfplay", "seed": job.seed})
            self._save_state()
        self._policies: dict[tuple[Role, str], Policy] = {}
        self.learners: dict[Role, Learner] = {}

    # -- pools -------------------------------------------------------------------------------
    def _policy(self, role: Role, spec: str) -> Policy:
        """The frozen policy of a pool entry, loaded once per process."""
        key = (role, spec)
        if key not in self._policies:
            path = self.run_dir.path / spec
            target = str(path) if spec.endswith(".zip") else spec
            self._policies[key] = resolve_policy(target, role, self.scenario, seed=self.job.seed)
        return self._policies[key]

    def _mixed(self, role: Role) -> MixedPolicy:
        pool = self.state.pools[role]
        if not pool.entries:
            raise PecliError(f"the {role} pool of run '{self.run_dir.name}' is empty (damaged {STATE_FILE}?)")
        members = [self._policy(role, e.spec) for e in pool.entries]
        return MixedPolicy(role, members, [e.name for e in pool.entries])

    def _priors(self, learner: Role) -> dict[str, float]:
        """PFSP priors: each entry's predicted win rate against the learner's latest checkpoint, from the
        newest tournament under the zoo, when it rated both."""
        latest = self.state.latest(learner)
        if latest is None or self.settings.opponents != "pfsp":
            return {}
        ratings = tournament_ratings(self.job.zoo)
        mine = ratings.get(str((self.run_dir.path / latest.checkpoint).resolve()))
        if mine is None or mine.get("role") != learner:
            return {}
        other = opponent_of(learner)
        priors = {}
        for e in self.state.pools[other].entries:
            key = str((self.run_dir.path / e.spec).resolve()) if e.spec.endswith(".zip") else f"{other}:{e.spec}"
            if key in ratings and ratings[key].get("role") == other:
                priors[e.name] = predicted_win_rate(ratings[key]["elo"], mine["elo"])
        return priors

    def _weigher(self, learner: Role) -> Callable[[OpponentPool], np.ndarray]:
        sp, priors = self.settings, self._priors(learner)
        return lambda pool: pool.weights(sp.opponents, sp.pfsp_power, priors, sp.pfsp_prior_episodes)

    # -- the loop ------------------------------------------------------------------------------
    def run(self) -> dict[Role, Path]:
        th.set_num_threads(self.scenario.training.torch_threads)
        for role in ROLES:
            self.learners[role] = Learner(self.job, role, self._mixed(opponent_of(role)), self.run_dir, self.state)
        for r in range(1, self.settings.rounds + 1):
            if all(self.state.done(r, role) for role in ROLES):
                continue
            for role in ROLES:
                if not self.state.done(r, role):
                    self._turn(r, role)
            self.report(self._summary(r))
        return {role: self.run_dir.path / self.state.latest(role).checkpoint for role in ROLES}

    def _turn(self, r: int, role: Role) -> None:
        """Train ``role`` for round ``r``, or the rest of it when its learner committed part of it."""
        sp, learner = self.settings, self.learners[role]
        t = self.scenario.training
        other = opponent_of(role)
        pool = self.state.pools[other]
        if self.state.latest(role) is not None:  # a new round: the learner moved on from last time's records
            pool.decay(sp.pfsp_decay)
        weigh = self._weigher(role)
        mixed = self._mixed(other)
        mixed.weights = weigh(pool)
        tracker = PoolTracker(pool, mixed, weigh if sp.opponents == "pfsp" else None)
        model = learner.model
        progress = learner.progress(r)
        if progress is None:
            progress = {"round": r, "start_steps": int(model.num_timesteps), "cpu_seconds": 0.0}
        else:  # resumed inside the turn: its records so far
            tracker.restore(progress["tracker"])
        seed = turn_seed(self.state.seed, r, role)
        if model.num_timesteps > progress["start_steps"]:  # new games from a seed of their own
            seed = resume_seed(seed, int(model.num_timesteps))
        learner.env.env_method("set_opponent", mixed)
        if learner.curriculum is not None:  # the games SB3 starts before any callback runs count too
            learner.curriculum.apply_to(learner.env, model.num_timesteps)
        model.set_env(learner.env, force_reset=True)  # every game starts afresh against the new pool
        model.set_random_seed(seed)

        cpu = time.process_time()

        def commit() -> Path:
            """Commit the learner's durable state with the turn's progress so far."""
            nonlocal cpu
            now = time.process_time()
            progress.update(tracker=tracker.to_dict(), cpu_seconds=progress["cpu_seconds"] + now - cpu)
            cpu = now
            episodes = sum(turn.episodes for turn in self.state.turns if turn.role == role) + tracker.episodes
            run_cpu = sum(turn.cpu_seconds for turn in self.state.turns) + progress["cpu_seconds"]
            return learner.durable.save(model, learner.fit, episodes, run_cpu, extra=dict(progress))

        next_commit = (tracker.episodes // t.checkpoint_every + 1) * t.checkpoint_every

        def checkpoint(episodes: int) -> None:
            nonlocal next_commit
            if episodes >= next_commit:
                commit()
                next_commit = (episodes // t.checkpoint_every + 1) * t.checkpoint_every

        tracker.listeners.append(checkpoint)
        remaining = progress["start_steps"] + sp.steps_per_round - int(model.num_timesteps)
        title = f"round {r}/{sp.rounds} · {role} vs {len(pool.entries)} {other}s ({sp.opponents})"
        display = RoundDisplay(tracker, sp.steps_per_round, title, enabled=self.job.progress)
        try:
            try:
                if remaining > 0:
                    model.learn(remaining, callback=CallbackList([*learner.callbacks, tracker, display]),
                                reset_num_timesteps=False, tb_log_name=role)
            finally:
                display.close()
                logger = getattr(model, "_logger", None)
                if logger is not None:
                    logger.close()
            self._finish_turn(r, role, tracker, commit)
        except KeyboardInterrupt:
            commit()
            raise SelfPlayInterrupted(r, role) from None

    def _finish_turn(self, r: int, role: Role, tracker: PoolTracker, commit: Callable[[], Path]) -> None:
        learner, other = self.learners[role], opponent_of(role)
        previous = self.state.latest(role)
        episodes = sum(t.episodes for t in self.state.turns if t.role == role) + tracker.episodes
        weights = dict(zip(tracker.opponent.names, tracker.opponent.weights))
        meta = replace(
            checkpoint_meta(learner.train_job, learner.model, episodes),
            opponent=f"selfplay:{self.settings.opponents}",
            round=r,
            parent=previous.checkpoint if previous else "",
            opponents=[
                {"name": e.name, "spec": e.spec, "generation": e.generation, "weight": round(float(weights[e.name]), 4),
                 "episodes": tracker.per_opponent[e.name][0], "opponent_wins": tracker.per_opponent[e.name][1]}
                for e in self.state.pools[other].entries
            ],
        )
        # the learner's durable state first, then its round checkpoint, then selfplay.json (the commit of
        # the turn): a stop in between resumes inside the turn with nothing left to train, and finishes it
        source = commit()
        path = self.run_dir.publish(source, role, checkpoint_name(r), meta)
        relative = str(path.relative_to(self.run_dir.path))
        self.state.pools[role].add(f"{role}-r{r:03d}", relative, generation=r)
        cpu_seconds = learner.durable.record.extra["cpu_seconds"]
        self.state.turns.append(Turn(r, role, int(learner.model.num_timesteps), tracker.episodes, tracker.captures,
                                     round(cpu_seconds, 2), relative, len(tracker.opponent.names)))
        self._save_state()

    def _save_state(self) -> None:
        atomic_write_json(self.run_dir.path / STATE_FILE, self.state.to_dict())

    def _summary(self, r: int) -> str:
        """The line printed after round ``r``."""
        parts = []
        for role in ROLES:
            turn = next(t for t in self.state.turns if t.round == r and t.role == role)
            rate = turn.capture_rate if role == "pursuer" else 1 - turn.capture_rate
            what = "captures" if role == "pursuer" else "escapes"
            parts.append(f"{role} {what} {rate:.2f} in {turn.episodes} episodes vs {turn.opponents} {opponent_of(role)}s")
        cpu = sum(t.cpu_seconds for t in self.state.turns if t.round == r)
        return f"round {r}/{self.settings.rounds}: " + "; ".join(parts) + f" ({cpu:.0f} CPU-s)"
