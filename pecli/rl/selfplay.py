"""Self-play. Alternating (the default): each round trains the pursuer against the evader pool, then the
evader against the pursuer pool, and adds each new checkpoint to its side's pool. Simultaneous (the
paper's MADDPG, :mod:`pecli.rl.simultaneous`): each round both learners play each other in the same
games and both learn every step; their round checkpoints join the pools too (for tournaments).

Both learners live for the whole run: their networks, optimisers and replay buffers carry over
from round to round. Each side's pool starts with the heuristic baselines. Within a turn, every
batched game draws its opponent from the pool when it starts (:class:`~pecli.policies.mixed.MixedPolicy`),
so one batch holds many opponents at once.

A run in the zoo::

    zoo/<run>/
        config.yaml, command.txt, versions.json, tb/     as for ``pecli train``
        selfplay.json                the state: pools and their records, finished turns, seeds
        pursuer/round-001.zip/.json  the pursuer after round 1, with its lineage in the metadata
        pursuer/average.zip/.json    the mean of the pursuer's last ``average_last`` rounds' weights: what the run
                                     hands over (rewritten after every round; pecli.rl.averaging)
        pursuer/resume/              the pursuer's durable state (pecli.rl.durable): model, optimisers, buffers
        evader/...

Each learner commits its durable state every ``checkpoint_every`` episodes of its turn, with the
turn's progress (steps, opponent records), and at the end of the turn; then ``selfplay.json``
records the finished turn. A run stopped in any way resumes inside the turn it was in, from the
learner's newest commit: at most one checkpoint interval is lost.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Literal

import numpy as np
import torch as th
from stable_baselines3.common.callbacks import CallbackList

from pecli.errors import PecliError
from pecli.io import atomic_write_json
from pecli.models.buffers import end_episodes
from pecli.policies.base import Policy
from pecli.policies.mixed import MixedPolicy
from pecli.rl import budget
from pecli.rl.averaging import average_checkpoints
from pecli.rl.callbacks import (
    CurriculumCallback,
    EpisodeStats,
    FiniteCheck,
    PoolTracker,
    ProgressDisplay,
    RoundDisplay,
    every_episodes,
)
from pecli.rl.durable import DurableState
from pecli.rl.handover import AVERAGE_FILE, STATE_FILE, stale_averages
from pecli.rl.opponents import PoolPlayers, opponent_rule
from pecli.rl.pool import EXPLOITER, MAIN, OpponentPool
from pecli.rl.simultaneous import learn_simultaneously
from pecli.rl.state import SelfPlayState, Turn, checkpoint_name, initial_state, read_state, round_of  # noqa: F401
from pecli.rl.train import (
    TrainJob,
    checkpoint_meta,
    make_learner,
    play_live,
    resume_seed,
)
from pecli.roles import ROLES, Role, opponent_of
from pecli.scenario import Scenario
from pecli.zoo import RESUME_DIR, Run
from wrappers.simultaneous import SimultaneousGame

KEEP = "keep"  # SelfPlayJob.cpu_hours: a resumed run keeps its own budget


class SelfPlayInterrupted(Exception):
    """Self-play stopped (Ctrl-C, SIGTERM) in ``round``, while ``role`` (or both sides) trained; its progress
    is committed."""

    def __init__(self, round: int, role: str) -> None:
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
    device: str = "cpu"  # where the networks train: cpu, cuda or auto
    cpu_hours: float | None | Literal["keep"] = KEEP  # the run's CPU budget (pecli.rl.budget), None for none, or
    # KEEP: a resumed run's own (none for a new run)


def write_averages(run: Run, state: SelfPlayState, scenario: Scenario) -> None:
    """Write each main learner's ``average.zip``, the mean of its newest rounds (:mod:`pecli.rl.handover`),
    unless it holds them already."""
    for role, inputs in stale_averages(run.path, state.records(), state.curriculum_steps, scenario).items():
        average_checkpoints(inputs, run.path / role / AVERAGE_FILE)


def tensorboard_name(role: Role, kind: str, r: int) -> str:
    """The TensorBoard run a turn logs to, under the run's ``tb/``: one per main learner (``pursuer_0``), and one
    per exploiter turn (``exploiter-pursuer/r007_0``), since an exploiter that joined its pool starts again
    from step 0 and would draw over the curves of the one before."""
    return role if kind == MAIN else f"exploiter-{role}/r{r:03d}"


def _hours(seconds: float, budget: float) -> str:
    """CPU seconds as hours: two decimals, or two significant digits under a budget below 0.1 CPU-h (0.0012 of
    0.002, not 0.00)."""
    return f"{seconds / 3600:.2f}" if budget >= 0.1 else f"{seconds / 3600:.2g}"


def turn_seed(seed: int, round: int, role: Role, kind: str = MAIN) -> int:
    """The seed of one turn: fixed by the run's seed, so a resumed run plays the turns it would have."""
    entropy = [seed, round, ROLES.index(role)] + ([1] if kind == EXPLOITER else [])
    return int(np.random.SeedSequence(entropy).generate_state(1)[0] % 2**31)


