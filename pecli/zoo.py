"""The checkpoint zoo: a folder of training runs, each with its config, command and checkpoints.

Layout of one run::

    zoo/<run>/
        config.yaml          the resolved scenario, training section included
        command.txt          the exact command that started the run (and each resume)
        versions.json        pecli, Stable-Baselines3, torch, numpy and Python versions
        <role>/
            ep0000250.zip    a checkpoint every ``checkpoint_every`` episodes (SB3 zip)
            ep0000250.json   its metadata (see :class:`CheckpointMeta`)
            final.zip/.json  the end of training
            best.zip/.json   with ``eval_every``: the checkpoint of the run's best evaluation so far
            last.zip/.json   the newest durable state's model (where a stopped run resumes from)
            resume/          the durable state: model, optimisers, buffers (pecli.rl.durable)
        run.json             what the run is: command, role, opponent, seed (what a resume keeps)

Every file is written atomically. A run's name is one folder name (:func:`check_run_name`), and a
process that creates or opens a run to write it holds the run folder's lock (:mod:`pecli.locks`)
until it closes the run or ends.
"""

from __future__ import annotations

import math
import os
import platform
import re
import shlex
import shutil
import sys
import tempfile
import weakref
from dataclasses import asdict, dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import yaml
from pydantic import ValidationError

from pecli import __version__
from pecli.errors import PecliError
from pecli.io import atomic_path, atomic_write_json, atomic_write_text, read_json
from pecli.locks import acquire, release
from pecli.records import MAX_CPU_SECONDS, RUN_NAME, JobRecord
from pecli.roles import Role
from pecli.scenario import MAX_HISTORY, MAX_STEPS, Scenario, scenario_from_dict
from pecli.text import shortened

FINAL = "final"
LAST = "last"
BEST = "best"  # the checkpoint with the run's best evaluation (with eval_every)
CONFIG_FILE = "config.yaml"  # per run: the resolved scenario it was started with
COMMAND_FILE = "command.txt"  # per run: every command that started or resumed it
AVERAGE_FILE = "average.zip"  # per self-play main learner: the mean of its last rounds, what the run hands over
JOB_FILE = "run.json"  # per run of `pecli train`: its command, role, opponent and seed
SELFPLAY_FILE = "selfplay.json"  # per self-play run: its turns, pools and records (pecli.rl.state)
RUN_MARKS = (COMMAND_FILE, JOB_FILE, SELFPLAY_FILE)  # what pecli writes into every run folder it makes
MAX_METADATA_BYTES = 16 << 20  # a checkpoint's .json: its opponents' records make it grow with a self-play pool
RESUME_DIR = "resume"  # per role: the learner's durable state (pecli.rl.durable)


class ZooError(PecliError):
    """A run or checkpoint that is missing, damaged or does not fit."""


