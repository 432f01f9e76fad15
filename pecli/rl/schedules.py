"""How a round of self-play is played, one class per ``selfplay.schedule`` behind one interface (:class:`Schedule`).

``alternating``   each side in turn trains against the other side's pool (drawn by the run's opponent rule,
                  :mod:`pecli.rl.opponents`); in a league, the exploiters then train against the newest main agents;
``simultaneous``  both learners in the same games, both learning every step (the paper's MADDPG).

Each turn commits its learner's durable state, then its checkpoint, then the run's record
(``publish`` of the run's loop), so a stop anywhere resumes inside the turn.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path
from typing import Any, Protocol

from stable_baselines3.common.callbacks import CallbackList

from pecli.models.buffers import end_episodes
from pecli.policies.base import Policy
from pecli.policies.mixed import MixedPolicy
from pecli.progress import PeriodicLines
from pecli.rl.callbacks import (
    EpisodeStats,
    FiniteCheck,
    PoolTracker,
    ProgressDisplay,
    RoundDisplay,
    every_episodes,
)
from pecli.rl.learner import Learner, SelfPlayInterrupted, SelfPlayJob, opponent_wins, tensorboard_name, turn_seed
from pecli.rl.opponents import OpponentRule, PoolPlayers
from pecli.rl.pool import EXPLOITER, MAIN, OpponentPool
from pecli.rl.simultaneous import learn_simultaneously
from pecli.rl.state import SelfPlayState
from pecli.rl.train import play_live, resume_seed
from pecli.roles import ROLES, Role, opponent_of
from pecli.scenario import Scenario
from pecli.scenario import SelfPlay as SelfPlaySettings
from pecli.text import cpu_time
from pecli.zoo import Run
from wrappers.simultaneous import SimultaneousGame


class RunLoop(Protocol):
    """What a schedule uses of the run it plays (:class:`pecli.rl.selfplay.SelfPlay`)."""

    job: SelfPlayJob
    settings: SelfPlaySettings
    scenario: Scenario
    state: SelfPlayState
    run_dir: Run
    learners: dict[Role, Learner]  # the main learner of each side
    exploiters: dict[Role, Learner]  # a league's exploiters, built at their first turn
    players: PoolPlayers
    opponents: OpponentRule

    def publish(
        self,
        r: int,
        role: Role,
        source: Path,
        episodes: int,
        captures: int,
        opponents: list[dict[str, Any]],
        pool_size: int,
        cpu_seconds: float,
        kind: str = MAIN,
        joined_by: str = "",
        join_rate: float | None = None,
    ) -> None: ...

    def save_state(self) -> None: ...

    def report(self, line: str) -> None: ...


def turn_lines(loop: RunLoop, label: str, steps: int, turn_cpu: Callable[[], float]) -> PeriodicLines | None:
    """Plain progress lines of a turn for a log, every ``job.log_every`` seconds (``None`` without): its ``steps``,
    and the run's CPU time (its finished turns' and ``turn_cpu()``, this turn's so far) out of its budget."""
    if loop.job.log_every is None:
        return None
    budget = None if loop.state.cpu_hours is None else 3600 * loop.state.cpu_hours
    return PeriodicLines(
        label,
        steps,
        loop.report,
        unit="steps",
        every=loop.job.log_every,
        details=lambda: "run " + cpu_time(loop.state.cpu_seconds() + turn_cpu(), budget),
    )


class Schedule(Protocol):
    """Plays one round of a self-play run."""

    def views(self, loop: RunLoop) -> dict[Role, tuple[Policy | None, Any]]:
        """Each learner's first opponent (a placeholder its turns replace) and its view of shared games, if any."""

    def play_round(self, loop: RunLoop, r: int, turns: list[tuple[str, Role]]) -> None:
        """Play the ``turns`` (``(learner, role)``) of round ``r`` that the run has not recorded yet."""


