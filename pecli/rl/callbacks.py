"""SB3 callbacks of a training run: a guard against non-finite learning, curriculum, episode statistics and
progress, evaluation, self-play's pool records and live view."""

from __future__ import annotations

import math
import time
from collections import deque
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import torch as th
from rich.console import Group
from rich.live import Live
from rich.markup import escape
from rich.progress import BarColumn, Progress, TextColumn, TimeRemainingColumn
from rich.table import Table
from stable_baselines3.common.callbacks import BaseCallback

from pecli.errors import PecliError
from pecli.progress import PeriodicLines
from pecli.rl.evaluations import append_evaluation, read_evaluations, start_log
from pecli.scenario import Scenario


class TrainingDiverged(PecliError):
    """A loss or a network parameter became NaN or infinite: the model is broken and is not saved."""


def non_finite_parameters(module: th.nn.Module) -> int:
    """How many of ``module``'s parameters hold a NaN or an infinity (0 for a healthy network)."""
    return sum(int(not th.isfinite(p).all()) for p in module.parameters())


class FiniteCheck(BaseCallback):
    """Stops training with :class:`TrainingDiverged` as soon as a logged loss or a parameter is not finite.

    Put it first in the callback list: the callbacks after it (checkpoints, evaluations) then never see a
    broken model, and the exception keeps the run from writing its ``final`` checkpoint. Every step it
    reads the losses of the last update (the logger's ``*loss`` and ``*nll`` values) and the actor's
    parameters (what plays and is exported; a sum per tensor, which a NaN or an infinity turns
    non-finite: about 1% of a step); at the end of training, every parameter of the policy.
    """

    def __init__(self) -> None:
        super().__init__()
        self._params: list[th.Tensor] = []

    def _on_training_start(self) -> None:
        self._params = list(self.model.policy.actor.parameters())

    def _on_step(self) -> bool:
        for key, value in self.logger.name_to_value.items():
            if key.endswith(("loss", "nll")) and not math.isfinite(value):
                self._stop(f"{key} is {value}")
        with th.no_grad():
            healthy = not self._params or bool(th.isfinite(th.stack([p.sum() for p in self._params])).all())
        if not healthy:
            self._stop(f"{non_finite_parameters(self.model.policy.actor)} actor parameter tensors hold NaN or inf")
        return True

    def _on_training_end(self) -> None:
        if broken := non_finite_parameters(self.model.policy):
            self._stop(f"{broken} parameter tensors of the policy hold NaN or inf")

    def _stop(self, what: str) -> None:
        raise TrainingDiverged(
            f"training diverged at step {self.num_timesteps:,}: {what}; stopped without saving this model "
            "(lower the learning rate, or check the rewards and reward_scale)"
        )