@dataclass
class CheckpointMeta:
    """What a checkpoint is: written next to it as ``<name>.json``."""

    role: Role
    steps: int  # learner transitions trained on
    episodes: int  # episodes finished while training
    algo: str  # a name of pecli.models.algorithms.ALGORITHMS: td3 | ddpg | ...
    belief: str  # none | bimdn | ...
    scenario: str  # scenario name
    scenario_hash: str  # Scenario.fingerprint(): a checkpoint only plays the game it learned
    opponent: str  # the policy string it trained against
    frame_skip: int
    frame_stack: int
    history_length: int
    history_stride: int
    run: str = ""
    seed: int = 0
    cpu_seconds: float | None = None  # pecli train: the run's CPU time when this was written, across resumes
    eval_capture_rate: float | None = None  # best.zip: the capture rate of the evaluation that made it the best
    round: int | None = None  # self-play: the round that produced it
    parent: str = ""  # self-play: the learner's checkpoint this round started from (run-relative)
    opponents: list[dict[str, Any]] = field(default_factory=list)  # self-play: the pool it trained against
    policy_kwargs: dict[str, Any] = field(
        default_factory=dict
    )  # pecli.models.algorithms.policy_kwargs: rebuilds the network
    belief_kwargs: dict[str, Any] | None = None  # the actor's BeliefModel arguments, with a belief
    averaged: list[str] = field(default_factory=list)  # pecli zoo average: the checkpoints it is the mean of
    pecli_version: str = __version__
    created: str = field(default_factory=lambda: datetime.now(UTC).isoformat(timespec="seconds"))

    def __post_init__(self) -> None:
        """Refuse values that cannot describe a checkpoint (a hand-edited or damaged file): ``ValueError``."""
        if self.role not in ("pursuer", "evader"):
            raise ValueError(f"role must be pursuer or evader, not {self.role!r}")
        for name, least, most in (
            ("steps", 0, MAX_STEPS),
            ("episodes", 0, MAX_STEPS),
            ("frame_skip", 1, 1000),
            ("frame_stack", 1, 1000),
            ("history_length", 1, MAX_HISTORY),
            ("history_stride", 1, MAX_HISTORY),
        ):  # the scenario's own bounds
            value = getattr(self, name)
            if not isinstance(value, int) or isinstance(value, bool) or not least <= value <= most:
                raise ValueError(f"{name} must be a whole number from {least} to {most}, not {shortened(value)}")
        for name in ("algo", "belief", "scenario", "scenario_hash", "opponent", "run", "parent", "pecli_version"):
            if not isinstance(getattr(self, name), str):
                raise ValueError(f"{name} must be a string, not {shortened(getattr(self, name))}")
        self._check_optional()
        if not isinstance(self.policy_kwargs, dict) or not isinstance(self.belief_kwargs, dict | None):
            raise ValueError("policy_kwargs and belief_kwargs must be JSON objects")
        if not isinstance(self.averaged, list) or not all(isinstance(p, str) for p in self.averaged):
            raise ValueError("averaged must be a list of checkpoint paths")

    def _check_optional(self) -> None:
        """Refuse what the fields pecli only reports hold if they are not what a run writes: ``ValueError``."""
        for name, most in (("seed", 2**32 - 1), ("round", MAX_STEPS)):
            value = getattr(self, name)
            if (value is not None or name == "seed") and (
                not isinstance(value, int) or isinstance(value, bool) or not 0 <= value <= most
            ):
                raise ValueError(f"{name} must be a whole number from 0 to {most}, not {shortened(value)}")
        for name, bound in (("cpu_seconds", MAX_CPU_SECONDS), ("eval_capture_rate", 1.0)):
            value = getattr(self, name)
            if value is not None and not (finite_number(value) and 0 <= value <= bound):
                raise ValueError(f"{name} must be a number from 0 to {bound:g}, not {shortened(value)}")
        if not isinstance(self.created, str):
            raise ValueError(f"created must be a date, not {shortened(self.created)}")
        if not isinstance(self.opponents, list) or not all(isinstance(o, dict) for o in self.opponents):
            raise ValueError("opponents must be a list of JSON objects")

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> CheckpointMeta:
        """The metadata in ``data`` (unknown keys ignored); ``ValueError`` naming the fields it lacks."""
        from dataclasses import MISSING, fields

        every = fields(cls)
        required = [f.name for f in every if f.default is MISSING and f.default_factory is MISSING]
        missing = [name for name in required if name not in data]
        if missing:
            raise ValueError(f"no {', '.join(missing)}")
        return cls(**{f.name: data[f.name] for f in every if f.name in data})


def metadata_path(checkpoint: Path) -> Path:
    """The metadata file of a checkpoint: ``ep0000250.zip`` → ``ep0000250.json``."""
    return checkpoint.with_suffix(".json")


def read_metadata(checkpoint: str | Path) -> CheckpointMeta:
    """The metadata of ``checkpoint``; :class:`ZooError` if it is missing or unreadable."""
    path = metadata_path(Path(checkpoint))
    if not path.is_file():
        raise ZooError(f"{checkpoint}: no metadata file {path.name} beside it (is this a pecli checkpoint?)")
    try:
        data = read_json(path, "metadata", max_bytes=MAX_METADATA_BYTES)
    except PecliError as exc:
        raise ZooError(str(exc)) from None
    try:
        if not isinstance(data, dict):
            raise TypeError("not a JSON object")
        return CheckpointMeta.from_dict(data)
    except (TypeError, ValueError, KeyError, AttributeError) as exc:
        raise ZooError(f"{path}: damaged metadata ({exc})") from None


CHECKPOINT_ENTRIES = ("data", "policy.pth")  # what every checkpoint zip (SB3's save) holds


def checkpoint_problem(checkpoint: Path, thorough: bool = False) -> str:
    """Why ``checkpoint`` is not a readable checkpoint file, or ``""``: empty, not a zip (truncated or
    damaged), a zip without a checkpoint's entries; with ``thorough``, also an entry that fails its CRC
    check (which reads the whole file)."""
    import zipfile
    import zlib

    try:
        if checkpoint.stat().st_size == 0:
            return "empty file"
        with zipfile.ZipFile(checkpoint) as archive:
            missing = [name for name in CHECKPOINT_ENTRIES if name not in archive.namelist()]
            if missing:
                return f"not a pecli checkpoint (no '{missing[0]}' in the zip: truncated, or another zip)"
            if thorough and (bad := archive.testzip()) is not None:
                return f"damaged zip ('{bad}' fails its CRC check)"
    except (zipfile.BadZipFile, EOFError, zlib.error, NotImplementedError, ValueError):
        return "damaged zip (truncated or not a zip)"
    except OSError as exc:
        return f"unreadable ({exc.strerror or exc})"
    return ""


