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

from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from typing import Any

import torch as th

from pecli.io import atomic_write_json
from pecli.rl import budget
from pecli.rl.averaging import average_checkpoints
from pecli.rl.handover import STATE_FILE, stale_averages
from pecli.rl.learner import (  # noqa: F401 (the run's job and its stop, importable from here)
    KEEP,
    Learner,
    SelfPlayInterrupted,
    SelfPlayJob,
    turn_seed,
)
from pecli.rl.opponents import PoolPlayers, opponent_rule
from pecli.rl.pool import EXPLOITER, MAIN
from pecli.rl.schedules import schedule_for
from pecli.rl.state import SelfPlayState, Turn, checkpoint_name, initial_state, read_state, round_of  # noqa: F401
from pecli.rl.train import (
    checkpoint_meta,
)
from pecli.roles import ROLES, Role, opponent_of
from pecli.scenario import Scenario
from pecli.text import cpu_time, plural
from pecli.zoo import AVERAGE_FILE, Run


def write_averages(run: Run, state: SelfPlayState, scenario: Scenario) -> None:
    """Write each main learner's ``average.zip``, the mean of its newest rounds (:mod:`pecli.rl.handover`),
    unless it holds them already."""
    for role, inputs in stale_averages(run.path, state.records(), state.curriculum_steps, scenario).items():
        average_checkpoints(inputs, run.path / role / AVERAGE_FILE)


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
                self.save_state()
        else:
            Run.check_new(job.zoo, job.name)
            self.state = replace(
                initial_state(job.scenario, job.seed), cpu_hours=None if job.cpu_hours == KEEP else job.cpu_hours
            )
            self.run_dir = Run.create(job.zoo, job.name, job.scenario, {"command": "selfplay", "seed": job.seed})
            self.save_state()
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
        schedule = schedule_for(self)
        for role, (placeholder, view) in schedule.views(self).items():
            self.learners[role] = Learner(self.job, role, placeholder, self.run_dir, self.state, view=view)
        records = self.state.records()
        for r in range(1, self.settings.rounds + 1):
            turns = budget.scheduled_turns(self.settings, records, r)
            if all(self.state.done(r, role, kind) for kind, role in turns):
                continue
            schedule.play_round(self, r, turns)
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
        spent = cpu_time(self.state.cpu_seconds(through=rounds), 3600 * (self.state.cpu_hours or 0.0))
        return f"budget reached: {spent} after round {rounds}"

    def plan(self) -> str:
        """What the run will do, in one line: rounds, steps, budget, schedule, opponents and belief."""
        sp, state = self.settings, self.state
        used = f" ({cpu_time(state.cpu_seconds())} used)" if state.turns else ""
        budget = "" if state.cpu_hours is None else f" or {state.cpu_hours:g} CPU-h{used}, whichever comes first,"
        opponents = f", opponents {sp.opponents}" if sp.schedule == "alternating" else ""
        return (
            f"self-play {self.run_dir.path}: {sp.rounds} round{'s' if sp.rounds > 1 else ''} of "
            f"{sp.steps_per_round:,} steps per side{budget} on {self.scenario.name}, {sp.schedule}{opponents}, "
            f"belief {self.scenario.training.belief}"
        )

    def nothing_trained(self) -> str:
        """Why a call trained nothing, and which option continues the run."""
        limits = [
            flag
            for flag, reached in (
                ("--cpu-hours", self.budget_reached()),
                ("--rounds", self.whole_rounds() >= self.settings.rounds),
            )
            if reached
        ]
        verb = "continue" if len(limits) > 1 else "continues"
        return f"nothing to train: a larger {' and '.join(limits) or '--rounds'} {verb} the run"

    def averages(self) -> dict[Role, Path]:
        """Each main learner's ``average.zip`` (the mean of its last ``average_last`` rounds), where there is one."""
        paths = {role: self.run_dir.path / role / AVERAGE_FILE for role in ROLES}
        return {role: path for role, path in paths.items() if path.is_file()}

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
    ) -> None:
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
        self.state.turns.append(
            Turn(
                round=r,
                role=role,
                steps=int(learner.model.num_timesteps),
                episodes=episodes,
                captures=captures,
                cpu_seconds=round(cpu_seconds, 2),
                checkpoint=relative,
                opponents=pool_size,
                learner=kind,
                joined=bool(joined_by),
                joined_by=joined_by,
                join_rate=None if join_rate is None else round(join_rate, 4),
            )
        )

    def save_state(self) -> None:
        atomic_write_json(self.run_dir.path / STATE_FILE, self.state.to_dict())

    def _summary(self, r: int) -> str:
        """The line printed after round ``r``."""
        parts = []
        for turn in (t for t in self.state.turns if t.round == r):
            role = turn.role
            rate = turn.capture_rate if role == "pursuer" else 1 - turn.capture_rate
            what = f"{'captures' if role == 'pursuer' else 'escapes'} {rate:.2f}"
            if turn.learner == MAIN and not turn.episodes:
                parts.append(f"{role}: no episode finished vs {turn.opponents} {opponent_of(role)}s")
            elif turn.learner == MAIN:
                parts.append(
                    f"{role} {what} in {plural(turn.episodes, 'episode')} vs {turn.opponents} {opponent_of(role)}s"
                )
            else:
                what = what if turn.episodes else "finished no episode"
                tried = "" if turn.join_rate is None else f", {turn.join_rate:.2f} in its join games"
                by_timeout = turn.joined_by == "timeout" or (  # a record older than joined_by: as it would be now
                    not turn.joined_by and rate < self.settings.exploiter_join
                )
                parts.append(
                    f"{role} exploiter {what} vs the main {opponent_of(role)}{tried}"
                    + (" and joins the pool" + (" (its timeout)" if by_timeout else "") if turn.joined else "")
                )
        cpu = sum(t.cpu_seconds for t in self.state.turns if t.round == r)
        return f"round {r}/{self.settings.rounds}: " + "; ".join(parts) + f" ({cpu_time(cpu)}{self._spent(r)})"

    def _spent(self, r: int) -> str:
        """What the run has spent after round ``r`` (of its budget, if it has one) and about how much more CPU time
        it needs: the rounds left at the mean cost of a round so far, at most what is left of the budget."""
        spent = self.state.cpu_seconds()
        budget = None if self.state.cpu_hours is None else 3600 * self.state.cpu_hours
        left = spent / max(r, 1) * (self.settings.rounds - r)
        if budget is not None:
            left = min(left, budget - spent)
        estimate = f", about {cpu_time(left)} left" if left > 0 else ""
        return f"; run {cpu_time(spent, budget)}{estimate}"
