"""One run of an experiment: train it (or continue it) with pecli's own entry points, and read its
progress from its files.

A run is a self-play run (:class:`pecli.rl.selfplay.SelfPlay`) or a one-role run
(:func:`pecli.rl.train.train`) in the experiment's zoo, ``<out>/zoo/<run>``. Both commit a durable
state at every checkpoint, so :func:`execute_run` continues whatever a stop left (Ctrl-C, a killed
driver, a lost worker) and trains nothing for a finished run: it is safe to call again, which is what a
retried task does.
"""

from __future__ import annotations

import shutil
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

from pecli.errors import ConfigError, PecliError
from pecli.experiment.spec import RunSpec
from pecli.io import read_json
from pecli.records import ProgressRecord, validated
from pecli.rl.budget import budget_reached, whole_rounds
from pecli.rl.handover import STATE_FILE as SELFPLAY_STATE
from pecli.rl.handover import stale_averages
from pecli.rl.state import SelfPlayState, read_state_file
from pecli.scenario import Training, dotted, read_yaml
from pecli.zoo import CONFIG_FILE, FINAL, RESUME_DIR, Run

DURABLE_RECORD = "state.json"  # pecli.rl.durable.RECORD, read here as plain JSON


@dataclass
class RunProgress:
    """What a run's files say about it."""

    round: int  # rounds finished (self-play) or 0
    rounds: int  # rounds planned (self-play) or 0
    steps: int  # learner transitions, all roles together
    cpu_seconds: float  # the run's CPU time so far (every process that worked on it)
    done: bool
    role: str = ""  # the role training now (self-play), if known

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


def _progress(path: Path) -> ProgressRecord | None:
    """A learner's progress; ``None`` when there is none yet or it is damaged (its trainer says so)."""
    try:
        return validated(ProgressRecord, read_json(path, "record"), path, "record")
    except PecliError:
        return None


def _selfplay_state(path: Path) -> SelfPlayState | None:
    """A self-play run's validated state; ``None`` when there is none yet or it is damaged (its trainer says so)."""
    try:
        return read_state_file(path)
    except PecliError:
        return None


def run_progress(run: RunSpec, zoo: Path) -> RunProgress:
    """The run's progress from its files (cheap: a few small JSON files); all zeros for a run not started."""
    folder = zoo / run.name
    records = [_progress(folder / role / RESUME_DIR / DURABLE_RECORD) for role in run.roles]
    steps = sum(r.steps for r in records if r is not None)
    cpu = max((r.cpu_seconds for r in records if r is not None), default=0.0)
    if not run.selfplay:
        role = run.schedule
        done = (folder / role / f"{FINAL}.zip").is_file()
        return RunProgress(0, 0, steps, cpu, done)
    planned = run.scenario.training.selfplay.rounds
    state = _selfplay_state(folder / SELFPLAY_STATE)
    turns = state.records() if state is not None else []
    settings = run.scenario.training.selfplay
    rounds = min(whole_rounds(turns, settings), planned)
    cpu = max(cpu, sum(float(t.get("cpu_seconds", 0.0)) for t in turns))
    done = rounds == planned or budget_reached(turns, run.cpu_hours, settings)
    role = ""
    if not done:
        mains = {(t.get("round"), t.get("role")) for t in turns if t.get("learner", "main") == "main"}
        role = "evader" if (rounds + 1, "pursuer") in mains else "pursuer"
    return RunProgress(rounds, planned, steps, cpu, done, role)


def averages_behind(run: RunSpec, zoo: Path) -> bool:
    """Whether a self-play run's averages lag its rounds (a stop came between a round's record and them): its
    task, even when the run is finished, has them to write (cheap: JSON files only)."""
    state = _selfplay_state(zoo / run.name / SELFPLAY_STATE) if run.selfplay else None
    if state is None:  # none yet, or damaged: its trainer says so
        return False
    return bool(stale_averages(zoo / run.name, state.records(), state.curriculum_steps, run.scenario))