class Simultaneous:
    """Both learners in the same batched games (:class:`~wrappers.simultaneous.SimultaneousGame`)."""

    def __init__(self, loop: RunLoop) -> None:
        beliefs = {role: loop.scenario.training.belief != "none" for role in ROLES}
        self.games = SimultaneousGame(loop.scenario, loop.scenario.training.n_envs, loop.job.seed, history=beliefs)

    def views(self, loop: RunLoop) -> dict[Role, tuple[Policy | None, Any]]:
        return {role: (None, self.games.faces[role]) for role in ROLES}

    def play_round(self, loop: RunLoop, r: int, turns: list[tuple[str, Role]]) -> None:
        """Round ``r`` of the simultaneous schedule: both learners in the same games for ``steps_per_round``
        steps each, or the rest of it when they committed part of it."""
        sp, t = loop.settings, loop.scenario.training
        learners, games = loop.learners, self.games
        progress = {role: learners[role].progress(r) for role in ROLES}
        for role in ROLES:
            if progress[role] is None:
                progress[role] = {
                    "round": r,
                    "start_steps": int(learners[role].model.num_timesteps),
                    "cpu_seconds": 0.0,
                    "episodes": 0,
                    "captures": 0,
                }
        seed = turn_seed(loop.state.seed, r, "pursuer")
        if any(learners[role].model.num_timesteps > progress[role]["start_steps"] for role in ROLES):
            seed = resume_seed(seed, int(learners["pursuer"].model.num_timesteps))  # resumed inside: games of their own
        stats = {
            role: EpisodeStats(episodes=progress[role]["episodes"], captures=progress[role]["captures"])
            for role in ROLES
        }
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
                progress[role].update(
                    cpu_seconds=progress[role]["cpu_seconds"] + share,
                    episodes=stats[role].episodes,
                    captures=stats[role].captures,
                )
                episodes = sum(turn.episodes for turn in loop.state.turns if turn.role == role) + stats[role].episodes
                run_cpu = loop.state.cpu_seconds() + sum(p["cpu_seconds"] for p in progress.values())
                learner = learners[role]
                sources[role] = learner.durable.save(
                    learner.model, learner.fit, episodes, run_cpu, extra=dict(progress[role])
                )
            return sources

        stats["pursuer"].listeners.append(
            every_episodes(t.checkpoint_every, stats["pursuer"].episodes, lambda _: commit())
        )
        remaining = max(
            progress[role]["start_steps"] + sp.steps_per_round - int(learners[role].model.num_timesteps)
            for role in ROLES
        )
        title = f"round {r}/{sp.rounds} · pursuer and evader together (simultaneous)"
        target = int(learners["pursuer"].model.num_timesteps) + max(remaining, 0)
        lines = turn_lines(
            loop, title, target, lambda: sum(p["cpu_seconds"] for p in progress.values()) + time.process_time() - cpu
        )
        display = ProgressDisplay(stats["pursuer"], target, title, enabled=loop.job.progress, lines=lines)
        callbacks = {
            "pursuer": [FiniteCheck(), *learners["pursuer"].callbacks, stats["pursuer"], display],
            "evader": [FiniteCheck()]
            + [c for c in learners["evader"].callbacks if c is not learners["evader"].curriculum]
            + [stats["evader"]],
        }
        try:
            if remaining > 0:
                learn_simultaneously({role: learners[role].model for role in ROLES}, remaining, callbacks)
            sources = commit()
            for role in ROLES:
                other = opponent_of(role)
                opponent = {
                    "name": f"{other}-learner",
                    "spec": "",
                    "generation": r,
                    "weight": 1.0,
                    "episodes": stats[role].episodes,
                    "opponent_wins": opponent_wins(role, stats[role]),
                }
                loop.publish(
                    r,
                    role,
                    sources[role],
                    stats[role].episodes,
                    stats[role].captures,
                    [opponent],
                    1,
                    progress[role]["cpu_seconds"],
                )
            loop.save_state()
        except KeyboardInterrupt:
            commit()
            raise SelfPlayInterrupted(r, "both sides") from None
        finally:
            for role in ROLES:
                logger = getattr(learners[role].model, "_logger", None)
                if logger is not None:
                    logger.close()