def _wins(role: Role, stats: EpisodeStats) -> int:
    """The opponent's wins among the episodes ``stats`` counted for ``role``'s learner."""
    return stats.episodes - stats.captures if role == "pursuer" else stats.captures


class Learner:
    """One side of self-play: its SB3 model, its batched view, its durable state and the callbacks that outlive a turn."""

    def __init__(self, job: SelfPlayJob, role: Role, placeholder: Policy | None, run: Run, state: SelfPlayState,
                 view: Any = None, kind: str = MAIN) -> None:
        """Build the ``kind`` learner of ``role`` (main, or a league's exploiter) afresh, or from its durable
        state when it has one. It plays against ``placeholder`` (replaced by each turn's pool) or, in the
        simultaneous schedule, in ``view``."""
        self.role, self.kind = role, kind
        self.folder = role if kind == MAIN else f"{EXPLOITER}-{role}"  # where its checkpoints and state go
        self.train_job = TrainJob(role=role, scenario=job.scenario, opponent="selfplay", zoo=job.zoo, name=job.name,
                                  seed=job.seed, device=job.device)
        self.env, self.model, self.fit = make_learner(self.train_job, placeholder, job.seed, run.path / "tb", view=view)
        t = job.scenario.training
        self.callbacks: list[Any] = []
        self.curriculum: CurriculumCallback | None = None
        if t.curriculum.enabled and kind == MAIN:  # an exploiter plays the real game: the holes it finds are real
            self.curriculum = CurriculumCallback(job.scenario, t.curriculum.span(state.curriculum_steps))
            self.callbacks.append(self.curriculum)
        if self.fit is not None:
            self.callbacks.append(self.fit)
        self.durable = DurableState(run.role_dir(self.folder) / RESUME_DIR)
        record = self.durable.read()
        latest = state.latest(role, kind)
        if record is not None and latest is not None and latest.joined and record.extra.get("round") == latest.round:
            record = None  # an exploiter that joined the pool starts afresh; a stop came before it was cleared
        if record is not None:
            self.durable.restore(record, self.model, self.fit)
        elif latest is not None and not latest.joined:
            raise PecliError(f"run '{run.name}' was written by an older pecli (its {role} has no {RESUME_DIR}/ state), "
                             "which this one cannot resume; its checkpoints still play (with --trust)")
        else:
            self.durable.clear()  # a fresh learner: what a stop before its first commit left goes

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
            if job.cpu_hours != KEEP and job.cpu_hours != self.state.cpu_hours:  # a new budget replaces its own
                self.state.cpu_hours = job.cpu_hours
                self._save_state()
        else:
            Run.check_new(job.zoo, job.name)
            self.state = replace(initial_state(job.scenario, job.seed), cpu_hours=None if job.cpu_hours == KEEP else job.cpu_hours)
            self.run_dir = Run.create(job.zoo, job.name, job.scenario, {"command": "selfplay", "seed": job.seed})
            self._save_state()
        self.players = PoolPlayers(self.run_dir.path, self.scenario, job.seed)  # the pools' frozen players
        self.opponents = opponent_rule(self.settings, self.players, job.zoo)  # whom each turn's learner meets
        self.learners: dict[Role, Learner] = {}  # the main learner of each side
        self.exploiters: dict[Role, Learner] = {}  # a league's exploiters

    # -- the loop ------------------------------------------------------------------------------
    def run(self, after_round: Callable[[int], bool] | None = None) -> dict[Role, Path]:
        """Play the rounds not yet played, until the last or the run's CPU budget; ``after_round(r)`` returning
        False stops after round ``r``."""
        if self.budget_reached():  # nothing to load or play
            self.report(self._budget_line())
            write_averages(self.run_dir, self.state, self.scenario)
            return self._latest()
        th.set_num_threads(self.scenario.training.torch_threads)
        simultaneous = self.settings.schedule == "simultaneous"
        games = None
        if simultaneous:
            beliefs = {role: self.scenario.training.belief != "none" for role in ROLES}
            games = SimultaneousGame(self.scenario, self.scenario.training.n_envs, self.job.seed, history=beliefs)
        for role in ROLES:
            placeholder = None if simultaneous else self.players.mixture(self.state.pools[opponent_of(role)])
            view = games.faces[role] if games is not None else None
            self.learners[role] = Learner(self.job, role, placeholder, self.run_dir, self.state, view=view)
        records = self.state.records()
        for r in range(1, self.settings.rounds + 1):
            turns = budget.scheduled_turns(self.settings, records, r)
            if all(self.state.done(r, role, kind) for kind, role in turns):
                continue
            if games is not None:
                self._joint_round(r, games)
            else:
                for kind, role in turns:  # the main agents first: the exploiters then train against the new ones
                    if not self.state.done(r, role, kind):
                        self._turn(r, role, kind)
            records = self.state.records()
            write_averages(self.run_dir, self.state, self.scenario)
            self.report(self._summary(r))
            if self.budget_reached():
                self.report(self._budget_line())
                break
            if after_round is not None and not after_round(r):
                break
        write_averages(self.run_dir, self.state, self.scenario)  # catches up after a stop before a round's averages
        return self._latest()

    def _latest(self) -> dict[Role, Path]:
        return {role: self.run_dir.path / self.state.latest(role).checkpoint for role in ROLES}

    def whole_rounds(self) -> int:
        """How many rounds, from round 1 on, have all their turns recorded (:mod:`pecli.rl.budget`)."""
        return budget.whole_rounds(self.state.records(), self.settings)

    def budget_reached(self) -> bool:
        """Whether the run's CPU budget is spent by its last whole round (:mod:`pecli.rl.budget`)."""
        return budget.budget_reached(self.state.records(), self.state.cpu_hours, self.settings)

    def _budget_line(self) -> str:
        rounds = self.whole_rounds()
        return (f"budget reached: {_hours(self.state.cpu_seconds(through=rounds), self.state.cpu_hours)} of "
                f"{self.state.cpu_hours:g} "
                f"CPU-h after round {rounds}")

    def plan(self) -> str:
        """What the run will do, in one line: rounds, steps, budget, schedule, opponents and belief."""
        sp, state = self.settings, self.state
        used = f" ({state.cpu_seconds() / 3600:.2f} used)" if state.turns else ""
        budget = "" if state.cpu_hours is None else f" or {state.cpu_hours:g} CPU-h{used}, whichever comes first,"
        opponents = f", opponents {sp.opponents}" if sp.schedule == "alternating" else ""
        return (f"self-play {self.run_dir.path}: {sp.rounds} round{'s' if sp.rounds > 1 else ''} of "
                f"{sp.steps_per_round:,} steps per side{budget} on {self.scenario.name}, {sp.schedule}{opponents}, "
                f"belief {self.scenario.training.belief}")

    def nothing_trained(self) -> str:
        """Why a call trained nothing, and which option continues the run."""
        limits = [flag for flag, reached in (("--cpu-hours", self.budget_reached()),
                                             ("--rounds", self.whole_rounds() >= self.settings.rounds)) if reached]
        verb = "continue" if len(limits) > 1 else "continues"
        return f"nothing to train: a larger {' and '.join(limits) or '--rounds'} {verb} the run"

    def averages(self) -> dict[Role, Path]:
        """Each main learner's ``average.zip`` (the mean of its last ``average_last`` rounds), where there is one."""
        paths = {role: self.run_dir.path / role / AVERAGE_FILE for role in ROLES}
        return {role: path for role, path in paths.items() if path.is_file()}

    def _joint_round(self, r: int, games: SimultaneousGame) -> None:
        """Round ``r`` of the simultaneous schedule: both learners in the same games for ``steps_per_round``
        steps each, or the rest of it when they committed part of it."""
        sp, t = self.settings, self.scenario.training
        learners = self.learners
        progress = {role: learners[role].progress(r) for role in ROLES}
        for role in ROLES:
            if progress[role] is None:
                progress[role] = {"round": r, "start_steps": int(learners[role].model.num_timesteps), "cpu_seconds": 0.0,
                                  "episodes": 0, "captures": 0}
        seed = turn_seed(self.state.seed, r, "pursuer")
        if any(learners[role].model.num_timesteps > progress[role]["start_steps"] for role in ROLES):
            seed = resume_seed(seed, int(learners["pursuer"].model.num_timesteps))  # resumed inside: games of their own
        stats = {role: EpisodeStats(episodes=progress[role]["episodes"], captures=progress[role]["captures"])
                 for role in ROLES}
        for role in ROLES:
            model = learners[role].model
            end_episodes(model.replay_buffer)  # the games in flight end here
            model.set_env(learners[role].env, force_reset=True)
            model.set_random_seed(seed)
        games.next_seed = seed
        curriculum = learners["pursuer"].curriculum  # one schedule for the shared games, the pursuer's
        if curriculum is not None:
            curriculum.apply_to(learners["pursuer"].env, learners["pursuer"].model.num_timesteps)
        cpu = time.process_time()

        def commit() -> dict[Role, Path]:
            """Commit both learners' durable states with the round's progress so far."""
            nonlocal cpu
            now = time.process_time()
            share = (now - cpu) / len(ROLES)  # the round's CPU, half to each learner
            cpu = now  # counted once, even when a stop during the saves below commits again
            sources = {}
            for role in ROLES:
                progress[role].update(cpu_seconds=progress[role]["cpu_seconds"] + share,
                                      episodes=stats[role].episodes, captures=stats[role].captures)
                episodes = sum(turn.episodes for turn in self.state.turns if turn.role == role) + stats[role].episodes
                run_cpu = self.state.cpu_seconds() + sum(p["cpu_seconds"] for p in progress.values())
                learner = learners[role]
                sources[role] = learner.durable.save(learner.model, learner.fit, episodes, run_cpu, extra=dict(progress[role]))
            return sources

        stats["pursuer"].listeners.append(every_episodes(t.checkpoint_every, stats["pursuer"].episodes,
                                                         lambda _: commit()))
        remaining = max(progress[role]["start_steps"] + sp.steps_per_round - int(learners[role].model.num_timesteps)
                        for role in ROLES)
        title = f"round {r}/{sp.rounds} · pursuer and evader together (simultaneous)"
        target = int(learners["pursuer"].model.num_timesteps) + max(remaining, 0)
        display = ProgressDisplay(stats["pursuer"], target, title, enabled=self.job.progress)
        callbacks = {
            "pursuer": [FiniteCheck(), *learners["pursuer"].callbacks, stats["pursuer"], display],
            "evader": [FiniteCheck()] + [c for c in learners["evader"].callbacks if c is not learners["evader"].curriculum]
            + [stats["evader"]],
        }
        try:
            if remaining > 0:
                learn_simultaneously({role: learners[role].model for role in ROLES}, remaining, callbacks)
            sources = commit()
            for role in ROLES:
                other = opponent_of(role)
                opponent = {"name": f"{other}-learner", "spec": "", "generation": r, "weight": 1.0,
                            "episodes": stats[role].episodes,
                            "opponent_wins": _wins(role, stats[role])}
                self._publish(r, role, sources[role], stats[role].episodes, stats[role].captures, [opponent], 1,
                              progress[role]["cpu_seconds"])
            self._save_state()
        except KeyboardInterrupt:
            commit()
            raise SelfPlayInterrupted(r, "both sides") from None
        finally:
            for role in ROLES:
                logger = getattr(learners[role].model, "_logger", None)
                if logger is not None:
                    logger.close()

    def _turn(self, r: int, role: Role, kind: str = MAIN) -> None:
        """Train ``role``'s ``kind`` learner for round ``r``, or the rest of it when it committed part of it.
        A main learner plays the other side's pool; a league's exploiter the other side's newest main."""
        sp, t = self.settings, self.scenario.training
        other = opponent_of(role)
        if kind == MAIN:
            pool = self.state.pools[other]
            if self.state.latest(role) is not None:  # a new round: the learner moved on from last time's records
                pool.decay(sp.pfsp_decay)
            meta_cpu = time.process_time()
            weigh = self.opponents.weigher(role, self.state)  # with opponents nash, the meta-game's new pairings play here: their CPU counts
            meta_cpu = time.process_time() - meta_cpu
            mixed = self.players.mixture(self.state.pools[other])
            mixed.weights = weigh(pool)
            tracker = PoolTracker(pool, mixed, weigh if sp.opponents in ("pfsp", "league") else None)
        else:
            target = self.state.latest(other)
            pool = OpponentPool(other)
            entry = pool.add(f"{other}-r{target.round:03d}", target.checkpoint, generation=target.round)
            mixed = MixedPolicy(other, [self.players.player(other, entry.spec)], [entry.name])
            tracker = PoolTracker(pool, mixed)
            if role not in self.exploiters:  # built at its first turn: a run may have spent hours without exploiters
                self.exploiters[role] = Learner(self.job, role, mixed, self.run_dir, self.state, kind=EXPLOITER)
        learner = self.learners[role] if kind == MAIN else self.exploiters[role]
        model = learner.model
        progress = learner.progress(r)
        if progress is None:
            progress = {"round": r, "start_steps": int(model.num_timesteps), "cpu_seconds": 0.0}
        else:  # resumed inside the turn: its records so far
            tracker.restore(progress["tracker"])
        if kind == MAIN:
            progress["cpu_seconds"] += meta_cpu
        seed = turn_seed(self.state.seed, r, role, kind)
        if model.num_timesteps > progress["start_steps"]:  # new games from a seed of their own
            seed = resume_seed(seed, int(model.num_timesteps))
        learner.env.env_method("set_opponent", mixed)
        if learner.curriculum is not None:  # the games SB3 starts before any callback runs count too
            learner.curriculum.apply_to(learner.env, model.num_timesteps)
        end_episodes(model.replay_buffer)  # the games in flight end here: returns must not run into the new ones
        model.set_env(learner.env, force_reset=True)  # every game starts afresh against the new pool
        model.set_random_seed(seed)

        cpu = time.process_time()

        def commit() -> Path:
            """Commit the learner's durable state with the turn's progress so far."""
            nonlocal cpu
            now = time.process_time()
            progress.update(tracker=tracker.to_dict(), cpu_seconds=progress["cpu_seconds"] + now - cpu)
            cpu = now
            episodes = sum(turn.episodes for turn in self.state.turns if turn.role == role and turn.learner == kind) \
                + tracker.episodes
            run_cpu = self.state.cpu_seconds() + progress["cpu_seconds"]
            return learner.durable.save(model, learner.fit, episodes, run_cpu, extra=dict(progress))

        tracker.listeners.append(every_episodes(t.checkpoint_every, tracker.episodes, lambda _: commit()))
        remaining = progress["start_steps"] + sp.steps_per_round - int(model.num_timesteps)
        what = f"{role} exploiter vs the main {other}" if kind == EXPLOITER else \
            f"{role} vs {len(pool.entries)} {other}s ({sp.opponents})"
        display = RoundDisplay(tracker, sp.steps_per_round, f"round {r}/{sp.rounds} · {what}", enabled=self.job.progress)
        try:
            try:
                if remaining > 0:
                    model.learn(remaining, callback=CallbackList([FiniteCheck(), *learner.callbacks, tracker, display]),
                                reset_num_timesteps=False, tb_log_name=tensorboard_name(role, kind, r))
            finally:
                display.close()
                logger = getattr(model, "_logger", None)
                if logger is not None:
                    logger.close()
            self._finish_turn(r, role, kind, tracker, commit)
        except KeyboardInterrupt:
            commit()
            raise SelfPlayInterrupted(r, role if kind == MAIN else f"{role} exploiter") from None

    def _finish_turn(self, r: int, role: Role, kind: str, tracker: PoolTracker, commit: Callable[[], Path]) -> None:
        """The learner's durable state first, then its round checkpoint, then selfplay.json (the commit of
        the turn): a stop in between resumes inside the turn with nothing left to train, and finishes it.
        A league's exploiter joins its side's pool if it won ``exploiter_join`` of its games (of its join games, with
        ``exploiter_join_games``), or at the end of its ``league_exploiter_timeout``-th turn without joining, then
        starts afresh."""
        weights = dict(zip(tracker.opponent.names, tracker.opponent.weights))
        opponents = [
            {"name": e.name, "spec": e.spec, "generation": e.generation, "weight": round(float(weights[e.name]), 4),
             "episodes": tracker.per_opponent[e.name][0], "opponent_wins": tracker.per_opponent[e.name][1]}
            for e in tracker.pool.entries
        ]
        lost = sum(o["opponent_wins"] for o in opponents)
        rate = 1 - lost / tracker.episodes if tracker.episodes else float("nan")
        join_rate = None
        if kind == EXPLOITER and self.settings.exploiter_join_games:  # played before the commit: its CPU counts
            join_rate = self._join_games(r, role, tracker.pool.entries[0].spec)
        joined_by = ""
        if kind == EXPLOITER:
            won = (rate if join_rate is None else join_rate) >= self.settings.exploiter_join  # nan: no game, not won
            joined_by = "win" if won else "timeout" if self._timed_out(role) else ""
        source = commit()
        learner = self.learners[role] if kind == MAIN else self.exploiters[role]
        self._publish(r, role, source, tracker.episodes, tracker.captures, opponents, len(tracker.opponent.names),
                      learner.durable.record.extra["cpu_seconds"], kind, joined_by, join_rate)
        self._save_state()
        if joined_by:  # AlphaStar's exploiters start again once they join: a new learner, its old state gone
            self.exploiters[role] = Learner(self.job, role, tracker.opponent, self.run_dir, self.state, kind=EXPLOITER)

    def _join_games(self, r: int, role: Role, target: str) -> float:
        """The share of ``exploiter_join_games`` games that ``role``'s exploiter, as its turn of round ``r`` ends,
        wins against ``target``, the main agent it trained against: both frozen, from start states seeded by the
        turn (a run resumed inside the turn plays the same games)."""
        learner = self.exploiters[role]
        captured = play_live(learner.train_job, learner.model, self.players.player(opponent_of(role), target),
                             self.settings.exploiter_join_games, turn_seed(self.state.seed, r, role, EXPLOITER) + 1)
        return captured if role == "pursuer" else 1 - captured

    def _timed_out(self, role: Role) -> bool:
        """Whether ``role``'s exploiter, in the turn ending now, has trained ``league_exploiter_timeout`` turns
        since it last started afresh (counted from the record: a resumed run counts alike)."""
        timeout = self.settings.league_exploiter_timeout
        turns = 1  # the one ending now, not recorded yet
        for turn in reversed(self.state.turns):
            if turn.role == role and turn.learner == EXPLOITER:
                if turn.joined:
                    break
                turns += 1
        return 0 < timeout <= turns

    def _publish(self, r: int, role: Role, source: Path, episodes: int, captures: int, opponents: list[dict[str, Any]],
                 pool_size: int, cpu_seconds: float, kind: str = MAIN, joined_by: str = "",
                 join_rate: float | None = None) -> None:
        """Make the committed model ``source`` the checkpoint of round ``r`` of ``role``'s ``kind`` learner,
        add it to its side's pool (a main learner's always, an exploiter's if it joined: ``joined_by`` a reason)
        and record the turn (the caller saves the state)."""
        learner = self.learners[role] if kind == MAIN else self.exploiters[role]
        previous = self.state.latest(role, kind)
        total = sum(t.episodes for t in self.state.turns if t.role == role and t.learner == kind) + episodes
        schedule = "simultaneous" if self.settings.schedule == "simultaneous" else self.settings.opponents
        meta = replace(
            checkpoint_meta(learner.train_job, learner.model, total),
            opponent=f"selfplay:{schedule}" + (f"-{EXPLOITER}" if kind == EXPLOITER else ""),
            round=r,
            parent=previous.checkpoint if previous and not previous.joined else "",
            opponents=opponents,
        )
        path = self.run_dir.publish(source, learner.folder, checkpoint_name(r), meta)
        relative = str(path.relative_to(self.run_dir.path))
        if kind == MAIN or joined_by:
            self.state.pools[role].add(f"{learner.folder}-r{r:03d}", relative, generation=r)
        self.state.turns.append(Turn(round=r, role=role, steps=int(learner.model.num_timesteps), episodes=episodes,
                                     captures=captures, cpu_seconds=round(cpu_seconds, 2), checkpoint=relative,
                                     opponents=pool_size, learner=kind, joined=bool(joined_by), joined_by=joined_by,
                                     join_rate=None if join_rate is None else round(join_rate, 4)))

    def _save_state(self) -> None:
        atomic_write_json(self.run_dir.path / STATE_FILE, self.state.to_dict())

    def _summary(self, r: int) -> str:
        """The line printed after round ``r``."""
        parts = []
        for turn in (t for t in self.state.turns if t.round == r):
            role = turn.role
            rate = turn.capture_rate if role == "pursuer" else 1 - turn.capture_rate
            what = ("captures" if role == "pursuer" else "escapes") + (f" {rate:.2f}" if turn.episodes else " -")
            if turn.learner == MAIN and not turn.episodes:
                parts.append(f"{role}: no episode finished vs {turn.opponents} {opponent_of(role)}s")
            elif turn.learner == MAIN:
                parts.append(f"{role} {what} in {turn.episodes} episodes vs {turn.opponents} {opponent_of(role)}s")
            else:
                tried = "" if turn.join_rate is None else f", {turn.join_rate:.2f} in its join games"
                by_timeout = turn.joined_by == "timeout" or (  # a record older than joined_by: as it would be now
                    not turn.joined_by and rate < self.settings.exploiter_join)
                parts.append(f"{role} exploiter {what} vs the main {opponent_of(role)}{tried}"
                             + (" and joins the pool" + (" (its timeout)" if by_timeout else "") if turn.joined else ""))
        cpu = sum(t.cpu_seconds for t in self.state.turns if t.round == r)
        used = "" if self.state.cpu_hours is None else \
            f"; {_hours(self.state.cpu_seconds(), self.state.cpu_hours)} of {self.state.cpu_hours:g} CPU-h"
        return f"round {r}/{self.settings.rounds}: " + "; ".join(parts) + f" ({cpu:.0f} CPU-s{used})"