def versions() -> dict[str, str]:
    """Versions of what a checkpoint depends on."""
    import numpy
    import stable_baselines3
    import torch

    return {
        "pecli": __version__,
        "stable_baselines3": stable_baselines3.__version__,
        "torch": torch.__version__,
        "numpy": numpy.__version__,
        "python": platform.python_version(),
    }


def command_line() -> str:
    """The command that is running, quoted so that it can be pasted back into a shell."""
    return shlex.join([Path(sys.argv[0]).name, *sys.argv[1:]])


_RUN_NAME = re.compile(RUN_NAME)


def check_run_name(name: str) -> str:
    """``name`` if it is one folder name of letters, digits, ``-``, ``_`` and ``.`` (not starting with
    ``.``, at most 128 characters); else :class:`ZooError`: a run stays inside its zoo."""
    if not isinstance(name, str) or not _RUN_NAME.fullmatch(name):
        raise ZooError(
            f"run name {name!r} is not allowed: use one folder name of letters, digits, '-', '_' "
            "and '.' (not starting with '.', at most 128 characters)"
        )
    return name


def safe_run_name(text: str) -> str:
    """``text`` as a run name: every other character becomes ``-`` (for names made from a scenario's name)."""
    return re.sub(r"[^A-Za-z0-9._-]+", "-", text).lstrip(".-")[:128] or "run"


