"""Durable training state: what a stopped learner needs to continue, on disk at every checkpoint.

A run can end at any moment: Ctrl-C, SIGKILL, the OOM killer, a power cut, a preempted cluster worker.
At every checkpoint :meth:`DurableState.save` writes what the learner needs to continue, so a stop
loses at most one checkpoint interval::

    <run>/<role>/resume/
        state.json                       the commit record: names every file below, with the counters
        model-000120000.zip              weights and optimiser states (SB3's zip; only its state dicts are read back)
        replay-00000000-00001500.npz     rows of the replay buffer, those added in one interval (plain arrays)
        belief-00000000-00012000.npz     a learned belief's (window, position) pairs, likewise
        belief-optimizer-000120000.pt    the belief's optimiser state (tensors: torch.load(weights_only=True))

A buffer is written incrementally: each save adds one file with the rows added since the previous
save (and the previous save's last row again, which may have been marked as an episode end since),
and a file leaves once every row of it has been overwritten in the ring. So a save costs what the
interval added, not the whole buffer. Each save writes its new files, then replaces ``state.json``
(the commit), then deletes what ``state.json`` no longer names: a file is either named by the
committed record and complete, or garbage left by a stop, removed by the next save or load.

Not saved: the games in flight. A resumed learner starts new games (from a seed of its own,
see :func:`pecli.rl.train.resume_seed`), so the partial episodes of the interval are lost too.
"""

from __future__ import annotations

import math
import zipfile
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch as th

from pecli.errors import PecliError
from pecli.io import atomic_path, atomic_write_json, read_bounded, read_json
from pecli.models.buffers import end_episodes
from pecli.trust import untrusted
from pecli.zoo import ZooError

RECORD = "state.json"
FORMAT = 1


@dataclass
class Chunk:
    """One file of a ring buffer: the rows numbered ``[start, end)`` since the buffer was created."""

    file: str
    start: int
    end: int


@dataclass
class Ring:
    """What the files of one ring buffer hold: ``added`` rows so far, in a ring of ``capacity`` rows."""

    capacity: int
    added: int = 0
    chunks: list[Chunk] = field(default_factory=list)

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> Ring:
        chunks = [Chunk(**c) for c in data["chunks"]]
        ring = cls(_count(data["capacity"], "capacity"), _count(data["added"], "added"), chunks)
        for c in chunks:
            if not isinstance(c.file, str) or _count(c.start, "start") > _count(c.end, "end"):
                raise ValueError(f"a chunk of rows {c.start!r} to {c.end!r} in {c.file!r}")
        return ring


def _count(value: Any, name: str) -> int:
    """``value`` if it is a whole number >= 0; ``ValueError`` naming ``name`` otherwise."""
    if not isinstance(value, int) or isinstance(value, bool) or value < 0:
        raise ValueError(f"{name} must be a whole number >= 0, not {value!r}")
    return value


@dataclass
class Record:
    """The committed state of one learner (``state.json``)."""

    steps: int  # the model's num_timesteps
    episodes: int
    n_updates: int
    cpu_seconds: float
    model: str
    replay: Ring | None = None
    belief: Ring | None = None
    belief_optimizer: str | None = None
    belief_rng: dict[str, Any] | None = None
    extra: dict[str, Any] = field(default_factory=dict)  # the caller's: self-play's turn in progress
    format: int = FORMAT

    def files(self) -> set[str]:
        """Every file the record names."""
        names = {self.model}
        for ring in (self.replay, self.belief):
            if ring is not None:
                names |= {c.file for c in ring.chunks}
        if self.belief_optimizer:
            names.add(self.belief_optimizer)
        return names

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> Record:
        if data.get("format") != FORMAT:
            raise ValueError(f"format {data.get('format')!r}, this pecli reads {FORMAT}")
        rings = {key: Ring.from_dict(data[key]) if data.get(key) else None for key in ("replay", "belief")}
        record = cls(**{**data, **rings})
        for name in ("steps", "episodes", "n_updates"):
            _count(getattr(record, name), name)
        if not isinstance(record.cpu_seconds, int | float) or not math.isfinite(record.cpu_seconds):
            raise ValueError(f"cpu_seconds must be a number, not {record.cpu_seconds!r}")
        if (
            not isinstance(record.model, str)
            or not isinstance(record.belief_optimizer, str | None)
            or not isinstance(record.belief_rng, dict | None)
            or not isinstance(record.extra, dict)
        ):
            raise ValueError("model and belief_optimizer name files; belief_rng and extra are JSON objects")
        return record


def _own_file_name(name: object) -> bool:
    """Whether ``name`` is a plain file name, as a commit writes them: no folder, no way up, no hidden file."""
    return isinstance(name, str) and bool(name) and name == Path(name).name and not name.startswith(".")