class Alternating:
    """One side at a time against the other side's pool; a league's exploiters after the main learners."""

    def views(self, loop: RunLoop) -> dict[Role, tuple[Policy | None, Any]]:
        return {role: (loop.players.mixture(loop.state.pools[opponent_of(role)]), None) for role in ROLES}

    def play_round(self, loop: RunLoop, r: int, turns: list[tuple[str, Role]]) -> None:
        for kind, role in turns:  # the main agents first: the exploiters then train against the new ones
            if not loop.state.done(r, role, kind):
                self.turn(loop, r, role, kind)

    def turn(self, loop: RunLoop, r: int, role: Role, kind: str = MAIN) -> None:
        """Train ``role``'s ``kind`` learner for round ``r``, or the rest of it when it committed part of it.
        A main learner plays the other side's pool; a league's exploiter the other side's newest main."""
        sp, t = loop.settings, loop.scenario.training
        other = opponent_of(role)
        if kind == MAIN:
            pool = loop.state.pools[other]
            if loop.state.latest(role) is not None:  # a new round: the learner moved on from last time's records
                pool.decay(sp.pfsp_decay)
            meta_cpu = time.process_time()
            weigh = loop.opponents.weigher(
                role, loop.state
            )  # with opponents nash, the meta-game's new pairings play here: their CPU counts
            meta_cpu = time.process_time() - meta_cpu
            mixed = loop.players.mixture(loop.state.pools[other])
            mixed.weights = weigh(pool)
            tracker = PoolTracker(pool, mixed, weigh if sp.opponents in ("pfsp", "league") else None)
        else:
            target = loop.state.latest(other)
            pool = OpponentPool(other)
            entry = pool.add(f"{other}-r{target.round:03d}", target.checkpoint, generation=target.round)
            mixed = MixedPolicy(other, [loop.players.player(other, entry.spec)], [entry.name])
            tracker = PoolTracker(pool, mixed)
            if role not in loop.exploiters:  # built at its first turn: a run may have spent hours without exploiters
                loop.exploiters[role] = Learner(loop.job, role, mixed, loop.run_dir, loop.state, kind=EXPLOITER)
        learner = loop.learners[role] if kind == MAIN else loop.exploiters[role]
        model = learner.model
        progress = learner.progress(r)
        if progress is None:
            progress = {"round": r, "start_steps": int(model.num_timesteps), "cpu_seconds": 0.0}
        else:  # resumed inside the turn: its records so far
            tracker.restore(progress["tracker"])
        if kind == MAIN:
            progress["cpu_seconds"] += meta_cpu
        seed = turn_seed(loop.state.seed, r, role, kind)
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
            episodes = (
                sum(turn.episodes for turn in loop.state.turns if turn.role == role and turn.learner == kind)
                + tracker.episodes
            )
            run_cpu = loop.state.cpu_seconds() + progress["cpu_seconds"]
            return learner.durable.save(model, learner.fit, episodes, run_cpu, extra=dict(progress))

        tracker.listeners.append(every_episodes(t.checkpoint_every, tracker.episodes, lambda _: commit()))
        remaining = progress["start_steps"] + sp.steps_per_round - int(model.num_timesteps)
        what = (
            f"{role} exploiter vs the main {other}"
            if kind == EXPLOITER
            else f"{role} vs {len(pool.entries)} {other}s ({sp.opponents})"
        )
        title = f"round {r}/{sp.rounds} · {what}"
        lines = turn_lines(loop, title, sp.steps_per_round, lambda: progress["cpu_seconds"] + time.process_time() - cpu)
        display = RoundDisplay(tracker, sp.steps_per_round, title, enabled=loop.job.progress, lines=lines)
        try:
            try:
                if remaining > 0:
                    model.learn(
                        remaining,
                        callback=CallbackList([FiniteCheck(), *learner.callbacks, tracker, display]),
                        reset_num_timesteps=False,
                        tb_log_name=tensorboard_name(role, kind, r),
                    )
            finally:
                display.close()
                logger = getattr(model, "_logger", None)
                if logger is not None:
                    logger.close()
            self.finish_turn(loop, r, role, kind, tracker, commit)
        except KeyboardInterrupt:
            commit()
            raise SelfPlayInterrupted(r, role if kind == MAIN else f"{role} exploiter") from None

    def finish_turn(
        self, loop: RunLoop, r: int, role: Role, kind: str, tracker: PoolTracker, commit: Callable[[], Path]
    ) -> None:
        """The learner's durable state first, then its round checkpoint, then selfplay.json (the commit of
        the turn): a stop in between resumes inside the turn with nothing left to train, and finishes it.
        A league's exploiter joins its side's pool if it won ``exploiter_join`` of its games (of its join games, with
        ``exploiter_join_games``), or at the end of its ``league_exploiter_timeout``-th turn without joining, then
        starts afresh."""
        weights = dict(zip(tracker.opponent.names, tracker.opponent.weights))
        opponents = [
            {
                "name": e.name,
                "spec": e.spec,
                "generation": e.generation,
                "weight": round(float(weights[e.name]), 4),
                "episodes": tracker.per_opponent[e.name][0],
                "opponent_wins": tracker.per_opponent[e.name][1],
            }
            for e in tracker.pool.entries
        ]
        lost = sum(o["opponent_wins"] for o in opponents)
        rate = 1 - lost / tracker.episodes if tracker.episodes else float("nan")
        join_rate = None
        if kind == EXPLOITER and loop.settings.exploiter_join_games:  # played before the commit: its CPU counts
            join_rate = self.join_games(loop, r, role, tracker.pool.entries[0].spec)
        joined_by = ""
        if kind == EXPLOITER:
            won = (rate if join_rate is None else join_rate) >= loop.settings.exploiter_join  # nan: no game, not won
            joined_by = "win" if won else "timeout" if self.timed_out(loop, role) else ""
        source = commit()
        learner = loop.learners[role] if kind == MAIN else loop.exploiters[role]
        loop.publish(
            r,
            role,
            source,
            tracker.episodes,
            tracker.captures,
            opponents,
            len(tracker.opponent.names),
            learner.durable.record.extra["cpu_seconds"],
            kind,
            joined_by,
            join_rate,
        )
        loop.save_state()
        if joined_by:  # AlphaStar's exploiters start again once they join: a new learner, its old state gone
            loop.exploiters[role] = Learner(loop.job, role, tracker.opponent, loop.run_dir, loop.state, kind=EXPLOITER)

    def join_games(self, loop: RunLoop, r: int, role: Role, target: str) -> float:
        """The share of ``exploiter_join_games`` games that ``role``'s exploiter, as its turn of round ``r`` ends,
        wins against ``target``, the main agent it trained against: both frozen, from start states seeded by the
        turn (a run resumed inside the turn plays the same games)."""
        learner = loop.exploiters[role]
        captured = play_live(
            learner.train_job,
            learner.model,
            loop.players.player(opponent_of(role), target),
            loop.settings.exploiter_join_games,
            turn_seed(loop.state.seed, r, role, EXPLOITER) + 1,
        )
        return captured if role == "pursuer" else 1 - captured

    def timed_out(self, loop: RunLoop, role: Role) -> bool:
        """Whether ``role``'s exploiter, in the turn ending now, has trained ``league_exploiter_timeout`` turns
        since it last started afresh (counted from the record: a resumed run counts alike)."""
        timeout = loop.settings.league_exploiter_timeout
        turns = 1  # the one ending now, not recorded yet
        for turn in reversed(loop.state.turns):
            if turn.role == role and turn.learner == EXPLOITER:
                if turn.joined:
                    break
                turns += 1
        return 0 < timeout <= turns


def schedule_for(loop: RunLoop) -> Schedule:
    """The schedule ``selfplay.schedule`` names."""
    return Simultaneous(loop) if loop.settings.schedule == "simultaneous" else Alternating()