class Run:
    """One training run in a zoo: ``zoo/<name>/``.

    :meth:`create` and :meth:`open` take the run folder's lock for writing; it is released by
    :meth:`close`, when the object is garbage-collected, or when the process ends.
    """

    def __init__(self, path: Path) -> None:
        self.path = path
        self.name = path.name

    def _lock(self) -> None:
        acquire(self.path, f"run '{self.name}'")
        self._release = weakref.finalize(self, release, self.path)

    def close(self) -> None:
        """Release the run folder's lock (taken by :meth:`create` or :meth:`open`)."""
        if hasattr(self, "_release"):
            self._release()

    @staticmethod
    def check_new(zoo: Path, name: str) -> None:
        """:class:`ZooError` unless ``name`` is a valid run name and ``zoo/name`` is free for a new run."""
        check_run_name(name)
        if (zoo / name).exists():
            raise ZooError(f"run '{name}' already exists in {zoo}: pass --resume to continue it, or another --name")

    @classmethod
    def create(cls, zoo: Path, name: str, scenario: Scenario, job: dict[str, Any]) -> Run:
        """Make a new run folder holding its config, versions, command and ``job`` (see :meth:`write_job`);
        :class:`ZooError` if one of that name exists. The folder appears whole or not at all."""
        cls.check_new(zoo, name)
        path = zoo / name
        try:
            zoo.mkdir(parents=True, exist_ok=True)
            staging = Path(tempfile.mkdtemp(prefix=f".{name}.", dir=zoo))
        except OSError as exc:
            raise ZooError(f"cannot create the run folder {path}: {exc.strerror}") from None
        run = cls(staging)
        run.write_config(scenario)
        atomic_write_json(staging / "versions.json", versions())
        run.write_job(job)
        run.log_command()
        try:
            staging.rename(path)
        except OSError as exc:
            shutil.rmtree(staging, ignore_errors=True)
            raise ZooError(f"cannot create the run folder {path}: {exc.strerror}") from None
        run = cls(path)
        run._lock()
        return run

    @classmethod
    def open(cls, zoo: Path, name: str) -> Run:
        """The run ``zoo/name``, locked for writing; :class:`ZooError` if there is none."""
        path = zoo / check_run_name(name)
        if not (path / CONFIG_FILE).is_file():
            raise ZooError(f"no run '{name}' in {zoo} to resume")
        run = cls(path)
        run._lock()
        return run

    def scenario(self) -> Scenario:
        """The resolved scenario the run was started with."""
        from pecli.errors import ConfigError
        from pecli.scenario import read_yaml

        source = self.path / CONFIG_FILE
        try:
            data = read_yaml(source)
        except ConfigError as exc:
            raise ZooError(f"damaged run config: {exc}") from None
        return scenario_from_dict(data, source=str(source))

    def write_config(self, scenario: Scenario) -> None:
        """Write the resolved scenario as the run's ``config.yaml``."""
        atomic_write_text(self.path / CONFIG_FILE, yaml.safe_dump(scenario.model_dump(mode="json"), sort_keys=False))

    def log_command(self) -> None:
        """Append the current command to ``command.txt``."""
        log = self.path / COMMAND_FILE
        previous = log.read_text() if log.exists() else ""
        atomic_write_text(log, previous + command_line() + "\n")

    def role_dir(self, role: Role) -> Path:
        directory = self.path / role
        directory.mkdir(exist_ok=True)
        return directory

    def checkpoint(self, role: Role, name: str) -> Path:
        """Path of the checkpoint ``name`` (``ep0000250``, ``final``, ``last``) of ``role``."""
        return self.role_dir(role) / f"{name}.zip"

    @staticmethod
    def episode_name(episodes: int) -> str:
        return f"ep{episodes:07d}"

    def save(self, model: Any, role: Role, name: str, meta: CheckpointMeta) -> Path:
        """Write ``model`` (an SB3 algorithm) and its metadata atomically; returns the checkpoint path."""
        path = self.checkpoint(role, name)
        with atomic_path(path) as tmp:
            model.save(tmp)
        atomic_write_json(metadata_path(path), meta.to_dict())
        return path

    def publish(self, source: Path, role: Role, name: str, meta: CheckpointMeta) -> Path:
        """Make the model file ``source`` (a durable state's) the checkpoint ``name`` of ``role`` too, with
        ``meta``: a hard link where the file system allows one (no second copy is written), else a copy."""
        path = self.checkpoint(role, name)
        with atomic_path(path) as tmp:
            tmp.unlink()
            try:
                os.link(source, tmp)
            except OSError:
                shutil.copyfile(source, tmp)
        atomic_write_json(metadata_path(path), meta.to_dict())
        return path

    def write_job(self, job: dict[str, Any]) -> None:
        """Record what the run is (``run.json``): the command and the settings a resume must keep."""
        atomic_write_json(self.path / JOB_FILE, job)

    def job(self) -> dict[str, Any] | None:
        """What :meth:`write_job` recorded; ``None`` for a run without it (written by an older pecli)."""
        path = self.path / JOB_FILE
        if not path.is_file():
            return None
        try:
            data = read_json(path, "run record", max_bytes=1 << 20)
        except PecliError as exc:
            raise ZooError(str(exc)) from None
        if not isinstance(data, dict):
            raise ZooError(f"{path}: damaged (not a JSON object)")
        try:
            JobRecord.model_validate(data)
        except ValidationError as exc:
            first = exc.errors()[0]
            raise ZooError(
                f"{path}: damaged ({'.'.join(map(str, first['loc'])) or 'record'}: {first['msg']})"
            ) from None
        return data


@dataclass
class CheckpointEntry:
    """One checkpoint file found in a zoo, with its metadata or the reason it has none."""

    path: Path
    meta: CheckpointMeta | None
    problem: str = ""


def runs_in(zoo: Path) -> list[Run]:
    """Every run folder (one with a ``config.yaml``) under ``zoo``, sorted by name."""
    if (zoo / CONFIG_FILE).is_file():
        return [Run(zoo)]
    return [Run(p.parent) for p in sorted(zoo.glob(f"*/{CONFIG_FILE}"))]


def run_of(checkpoint: Path) -> Run | None:
    """The run a checkpoint sits in (``RUN/ROLE/NAME.zip`` with ``RUN/config.yaml``), or None outside a run."""
    run = checkpoint.parent.parent
    return Run(run) if (run / CONFIG_FILE).is_file() else None


def checkpoints_in(run: Run) -> list[CheckpointEntry]:
    """The checkpoints of a run, each with its metadata; damaged ones say why."""
    entries = []
    for path in sorted(run.path.glob("*/*.zip")):
        if not metadata_path(path).is_file():
            entries.append(CheckpointEntry(path, None, "no metadata"))
            continue
        try:
            meta = read_metadata(path)
        except ZooError:
            entries.append(CheckpointEntry(path, None, "damaged metadata"))
            continue
        entries.append(CheckpointEntry(path, meta, checkpoint_problem(path)))
    return entries


def finite_number(value: object) -> bool:
    """Whether ``value`` is a finite int or float (a boolean is not), as a record read back must hold."""
    return isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value)