# -- ring buffers as arrays ---------------------------------------------------------------------------


def replay_arrays(buffer: Any) -> dict[str, np.ndarray]:
    """The arrays of an SB3 replay buffer, each ``(rows, n_envs, ...)``, by name."""
    arrays: dict[str, np.ndarray] = {}
    for prefix, part in (("obs", buffer.observations), ("next_obs", getattr(buffer, "next_observations", None))):
        if isinstance(part, dict):
            arrays.update({f"{prefix}.{key}": value for key, value in part.items()})
        elif part is not None:
            arrays[prefix] = part
    for name in ("actions", "rewards", "dones", "timeouts"):
        arrays[name] = getattr(buffer, name)
    return arrays


def write_chunk(directory: Path, prefix: str, arrays: dict[str, np.ndarray], ring: Ring, added: int) -> Ring:
    """``ring`` after writing the rows ``[ring.added - 1, added)`` (at most the last ``capacity``) to a new file.

    The previous file's last row is written again: a learner that abandons its games marks it as an
    episode end after that file was written (:func:`pecli.models.buffers.end_episodes`)."""
    kept = [c for c in ring.chunks if c.end > added - ring.capacity]  # files with a row not yet overwritten
    if added <= ring.added:
        return Ring(ring.capacity, added, kept)
    start = max(ring.added - 1, 0, added - ring.capacity)
    name = f"{prefix}-{start:08d}-{added:08d}.npz"
    rows = np.arange(start, added) % ring.capacity
    with atomic_path(directory / name) as tmp:
        np.savez(tmp, **{key: value[rows] for key, value in arrays.items()})
    return Ring(ring.capacity, added, [*kept, Chunk(name, start, added)])


def _read_chunks(directory: Path, ring: Ring, arrays: dict[str, np.ndarray]) -> None:
    """Fill ``arrays`` (the buffer's own) from the files of ``ring``, oldest first."""
    for chunk in ring.chunks:
        rows = np.arange(chunk.start, chunk.end) % ring.capacity
        if not zipfile.is_zipfile(directory / chunk.file):
            raise ValueError(f"{chunk.file}: not a .npz archive (damaged or truncated)")
        with np.load(directory / chunk.file, allow_pickle=False) as data:
            if set(data.files) != set(arrays):
                raise ValueError(f"{chunk.file} holds {sorted(data.files)}, the buffer {sorted(arrays)}")
            for key, target in arrays.items():
                if data[key].shape != (rows.size, *target.shape[1:]):
                    raise ValueError(
                        f"{chunk.file}: {key} has shape {data[key].shape}, the buffer rows {target.shape[1:]}"
                    )
                target[rows] = data[key]


def _replay_added(buffer: Any, ring: Ring, steps_before: int, steps_now: int) -> int:
    """Rows ever added to an SB3 buffer, from the ring's count, the buffer's position and the steps since.

    SB3 adds one row per vector step, so about ``(steps_now - steps_before) / n_envs`` rows came since
    the ring's count (give or take the row of the step in progress); the position fixes the exact
    number modulo the capacity."""
    if not buffer.full:
        return int(buffer.pos)
    since = (int(buffer.pos) - ring.added) % ring.capacity
    expected = (steps_now - steps_before) / buffer.n_envs
    return ring.added + since + ring.capacity * max(0, round((expected - since) / ring.capacity))


# -- the state of one learner -----------------------------------------------------------------------


