"""One side of self-play: the run's job, a learner (its model, view, durable state and callbacks), turn seeds.

Used by the loop (:mod:`pecli.rl.selfplay`) and by the schedules that play its rounds (:mod:`pecli.rl.schedules`).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import numpy as np

from pecli.errors import PecliError
from pecli.policies.base import Policy
from pecli.rl.callbacks import CurriculumCallback, EpisodeStats
from pecli.rl.durable import DurableState
from pecli.rl.pool import EXPLOITER, MAIN
from pecli.rl.state import SelfPlayState
from pecli.rl.train import TrainJob, make_learner
from pecli.roles import ROLES, Role
from pecli.scenario import Scenario
from pecli.zoo import RESUME_DIR, Run

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
    log_every: float | None = None  # seconds between plain progress lines (a log's, when there is no bar); None: none
    device: str = "cpu"  # where the networks train: cpu, cuda or auto
    cpu_hours: float | None | Literal["keep"] = KEEP  # the run's CPU budget (pecli.rl.budget), None for none, or
    # KEEP: a resumed run's own (none for a new run)


def tensorboard_name(role: Role, kind: str, r: int) -> str:
    """The TensorBoard run a turn logs to, under the run's ``tb/``: one per main learner (``pursuer_0``), and one
    per exploiter turn (``exploiter-pursuer/r007_0``), since an exploiter that joined its pool starts again
    from step 0 and would draw over the curves of the one before."""
    return role if kind == MAIN else f"exploiter-{role}/r{r:03d}"


def turn_seed(seed: int, round: int, role: Role, kind: str = MAIN) -> int:
    """The seed of one turn: fixed by the run's seed, so a resumed run plays the turns it would have."""
    entropy = [seed, round, ROLES.index(role)] + ([1] if kind == EXPLOITER else [])
    return int(np.random.SeedSequence(entropy).generate_state(1)[0] % 2**31)


def opponent_wins(role: Role, stats: EpisodeStats) -> int:
    """The opponent's wins among the episodes ``stats`` counted for ``role``'s learner."""
    return stats.episodes - stats.captures if role == "pursuer" else stats.captures


class Learner:
    """One side of self-play: its SB3 model, its batched view, its durable state and the callbacks that
    outlive a turn."""

    def __init__(
        self,
        job: SelfPlayJob,
        role: Role,
        placeholder: Policy | None,
        run: Run,
        state: SelfPlayState,
        view: Any = None,
        kind: str = MAIN,
    ) -> None:
        """Build the ``kind`` learner of ``role`` (main, or a league's exploiter) afresh, or from its durable
        state when it has one. It plays against ``placeholder`` (replaced by each turn's pool) or, in the
        simultaneous schedule, in ``view``."""
        self.role, self.kind = role, kind
        self.folder = role if kind == MAIN else f"{EXPLOITER}-{role}"  # where its checkpoints and state go
        self.train_job = TrainJob(
            role=role,
            scenario=job.scenario,
            opponent="selfplay",
            zoo=job.zoo,
            name=job.name,
            seed=job.seed,
            device=job.device,
        )
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
            raise PecliError(
                f"run '{run.name}' was written by an older pecli (its {role} has no {RESUME_DIR}/ state), "
                "which this one cannot resume; its checkpoints still play (with --trust)"
            )
        else:
            self.durable.clear()  # a fresh learner: what a stop before its first commit left goes

    def progress(self, round: int) -> dict[str, Any] | None:
        """The committed progress of the learner's turn in ``round`` (``None`` if it has none)."""
        record = self.durable.record
        if record is None or record.extra.get("round") != round:
            return None
        return record.extra