def every_episodes(every: int, done: int, action: Callable[[int], None]) -> Callable[[int], None]:
    """A listener for an episode counter (:attr:`EpisodeStats.listeners`) that calls ``action(total)`` each
    time the count passes the next multiple of ``every`` after ``done`` (a checkpoint cadence)."""
    following = (done // every + 1) * every

    def listener(total: int) -> None:
        nonlocal following
        if total >= following:
            action(total)
            following = (total // every + 1) * every

    return listener


class CurriculumCallback(BaseCallback):
    """Paper section V-A: over the first ``span`` learner transitions (:meth:`pecli.scenario.Curriculum.span`)
    the pursuer's FOV shrinks linearly from 2pi to its configured value and the evader's speed limit grows
    from 0 to its own.

    The schedule follows ``model.num_timesteps``, so a resumed run continues it where it stopped.
    """

    def __init__(self, scenario: Scenario, span: float) -> None:
        super().__init__()
        self.final_fov = scenario.pursuer.sensor.fov
        self.span = max(1.0, span)

    def progress(self, steps: int | None = None) -> float:
        return min(1.0, (self.num_timesteps if steps is None else steps) / self.span)

    def apply_to(self, env: Any, steps: int) -> float:
        """Set ``env``'s knobs for ``steps`` learner transitions; returns the progress. Call it before
        ``learn`` too: SB3 resets the env before any callback runs, and those first games count."""
        p = self.progress(steps)
        env.env_method("set_curriculum", 2 * math.pi + (self.final_fov - 2 * math.pi) * p, p)
        return p

    def _apply(self) -> None:
        p = self.apply_to(self.training_env, self.num_timesteps)
        self.logger.record("curriculum/progress", p)

    def _on_training_start(self) -> None:
        self._apply()

    def _on_step(self) -> bool:
        self._apply()
        return True


class EpisodeStats(BaseCallback):
    """Counts finished episodes and captures from the view's ``infos`` (from ``episodes`` and ``captures``
    on); logs the recent capture rate.

    ``on_episodes(total)`` is called whenever episodes finish (checkpointing hooks in there).
    """

    def __init__(self, episodes: int = 0, window: int = 100, captures: int = 0) -> None:
        super().__init__()
        self.episodes, self.captures = episodes, captures
        self.recent: deque[bool] = deque(maxlen=window)
        self.listeners: list[Callable[[int], None]] = []

    @property
    def capture_rate(self) -> float:
        return float(np.mean(self.recent)) if self.recent else float("nan")

    def _on_step(self) -> bool:
        finished = [info["captured"] for info in self.locals["infos"] if "captured" in info]
        if finished:
            self.recent.extend(finished)
            self.episodes += len(finished)
            self.captures += sum(finished)
            self.logger.record("pecli/capture_rate", self.capture_rate)
            self.logger.record("pecli/episodes", self.episodes)
            for listener in self.listeners:
                listener(self.episodes)
        return True


class ProgressDisplay(BaseCallback):
    """A rich progress bar: steps, episodes, recent capture rate, steps/s and ETA; and/or ``lines``, plain
    progress lines (:class:`pecli.progress.PeriodicLines` over the learner's steps) for a log."""

    def __init__(
        self,
        stats: EpisodeStats,
        total_steps: int,
        description: str,
        enabled: bool = True,
        lines: PeriodicLines | None = None,
    ) -> None:
        super().__init__()
        self.stats = stats
        self.lines = lines
        self.total_steps = total_steps
        self.progress = Progress(
            TextColumn("[bold]{task.description}"),
            BarColumn(),
            TextColumn("{task.completed:>9,.0f}/{task.total:,.0f} steps"),
            TextColumn("ep {task.fields[episodes]:>6}  capture {task.fields[capture]}  {task.fields[rate]} steps/s"),
            TimeRemainingColumn(),
            disable=not enabled,
        )
        self.task = self.progress.add_task(
            escape(description), total=total_steps, episodes=0, capture="  -  ", rate="-"
        )
        self._last = 0.0
        self._start_time = 0.0
        self._start_steps = 0

    def _on_training_start(self) -> None:
        self.progress.start()
        self._start_time = time.perf_counter()
        self._start_steps = self.num_timesteps
        if self.lines is not None:
            self.lines.start = self.num_timesteps
        self.progress.update(self.task, completed=self.num_timesteps)

    def _on_step(self) -> bool:
        now = time.perf_counter()
        if now - self._last >= 0.5:
            self._last = now
            self._refresh(now)
            if self.lines is not None:
                self.lines.update(self.num_timesteps)
        return True

    def _refresh(self, now: float) -> None:
        rate = (self.num_timesteps - self._start_steps) / max(now - self._start_time, 1e-9)
        capture = self.stats.capture_rate
        self.progress.update(
            self.task,
            completed=self.num_timesteps,
            episodes=self.stats.episodes,
            capture="  -  " if math.isnan(capture) else f"{capture:5.2f}",
            rate=f"{rate:,.0f}",
        )
        self.logger.record("time/steps_per_second", rate)

    def _on_training_end(self) -> None:
        self._refresh(time.perf_counter())
        self.progress.stop()


class Evaluation(BaseCallback):
    """Every ``every`` learner transitions, play ``episodes`` batched games against a fixed opponent.

    ``evaluate(model)`` returns the capture rate; each result is logged to TensorBoard and appended
    to ``csv_path`` with the learner's steps and the run's CPU time (for learning curves): ``clock()``,
    by default the process's, which a resumed run offsets by what it had spent before. An evaluation
    better than every earlier one of the run (those already in ``csv_path`` included) calls
    ``on_best(rate)``; better is a higher capture rate for a pursuer (``maximise``), a lower one for
    an evader.
    """

    def __init__(
        self,
        evaluate: Callable[[object], float],
        every: int,
        csv_path: Path,
        clock: Callable[[], float] = time.process_time,
        on_best: Callable[[float], None] | None = None,
        maximise: bool = True,
        cpu_every: float | None = None,
        on_record: Callable[[int, float, float], None] | None = None,
    ) -> None:
        super().__init__()
        self.evaluate, self.clock, self.on_best, self.on_record = evaluate, clock, on_best, on_record
        self.sign = 1.0 if maximise else -1.0
        self.best = -math.inf  # the best score, sign * capture rate
        self.every = every
        self.cpu_every = cpu_every  # instead of every ``every`` transitions: every ``cpu_every`` s of ``clock()``
        self.csv_path = csv_path
        self._next = 0.0

    def _on_training_start(self) -> None:
        if self.cpu_every:
            self._next = (self.clock() // self.cpu_every + 1) * self.cpu_every
        else:
            self._next = (self.num_timesteps // self.every + 1) * self.every
        if self.csv_path.exists():  # a resumed run: its best so far is in its log
            rates = [row.capture_rate for row in read_evaluations(self.csv_path)]
            self.best = max((self.sign * rate for rate in rates), default=-math.inf)
        else:
            start_log(self.csv_path)
        self._wall = time.perf_counter()

    def _on_step(self) -> bool:
        if self.cpu_every:
            if self.clock() >= self._next:
                self._next = (self.clock() // self.cpu_every + 1) * self.cpu_every
                self.record()
        elif self.num_timesteps >= self._next:
            self._next += self.every
            self.record()
        return True

    def record(self) -> float:
        rate = self.evaluate(self.model)
        self.logger.record("eval/capture_rate", rate)
        cpu = self.clock()
        append_evaluation(self.csv_path, self.num_timesteps, cpu, time.perf_counter() - self._wall, rate)
        if self.on_record is not None:
            self.on_record(self.num_timesteps, cpu, rate)
        if self.sign * round(rate, 4) > self.best:  # as logged, so a resumed run's tie is no new best
            self.best = self.sign * round(rate, 4)
            if self.on_best is not None:
                self.on_best(rate)
        return rate


class CpuBudget(BaseCallback):
    """Stops learning at the first step at which ``clock()`` (the run's CPU seconds) reaches ``seconds``."""

    def __init__(self, clock: Callable[[], float], seconds: float) -> None:
        super().__init__()
        self.clock, self.seconds = clock, seconds

    def _on_step(self) -> bool:
        return self.clock() < self.seconds


class PoolTracker(BaseCallback):
    """Self-play: credits every finished episode to the opponent that played it and, under PFSP,
    re-weights the draws of the games that start next.

    Args:
        pool: the opponents' pool (records are updated in place).
        opponent: the learner's opponent, a ``MixedPolicy`` over ``pool``'s entries (same order).
        weigh: ``pool -> weights`` when draws follow the records (PFSP), else ``None``.
    """

    def __init__(self, pool: Any, opponent: Any, weigh: Callable[[Any], np.ndarray] | None = None) -> None:
        super().__init__()
        self.pool, self.opponent, self.weigh = pool, opponent, weigh
        self.episodes = 0
        self.captures = 0
        self.per_opponent: dict[str, list[int]] = {name: [0, 0] for name in opponent.names}  # [episodes, wins]
        self.listeners: list[Callable[[int], None]] = []  # called with the episodes so far when some finish

    @property
    def capture_rate(self) -> float:
        return self.captures / self.episodes if self.episodes else float("nan")

    def to_dict(self) -> dict[str, Any]:
        return {"episodes": self.episodes, "captures": self.captures, "per_opponent": self.per_opponent}

    def restore(self, data: dict[str, Any]) -> None:
        """Continue the records of :meth:`to_dict` (a turn resumed), crediting them to the pool again."""
        self.episodes, self.captures = int(data["episodes"]), int(data["captures"])
        for name, (episodes, wins) in data["per_opponent"].items():
            self.per_opponent[name] = [episodes, wins]
            entry = self.pool.entry(name)
            entry.episodes += episodes
            entry.wins += wins
        if self.weigh is not None:
            self.opponent.weights = self.weigh(self.pool)

    def _on_step(self) -> bool:
        finished = [info for info in self.locals["infos"] if "opponent" in info]
        for info in finished:
            entry_won = info["captured"] if self.pool.role == "pursuer" else not info["captured"]
            self.pool.observe(info["opponent"], entry_won)
            record = self.per_opponent[info["opponent"]]
            record[0] += 1
            record[1] += int(entry_won)
            self.episodes += 1
            self.captures += int(info["captured"])
        if finished:
            self.logger.record("selfplay/capture_rate", self.capture_rate)
            for name in {info["opponent"] for info in finished}:  # TensorBoard: the learner's record per opponent
                episodes, entry_wins = self.per_opponent[name]
                self.logger.record(f"selfplay/win_rate_vs/{name}", 1.0 - entry_wins / episodes)
            if self.weigh is not None:
                self.opponent.weights = self.weigh(self.pool)
            for listener in self.listeners:
                listener(self.episodes)
        return True


class RoundDisplay(BaseCallback):
    """A rich live view of one side's turn in a self-play round: a progress bar and the opponents
    with their draw weights, episodes and win rates this round."""

    def __init__(
        self,
        tracker: PoolTracker,
        total_steps: int,
        title: str,
        enabled: bool = True,
        lines: PeriodicLines | None = None,
    ) -> None:
        super().__init__()
        self.tracker = tracker
        self.lines = lines  # plain progress lines over the turn's steps, for a log
        self.total_steps = total_steps
        self.title = title
        self.enabled = enabled
        self.progress = Progress(
            TextColumn("[bold]{task.description}"),
            BarColumn(),
            TextColumn("{task.completed:>8,.0f}/{task.total:,.0f} steps"),
            TextColumn("ep {task.fields[episodes]:>5}  capture {task.fields[capture]}"),
            TimeRemainingColumn(),
        )
        self.task = self.progress.add_task(title, total=total_steps, episodes=0, capture="  -  ")
        self.live: Live | None = None
        self._start = 0
        self._last = 0.0

    def _table(self) -> Table:
        table = Table(box=None, padding=(0, 2), header_style="dim")
        for column in ("opponent", "weight", "episodes", "it wins"):
            table.add_column(column, justify="left" if column == "opponent" else "right")
        for name, weight in zip(self.tracker.opponent.names, self.tracker.opponent.weights):
            episodes, wins = self.tracker.per_opponent[name]
            table.add_row(name, f"{weight:.2f}", str(episodes), f"{wins / episodes:.2f}" if episodes else "-")
        return table

    def _render(self) -> Group:
        capture = self.tracker.capture_rate
        self.progress.update(
            self.task,
            completed=self.num_timesteps - self._start,
            episodes=self.tracker.episodes,
            capture="  -  " if math.isnan(capture) else f"{capture:5.2f}",
        )
        return Group(self.progress, self._table())

    def _on_training_start(self) -> None:
        self._start = self.num_timesteps
        if self.enabled:
            self.live = Live(self._render(), refresh_per_second=4, transient=True)
            self.live.start()

    def _on_step(self) -> bool:
        now = time.perf_counter()
        if now - self._last >= 0.25:
            self._last = now
            if self.live is not None:
                self.live.update(self._render())
            if self.lines is not None:
                self.lines.update(self.num_timesteps - self._start)
        return True

    def _on_training_end(self) -> None:
        self.close()

    def close(self) -> None:
        """Stop the live view (also when training stops with an exception)."""
        if self.live is not None:
            self.live.stop()
            self.live = None
