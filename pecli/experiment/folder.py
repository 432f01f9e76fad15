"""An experiment's folder: what ``pecli experiment run`` writes there, read back by ``status`` and ``report``.

See :mod:`pecli.experiment.pipeline` for the layout.
"""

from __future__ import annotations

import socket
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from pecli.errors import PecliError
from pecli.experiment.runs import RunProgress, run_progress
from pecli.experiment.spec import LoadedExperiment, RunSpec, experiment_from_dict
from pecli.io import read_json
from pecli.locks import process_alive
from pecli.records import StateRecord, TaskMarker, validated
from pecli.scenario import read_yaml

SPEC_FILE = "experiment.yaml"
SCENARIO_FILE = "scenario.yaml"
STATE_FILE = "experiment.json"
KEPT_FILE = "kept.json"


@dataclass
class RunStatus:
    """One row of the live table."""

    run: RunSpec
    progress: RunProgress
    status: str = "pending"  # pending, queued, running, done, paused, failed, stopped
    error: str = ""
    submitted: float = 0.0
    host: str = ""


def open_experiment(out: Path) -> LoadedExperiment:
    """The experiment recorded in ``out`` (by a previous ``run``)."""
    path = out / SPEC_FILE
    if not path.is_file():
        raise PecliError(
            f"{out} holds no experiment (no {SPEC_FILE}): start one with `pecli experiment run NAME --out {out}`"
        )
    return experiment_from_dict(read_yaml(path), str(path))  # ConfigError in one line if damaged


def read_state(out: Path) -> dict[str, Any]:
    """``experiment.json`` of ``out`` ({} before there is one); :class:`PecliError` in one line if it is not one."""
    path = out / STATE_FILE
    if not path.is_file():
        return {}
    data = read_json(path, "experiment record")
    if not isinstance(data, dict):
        raise PecliError(f"{path}: damaged experiment record (not a JSON object)")
    validated(StateRecord, data, path, "experiment record")
    return data


def driver_alive(state: dict[str, Any]) -> bool:
    """Whether the driver that last wrote ``state`` still runs (known only on the driver's own host)."""
    driver = state.get("driver") or {}
    if driver.get("host") != socket.gethostname() or not isinstance(driver.get("pid"), int):
        return False
    return process_alive(driver["pid"]) and driver.get("ended") is None


def stage_lines(out: Path, state: dict[str, Any], alive: bool) -> list[str]:
    """The ranking's and the tournament's progress, one line each, from ``state``, whether its driver is
    ``alive``, and the pairings cached in ``out``: e.g. ``"ranking: running, 684/939 pairings played"``."""
    lines = []
    sessions = state.get("sessions") or [{}]
    if state.get("stages", {}).get("train") == "paused" and sessions[-1].get("until_cpu_hours"):
        lines.append(
            f"training: paused, every run at {sessions[-1]['until_cpu_hours']:g} CPU-h or its own budget "
            "(--until-cpu-hours)"
        )
    for name in ("ranking", "tournament"):
        stage = state.get("stages", {}).get(name)
        if not isinstance(stage, dict):
            continue
        total, status = stage.get("pairings", 0), stage.get("status")
        if status == "done":
            lines.append(f"{name}: done, {total} pairings")
            continue
        cache = out / name / "pairings"
        played = min(total, len(list(cache.glob("*.json")))) if cache.is_dir() else 0
        lines.append(f"{name}: {status if alive else 'stopped'}, {played}/{total} pairings played")
    return lines


def statuses(experiment: LoadedExperiment, out: Path) -> list[RunStatus]:
    """Every run's status from the files in ``out`` (what ``pecli experiment status`` shows)."""
    state = read_state(out)
    alive = driver_alive(state)
    recorded = state.get("runs", {})
    rows = []
    for run in experiment.runs():
        progress = run_progress(run, out / "zoo")
        record = recorded.get(run.name, {})
        status = record.get("status", "pending")
        marker = read_task_marker(out, run)
        if progress.done:
            status = "done"
        elif status in ("running", "queued") and not alive:
            status = "stopped"
        elif status == "queued" and marker.get("started", 0) >= (state.get("driver") or {}).get(
            "started", float("inf")
        ):
            status = "running"
        row = RunStatus(run, progress, status, record.get("error", ""), host=marker.get("host", ""))
        rows.append(row)
    return rows


def read_task_marker(out: Path, run: RunSpec) -> dict[str, Any]:
    """Where and since when a run's task runs (``tasks/<run>.json``, written by the task); {} if unknown."""
    try:
        data = read_json(out / "tasks" / f"{run.name}.json", "task record")
        validated(TaskMarker, data, run.name, "task record")
    except PecliError:
        return {}
    return data