class DurableState:
    """The resumable state of one learner in ``directory`` (``<run>/<role>/resume``).

    ``fit`` arguments are the learner's belief fitting (:class:`~pecli.rl.belief.FitBelief`), ``None``
    when its belief does not learn.
    """

    def __init__(self, directory: Path) -> None:
        self.directory = directory
        self.record: Record | None = None  # the last committed, once read or saved

    # reading ---------------------------------------------------------------------------------------
    def read(self) -> Record | None:
        """The committed record, ``None`` if none was committed yet; :class:`ZooError` if it is damaged."""
        path = self.directory / RECORD
        if not path.is_file():
            return None
        try:
            data = read_json(path, "resume state")
        except PecliError as exc:
            raise ZooError(str(exc)) from None
        try:
            record = Record.from_dict(data)
        except (AttributeError, KeyError, TypeError, ValueError) as exc:
            raise ZooError(f"{path}: damaged resume state ({type(exc).__name__}: {exc})") from None
        strays = sorted(name for name in record.files() if not _own_file_name(name))
        if strays:  # a record from elsewhere must not lead pecli out of this folder
            raise ZooError(f"{path}: damaged resume state (names {strays[0]!r}, not a file of {self.directory})")
        missing = sorted(
            name
            for name in record.files()
            if (self.directory / name).is_symlink() or not (self.directory / name).is_file()
        )
        if missing:
            raise ZooError(f"{path} names files that are gone ({', '.join(missing)})")
        return record

    def restore(self, record: Record, model: Any, fit: Any = None) -> None:
        """Load the committed ``record`` (from :meth:`read`) into ``model``, built like the run's model
        (:func:`~pecli.rl.train.make_model` from the run's config), and into ``fit``."""
        from pecli.models.checkpoint import MAX_WEIGHTS_BYTES, load_tensors, restore_model

        self._collect_garbage(record)
        restore_model(model, self.directory / record.model)
        model.num_timesteps, model._n_updates = record.steps, record.n_updates
        try:
            if record.replay is not None:
                buffer = model.replay_buffer
                if record.replay.capacity != buffer.buffer_size:
                    raise ValueError(f"{record.replay.capacity} rows, the run's buffer {buffer.buffer_size}")
                _read_chunks(self.directory, record.replay, replay_arrays(buffer))
                buffer.pos = record.replay.added % buffer.buffer_size
                buffer.full = record.replay.added >= buffer.buffer_size
                end_episodes(buffer)  # the games of the newest rows are lost: returns stop there
            if fit is not None and record.belief is not None:
                pairs = fit.buffer
                if record.belief.capacity != pairs.capacity:
                    raise ValueError(f"belief buffer of {record.belief.capacity} pairs, the run's {pairs.capacity}")
                _read_chunks(self.directory, record.belief, pairs.arrays())
                pairs.set_count(record.belief.added)
                if record.belief_rng is not None:
                    pairs.rng.bit_generator.state = record.belief_rng
                if record.belief_optimizer:
                    path = self.directory / record.belief_optimizer
                    # as bytes, so that a damaged file is told apart from one of pickled objects
                    state = read_bounded(path, "belief optimiser state", MAX_WEIGHTS_BYTES)
                    fit.optimizer.load_state_dict(load_tensors(state, path))
        except ValueError as exc:
            if "allow_pickle" in str(exc):  # an object array: only unpickling could read it
                raise untrusted(self.directory, "its buffer files hold pickled objects, not plain arrays") from None
            raise ZooError(f"cannot restore {self.directory}: {exc}") from None
        except (OSError, KeyError, RuntimeError, MemoryError) as exc:  # a truncated array, another buffer size, a
            # header that claims more rows than memory holds
            raise ZooError(f"cannot restore {self.directory}: {type(exc).__name__}: {exc}") from None
        self.record = record

    # writing ---------------------------------------------------------------------------------------
    def save(
        self, model: Any, fit: Any, episodes: int, cpu_seconds: float, extra: dict[str, Any] | None = None
    ) -> Path:
        """Commit the learner's state now; returns the model file (a checkpoint to link elsewhere)."""
        self.directory.mkdir(parents=True, exist_ok=True)
        previous = self.record
        steps = int(model.num_timesteps)
        model_name = f"model-{steps:09d}.zip"
        with atomic_path(self.directory / model_name) as tmp:
            model.save(tmp)
        record = Record(
            steps=steps,
            episodes=episodes,
            n_updates=int(model._n_updates),
            cpu_seconds=round(cpu_seconds, 2),
            model=model_name,
            extra=dict(extra or {}),
        )
        buffer = getattr(model, "replay_buffer", None)
        if buffer is not None:
            ring = previous.replay if previous and previous.replay else Ring(buffer.buffer_size)
            added = _replay_added(buffer, ring, previous.steps if previous else 0, steps)
            record.replay = write_chunk(self.directory, "replay", replay_arrays(buffer), ring, added)
        if fit is not None:
            pairs = fit.buffer
            ring = previous.belief if previous and previous.belief else Ring(pairs.capacity)
            record.belief = write_chunk(self.directory, "belief", pairs.arrays(), ring, pairs.added)
            record.belief_rng = pairs.rng.bit_generator.state
            record.belief_optimizer = f"belief-optimizer-{steps:09d}.pt"
            with atomic_path(self.directory / record.belief_optimizer) as tmp:
                th.save(fit.optimizer.state_dict(), tmp)
        atomic_write_json(self.directory / RECORD, asdict(record))  # the commit
        self.record = record
        self._collect_garbage(record)
        return self.directory / model_name

    def clear(self) -> None:
        """Forget every state (a run that starts over)."""
        self.record = None
        self._collect_garbage(None)
        (self.directory / RECORD).unlink(missing_ok=True)

    def _collect_garbage(self, record: Record | None) -> None:
        """Delete what ``record`` does not name (older states, files of an interrupted save)."""
        if not self.directory.is_dir():
            return
        keep = (record.files() if record is not None else set()) | {RECORD}
        for path in self.directory.iterdir():
            if path.is_file() and path.name not in keep:
                path.unlink(missing_ok=True)
