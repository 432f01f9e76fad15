"""SB3 callbacks of a training run: curriculum, episode statistics and progress, zoo checkpoints, evaluation."""

from __future__ import annotations

import csv
import math
import time
from collections import deque
from collections.abc import Callable
from pathlib import Path

import numpy as np
from rich.progress import BarColumn, Progress, TextColumn, TimeRemainingColumn
from stable_baselines3.common.callbacks import BaseCallback

from pecli.scenario import Scenario


class CurriculumCallback(BaseCallback):
    """Paper section V-A: over the first ``fraction`` of ``total_steps`` the pursuer's FOV shrinks
    linearly from 2pi to its configured value and the evader's speed limit grows from 0 to its own.

    The schedule follows ``model.num_timesteps``, so a resumed run continues it where it stopped.
    """

    def __init__(self, scenario: Scenario, total_steps: int, fraction: float) -> None:
        super().__init__()
        self.final_fov = scenario.pursuer.sensor.fov
        self.span = max(1.0, fraction * total_steps)

    def progress(self) -> float:
        return min(1.0, self.num_timesteps / self.span)

    def _apply(self) -> None:
        p = self.progress()
        fov = 2 * math.pi + (self.final_fov - 2 * math.pi) * p
        self.training_env.env_method("set_curriculum", fov, p)
        self.logger.record("curriculum/progress", p)

    def _on_training_start(self) -> None:
        self._apply()

    def _on_step(self) -> bool:
        self._apply()
        return True


class EpisodeStats(BaseCallback):
    """Counts finished episodes and captures from the view's ``infos``; logs the recent capture rate.

    ``on_episodes(total)`` is called whenever episodes finish (checkpointing hooks in there).
    """

    def __init__(self, episodes: int = 0, window: int = 100) -> None:
        super().__init__()
        self.episodes = episodes
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
            self.logger.record("pecli/capture_rate", self.capture_rate)
            self.logger.record("pecli/episodes", self.episodes)
            for listener in self.listeners:
                listener(self.episodes)
        return True


class ProgressDisplay(BaseCallback):
    """A rich progress bar: steps, episodes, recent capture rate, steps/s and ETA."""

    def __init__(self, stats: EpisodeStats, total_steps: int, description: str, enabled: bool = True) -> None:
        super().__init__()
        self.stats = stats
        self.total_steps = total_steps
        self.progress = Progress(
            TextColumn("[bold]{task.description}"),
            BarColumn(),
            TextColumn("{task.completed:>9,.0f}/{task.total:,.0f} steps"),
            TextColumn("ep {task.fields[episodes]:>6}  capture {task.fields[capture]}  {task.fields[rate]} steps/s"),
            TimeRemainingColumn(),
            disable=not enabled,
        )
        self.task = self.progress.add_task(description, total=total_steps, episodes=0, capture="  -  ", rate="-")
        self._last = 0.0
        self._start_time = 0.0
        self._start_steps = 0

    def _on_training_start(self) -> None:
        self.progress.start()
        self._start_time = time.perf_counter()
        self._start_steps = self.num_timesteps
        self.progress.update(self.task, completed=self.num_timesteps)

    def _on_step(self) -> bool:
        now = time.perf_counter()
        if now - self._last >= 0.5:
            self._last = now
            self._refresh(now)
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
    to ``csv_path`` with the learner's steps and the process's CPU time (for learning curves).
    """

    def __init__(self, evaluate: Callable[[object], float], every: int, csv_path: Path) -> None:
        super().__init__()
        self.evaluate = evaluate
        self.every = every
        self.csv_path = csv_path
        self._next = 0

    def _on_training_start(self) -> None:
        self._next = (self.num_timesteps // self.every + 1) * self.every
        if not self.csv_path.exists():
            with self.csv_path.open("w", newline="") as handle:
                csv.writer(handle).writerow(["steps", "cpu_seconds", "wall_seconds", "capture_rate"])
        self._wall = time.perf_counter()

    def _on_step(self) -> bool:
        if self.num_timesteps >= self._next:
            self._next += self.every
            self.record()
        return True

    def record(self) -> float:
        rate = self.evaluate(self.model)
        self.logger.record("eval/capture_rate", rate)
        with self.csv_path.open("a", newline="") as handle:
            csv.writer(handle).writerow(
                [self.num_timesteps, f"{time.process_time():.2f}", f"{time.perf_counter() - self._wall:.2f}", f"{rate:.4f}"]
            )
        return rate
