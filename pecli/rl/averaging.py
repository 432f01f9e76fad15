"""Average the weights of checkpoints along one learner's lineage (stochastic weight averaging, Izmailov et al.
2018, over self-play rounds).

A self-play learner's checkpoints of consecutive rounds are points along one training trajectory, and its
policy moves a lot from one round to the next against the players it does not train against
(docs/benchmarks/strength.md, "Averaging the last rounds"). The mean of the last rounds' weights plays more
robustly than any one of them at no training cost. Only checkpoints of one network (same role, algorithm,
belief, game and observation layout) average; the result is a checkpoint like any other: the newest input's file
with its policy weights replaced by the mean, and metadata that names what was averaged.
"""

from __future__ import annotations

import io
import shutil
import zipfile
from dataclasses import replace
from datetime import UTC, datetime
from pathlib import Path

import torch as th

from pecli.io import atomic_path, atomic_write_json
from pecli.models.checkpoint import MAX_WEIGHTS_BYTES, POLICY_ENTRY, read_weights
from pecli.zoo import CheckpointMeta, ZooError, metadata_path, read_metadata

SAME_NETWORK = (
    "role",
    "algo",
    "belief",
    "scenario_hash",
    "frame_skip",
    "frame_stack",
    "history_length",
    "history_stride",
    "policy_kwargs",
    "belief_kwargs",
)  # metadata that must agree to average


def _network(meta: CheckpointMeta, name: str) -> object:
    """What ``meta`` says of the network under ``name``; the belief's arguments without the scenario they carry
    (its game is ``scenario_hash``; its training settings, which pecli extends over versions, build no layer)."""
    if name == "belief_kwargs":
        return {key: value for key, value in (meta.belief_kwargs or {}).items() if key != "scenario"}
    return getattr(meta, name)


def mean_state(states: list[dict[str, th.Tensor]]) -> dict[str, th.Tensor]:
    """The key-wise mean of state dicts of one network; integer entries (counters) are the last one's."""
    keys = list(states[-1])
    if any(list(state) != keys for state in states):
        raise ZooError("their networks have different parameters")
    for key in keys:
        if any(state[key].shape != states[-1][key].shape for state in states):
            raise ZooError(f"their networks' {key[:80]} differ in shape")
    return {
        key: (
            th.stack([state[key].double() for state in states]).mean(0).to(states[-1][key].dtype)
            if states[-1][key].is_floating_point()
            else states[-1][key]
        )
        for key in keys
    }


def average_checkpoints(paths: list[Path], out: Path) -> CheckpointMeta:
    """Write to ``out`` the checkpoint whose policy weights are the mean of those of ``paths`` (the newest last);
    :class:`ZooError` if they are not checkpoints of one network. Returns its metadata."""
    if not paths:
        raise ZooError("no checkpoint to average")
    metas = [read_metadata(path) for path in paths]
    newest = metas[-1]
    for path, meta in zip(paths, metas):
        for name in SAME_NETWORK:
            if _network(meta, name) != _network(newest, name):
                raise ZooError(
                    f"{path}: its {name} differs from {paths[-1]}'s: only checkpoints of one network average"
                )
    states = [read_weights(path, only=(POLICY_ENTRY,))[0]["policy"] for path in paths]  # each error names its file
    try:
        policy = mean_state(states)
    except ZooError as exc:
        raise ZooError(f"{', '.join(map(str, paths))}: {exc}") from None
    buffer = io.BytesIO()
    th.save(policy, buffer)
    with (
        atomic_path(out) as tmp,
        zipfile.ZipFile(paths[-1]) as source,
        zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED) as target,
    ):
        if sum(item.file_size for item in source.infolist()) > MAX_WEIGHTS_BYTES:  # what is copied, unpacked
            raise ZooError(f"{paths[-1]}: unpacks to more than {MAX_WEIGHTS_BYTES:,} bytes: not a pecli checkpoint")
        for item in source.infolist():
            if item.filename == POLICY_ENTRY:
                target.writestr(item, buffer.getvalue())
                continue
            try:
                with source.open(item) as entry, target.open(item, "w") as copy:  # streamed: the rest as it is
                    shutil.copyfileobj(entry, copy)
            except (zipfile.BadZipFile, RuntimeError, NotImplementedError) as exc:  # bad CRC, encrypted, unknown
                raise ZooError(f"{paths[-1]}: damaged entry '{item.filename[:100]}' ({exc})") from None
    meta = replace(
        newest, averaged=[str(path) for path in paths], created=datetime.now(UTC).isoformat(timespec="seconds")
    )
    atomic_write_json(metadata_path(out), meta.to_dict())
    return meta