def training_left(runs: Sequence[tuple[RunSpec, RunProgress]]) -> tuple[float, int]:
    """An estimate of the CPU seconds the unfinished runs still need: for each, the mean CPU time of the
    finished runs of its kind and schedule, less what it has used. Returns ``(seconds, runs)``, ``runs``
    counting the unfinished runs left out for want of a finished run like them."""
    spent: dict[tuple[str, str], list[float]] = {}
    for run, progress in runs:
        if progress.done:
            spent.setdefault((run.kind, run.schedule), []).append(progress.cpu_seconds)
    seconds, unknown = 0.0, 0
    for run, progress in runs:
        if progress.done:
            continue
        finished = spent.get((run.kind, run.schedule))
        if finished:
            seconds += max(0.0, sum(finished) / len(finished) - progress.cpu_seconds)
        else:
            unknown += 1
    return seconds, unknown


def execute_run(
    run: RunSpec, zoo: Path, progress: bool = False, report: Callable[[str], None] = lambda line: None
) -> dict[str, Any]:
    """Train ``run`` into ``zoo`` to the end of its budget: start it, continue it from its durable state,
    or, for a finished run, train nothing (a self-play run's averages are written if a stop left them behind).
    Returns what it did (``started``, ``resumed`` or ``finished``), with the CPU seconds of this call and the
    run's progress. ``progress`` shows the trainers' own live progress; ``report`` gets self-play's line after
    each round (as ``pecli selfplay`` prints it)."""
    import torch

    from pecli.rl.selfplay import SelfPlay, SelfPlayJob, read_state, write_averages
    from pecli.rl.train import TrainJob, train
    from pecli.roles import DEFAULT_OPPONENT

    torch.set_num_threads(run.scenario.training.torch_threads)
    cpu = time.process_time()
    before = run_progress(run, zoo)
    folder = zoo / run.name
    if before.done:
        if averages_behind(run, zoo):  # a stop came between the last round's record and its averages
            run_dir = Run.open(zoo, run.name)
            try:
                write_averages(run_dir, read_state(run_dir), run.scenario)
            finally:
                run_dir.close()
        return {"did": "finished", "cpu_seconds": 0.0, "progress": before.to_dict()}
    if run.selfplay:
        resume = (folder / SELFPLAY_STATE).is_file()
        if folder.exists() and not resume:
            # stopped between creating the run folder and writing its first state: nothing was trained
            shutil.rmtree(folder)
        SelfPlay(
            SelfPlayJob(
                scenario=run.scenario,
                zoo=zoo,
                name=run.name,
                seed=run.seed,
                resume=resume,
                progress=progress,
                cpu_hours=run.cpu_hours,
            ),
            report=report,
        ).run()
    else:
        resume = (folder / CONFIG_FILE).is_file()
        opponent = run.opponent or DEFAULT_OPPONENT[run.schedule]
        train(
            TrainJob(
                role=run.schedule,
                scenario=run.scenario,
                opponent=opponent,
                zoo=zoo,
                name=run.name,
                seed=run.seed,
                resume=resume,
                progress=progress,
            )
        )
    return {
        "did": "resumed" if resume else "started",
        "cpu_seconds": round(time.process_time() - cpu, 2),
        "progress": run_progress(run, zoo).to_dict(),
    }


def setting_changes(old: Any, new: dict[str, Any]) -> list[str]:
    """The settings of the recorded scenario dump ``old`` that differ in ``new``, as ``key: old -> new``
    (dotted keys). A training setting ``old`` lacks (one added to pecli since) ran at its default: it is a
    change only where ``new`` sets it otherwise."""
    before, after = dotted(old), dotted(new)
    defaults = dotted(Training().model_dump(mode="json"), "training.")
    added = {key: defaults[key] for key in after.keys() & (defaults.keys() - before.keys())}  # ran at their defaults
    recorded = {**added, **before}
    shown = {key: f"{value} (its default)" for key, value in added.items()}
    return [
        f"{key}: {shown.get(key, recorded[key])} -> {after.get(key, '(no such setting)')}"
        for key in sorted(recorded)
        if recorded[key] != after.get(key, object())
    ]


def check_unchanged(run: RunSpec, zoo: Path) -> None:
    """:class:`ConfigError` if ``run`` was started in ``zoo`` with other settings: a resumed run keeps its own."""
    recorded = zoo / run.name / CONFIG_FILE
    if not recorded.is_file():
        return
    changed = setting_changes(read_yaml(recorded), run.scenario.model_dump(mode="json"))
    if changed:
        raise ConfigError(f"{run.name} was started with other settings ({changed[0]}): give them again, or another zoo")
