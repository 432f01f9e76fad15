"""Checkpoints are data, not code: rebuild a checkpoint's networks from pecli's JSON and load its weights.

A checkpoint is an SB3 zip beside pecli's metadata (:class:`~pecli.zoo.CheckpointMeta`). In the zip,
``data`` is JSON in which SB3 pickles what JSON cannot hold (classes, spaces, schedules), and the
``*.pth`` entries are state dicts. Unpickling runs whatever code a file's author put there, so pecli
never deserialises ``data``: it reads the state dicts with ``torch.load(weights_only=True)`` and builds
the networks from the metadata (algorithm, policy keyword arguments, belief) and the scenario.

Checkpoints written before the metadata described the network (pecli 0.1.0 before this format) can
only be rebuilt by unpickling; that needs an explicit ``pecli --trust`` (see :mod:`pecli.trust`).
"""

from __future__ import annotations

import io
import pickle
import re
import warnings
import zipfile
from pathlib import Path
from typing import Any

import torch as th
from gymnasium import spaces
from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.policies import BasePolicy

from pecli.belief.model import features_dim
from pecli.game import Game
from pecli.game.spaces import ACTION_SPACE, observation_space
from pecli.models.algorithms import get_algorithm
from pecli.models.extractors import BeliefExtractor, belief_observation_space
from pecli.scenario import MAX_BATCH, MAX_DEPTH, MAX_WIDTH, Scenario
from pecli.trust import trusted, untrusted
from pecli.zoo import CheckpointMeta, ZooError

POLICY_ENTRY = "policy.pth"  # the network's weights in an SB3 zip; the optimisers' are beside it
MAX_WEIGHTS_BYTES = 4 << 30  # one state dict of a checkpoint, unpacked: far above any network pecli trains
MAX_CRITICS = 64
MAX_QUANTILES = 10_000
BYTES_PER_WEIGHT = 4  # float32
SMALL_NETWORK_BYTES = 16 << 20  # what building a network of any metadata may cost before its weights are checked
MAX_PACKING = 8  # how far a checkpoint's .pth may compress: SB3 stores it as is; weights barely compress


def _mlp(widths: list[int], inputs: int = 1, outputs: int = 1) -> int:
    """Weights of a multilayer perceptron of hidden ``widths`` (biases left out: a lower bound)."""
    sizes = [inputs, *widths, outputs]
    return sum(a * b for a, b in zip(sizes, sizes[1:]))


def _widths(value: Any, what: str) -> list[int]:
    if (
        not isinstance(value, list)
        or len(value) > MAX_DEPTH
        or not all(isinstance(w, int) and not isinstance(w, bool) and 1 <= w <= MAX_WIDTH for w in value)
    ):
        raise ZooError(f"its metadata's {what} is not a list of at most {MAX_DEPTH} layers of 1 to {MAX_WIDTH} units")
    return value


def least_weights(meta: CheckpointMeta) -> int:
    """A lower bound of the weights of the network ``meta`` describes (actor, critics, belief), from its numbers
    alone: checked against the file before any layer is built, so metadata cannot make pecli allocate what its
    weights do not hold. :class:`ZooError` for numbers no pecli network has."""
    kwargs = meta.policy_kwargs
    arch = kwargs.get("net_arch", [])
    actor, critic = (arch.get("pi", []), arch.get("qf", [])) if isinstance(arch, dict) else (arch, arch)
    actor, critic = _widths(actor, "net_arch"), _widths(critic, "net_arch")
    critics = kwargs.get("n_critics", 1)
    quantiles = kwargs.get("n_quantiles", 1)
    for name, value, most in (("n_critics", critics, MAX_CRITICS), ("n_quantiles", quantiles, MAX_QUANTILES)):
        if not isinstance(value, int) or isinstance(value, bool) or not 1 <= value <= most:
            raise ZooError(f"its metadata's {name} {value!r} is not a whole number from 1 to {most}")
    total = _mlp(actor) + critics * _mlp(critic, outputs=quantiles)
    belief = meta.belief_kwargs or {}
    if belief:
        for name, most in (("hidden", MAX_WIDTH), ("fc", MAX_WIDTH), ("components", 1024), ("samples", MAX_BATCH)):
            value = belief.get(name, 1)
            if not isinstance(value, int) or isinstance(value, bool) or not 1 <= value <= most:
                raise ZooError(f"its metadata's belief {name} {value!r} is not a whole number from 1 to {most}")
        total += 8 * belief.get("hidden", 1) ** 2  # the LSTM's recurrent weights, both directions, four gates
    return total


def check_weights_size(meta: CheckpointMeta, path: str | Path) -> None:
    """:class:`ZooError` unless the checkpoint's ``policy.pth`` is no larger than :data:`MAX_WEIGHTS_BYTES` and
    large enough for the network its metadata describes (read from the zip's directory, nothing unpacked)."""
    try:
        with zipfile.ZipFile(path) as archive:
            size = archive.getinfo("policy.pth").file_size
    except KeyError:
        raise ZooError(f"{path}: not a checkpoint (it has no policy weights)") from None
    except (zipfile.BadZipFile, OSError):
        raise ZooError(f"{path}: not a checkpoint (damaged or not a zip file)") from None
    try:
        least = BYTES_PER_WEIGHT * least_weights(meta)
    except ZooError as exc:
        raise ZooError(f"{path}: {exc}") from None
    if least > max(size, SMALL_NETWORK_BYTES):  # a small mismatch is named layer by layer once the weights load
        raise ZooError(
            f"{path}: its metadata describes a network of at least {least:,} bytes of weights, more "
            f"than its {size:,} bytes hold (edited or damaged metadata)"
        )


def load_tensors(source: bytes | str | Path, name: str | Path, device: str = "cpu") -> Any:
    """What ``torch.save`` wrote to ``source`` (a file, or its bytes), if it is only tensors and plain
    containers (``weights_only=True``); :class:`~pecli.trust.UntrustedFileError` for anything else, :class:`ZooError`
    for a damaged file. ``name`` names it in messages."""
    try:
        with warnings.catch_warnings():  # torch warns about pickle protocols before refusing
            warnings.simplefilter("ignore")
            return th.load(
                io.BytesIO(source) if isinstance(source, bytes) else source, map_location=device, weights_only=True
            )
    except OSError as exc:
        raise ZooError(f"{name}: cannot read: {exc.strerror or exc}") from None
    except Exception as exc:  # torch refuses anything but tensors and plain containers with UnpicklingError
        if isinstance(source, bytes) and not _pickle_or_zip(source):
            raise ZooError(f"{name}: damaged (not what torch.save writes)") from None
        if "weights_only" in str(exc) or isinstance(exc, pickle.UnpicklingError):
            raise untrusted(name, "it holds pickled objects, not just tensors") from None
        raise ZooError(f"{name}: damaged ({type(exc).__name__}: {exc})") from None


def _pickle_or_zip(data: bytes) -> bool:
    """Whether ``data`` is a zip (torch.save's format) or a whole pickle stream: its opcodes are read, none run."""
    import pickletools

    if zipfile.is_zipfile(io.BytesIO(data)):
        return True
    try:
        for _ in pickletools.genops(data):
            pass
    except Exception:  # pickletools' errors for bytes no pickle holds: ValueError, struct.error, ...
        return False
    return True


def read_weights(
    path: str | Path, device: str = "cpu", only: tuple[str, ...] | None = None
) -> tuple[dict[str, Any], dict[str, Any] | None]:
    """The state dicts (``policy``, ``actor.optimizer``, ...) and the torch variables of an SB3 zip, read
    with :func:`load_tensors`; nothing else in the zip is looked at, nor any entry but ``only`` (e.g.
    ``("policy.pth",)``) where it is given. :class:`ZooError` if it cannot."""
    params: dict[str, Any] = {}
    variables = None
    try:
        with zipfile.ZipFile(path) as archive:
            members = [
                info
                for info in archive.infolist()
                if info.filename.endswith(".pth") and (only is None or info.filename in only)
            ]
            if sum(info.file_size for info in members) > MAX_WEIGHTS_BYTES:
                raise ZooError(
                    f"{path}: its weights unpack to more than {MAX_WEIGHTS_BYTES:,} bytes: not a pecli checkpoint"
                )
            for info in members:  # a few compressed megabytes must not unpack to gigabytes
                if info.file_size > max(MAX_PACKING * info.compress_size, SMALL_NETWORK_BYTES):
                    raise ZooError(
                        f"{path}: its {info.filename} unpacks to {info.file_size:,} bytes from {info.compress_size:,}: "
                        f"weights do not compress {MAX_PACKING} times (a zip bomb, or damaged)"
                    )
            entries = {info.filename: archive.read(info) for info in members}
    except zipfile.BadZipFile:
        raise ZooError(f"{path}: not a checkpoint (damaged or not a zip file)") from None
    except OSError as exc:
        raise ZooError(f"{path}: cannot read: {exc.strerror or exc}") from None
    for name, data in entries.items():
        loaded = load_tensors(data, f"{path} ({name})", device)
        if name in ("pytorch_variables.pth", "tensors.pth"):
            variables = loaded
        else:
            params[name.removesuffix(".pth")] = loaded
    if "policy" not in params:
        raise ZooError(f"{path}: not a checkpoint (it has no policy weights)")
    if problem := _weights_problem(params["policy"]):
        raise ZooError(f"{path}: damaged policy weights ({problem})")
    return params, variables


def _weights_problem(state: Any) -> str:
    """Why ``state`` is not a network's state dict (names to dense, real, finite tensors), or ``""``."""
    if not isinstance(state, dict):
        return f"a {type(state).__name__}, not a table of named tensors"
    for name, value in state.items():
        shown = str(name)[:80]
        if not isinstance(name, str) or not isinstance(value, th.Tensor):
            return f"{shown} is not a named tensor"
        if value.layout != th.strided:
            return f"{shown} is a sparse tensor"
        if not (value.is_floating_point() or value.dtype == th.int64):  # int64: batch norm's counts
            return f"{shown} is a tensor of {str(value.dtype).removeprefix('torch.')}"
        if value.is_floating_point() and not bool(th.isfinite(value).all()):
            return f"{shown} holds NaN or infinite values"
    return ""


def spaces_of(meta: CheckpointMeta, scenario: Scenario) -> tuple[spaces.Dict, spaces.Box]:
    """The observation and action spaces a checkpoint's policy was built for, from its metadata."""
    training = scenario.training.model_copy(
        update={
            "frame_stack": meta.frame_stack,
            "history_length": meta.history_length,
            "history_stride": meta.history_stride,
        }
    )
    with_belief = meta.belief != "none"
    space = observation_space(Game(scenario, n=1), meta.role, training, history=with_belief)
    if with_belief:
        samples = (meta.belief_kwargs or {}).get("samples", scenario.training.belief_settings.samples)
        space = belief_observation_space(space, features_dim(meta.belief, samples))
    return space, ACTION_SPACE


def build_policy(meta: CheckpointMeta, scenario: Scenario, device: str = "cpu") -> BasePolicy:
    """A fresh policy of the shape ``meta`` describes (weights untrained)."""
    algorithm = get_algorithm(meta.algo)
    kwargs = dict(meta.policy_kwargs)
    if meta.belief != "none":
        if not meta.belief_kwargs:
            raise ZooError(f"metadata of a '{meta.belief}' checkpoint without its belief_kwargs")
        kwargs.update(
            features_extractor_class=BeliefExtractor, features_extractor_kwargs={"belief": meta.belief_kwargs}
        )
    observation, action = spaces_of(meta, scenario)
    try:
        return algorithm.policy(observation, action, lambda _: 0.0, **kwargs).to(device)
    except (TypeError, ValueError, KeyError) as exc:
        raise ZooError(f"its metadata describes no network pecli can build ({type(exc).__name__}: {exc})") from None


_SIZE_MISMATCH = re.compile(
    r"size mismatch for ([\w.]+): copying a param with shape torch\.Size\((\[[^\]]*\])\) "
    r"from checkpoint, the shape in current model is torch\.Size\((\[[^\]]*\])\)"
)


def _mismatch(exc: RuntimeError) -> str:
    """The first difference between weights and metadata, from torch's long ``load_state_dict`` message."""
    text = str(exc)
    if m := _SIZE_MISMATCH.search(text):
        return f"{m[1]} has shape {m[2]} in the weights but {m[3]} by the metadata"
    if m := re.search(r'(Missing key\(s\)|Unexpected key\(s\)) in state_dict: ("[^"]+")', text):
        return f"{m[1].lower()} {m[2]}"
    return text.splitlines()[0][:200]


def _old_module_names() -> None:
    """Where an older pecli kept the classes its pickled checkpoints name (``pecli.rl.policies``, ...): the same
    classes, now in :mod:`pecli.models`, so that a trusted old checkpoint still unpickles."""
    import importlib
    import sys

    for name in ("algorithms", "buffers", "extractors", "policies", "checkpoint"):
        sys.modules.setdefault(f"pecli.rl.{name}", importlib.import_module(f"pecli.models.{name}"))


def load_policy(path: str | Path, meta: CheckpointMeta, scenario: Scenario, device: str = "cpu") -> BasePolicy:
    """The policy of the checkpoint at ``path``, rebuilt from ``meta`` and its weights; unpickles nothing
    unless the checkpoint predates pecli's network metadata and the user trusts it."""
    if not meta.policy_kwargs:
        if not trusted():
            raise untrusted(
                path,
                "it was written before pecli described networks in its metadata, so only unpickling can rebuild it",
            )
        _old_module_names()
        try:
            return get_algorithm(meta.algo).cls.load(path, device=device).policy
        except Exception as exc:  # a truncated or foreign zip: SB3 raises many kinds
            raise ZooError(f"cannot load {path}: {type(exc).__name__}: {exc}") from None
    check_weights_size(meta, path)  # from the zip's directory, before anything is unpacked or built
    params, _ = read_weights(path, device, only=(POLICY_ENTRY,))  # bounded in size; refuses pickled objects
    try:
        policy = build_policy(meta, scenario, device)
    except ZooError as exc:
        raise ZooError(f"{path}: {exc}") from None
    try:
        policy.load_state_dict(params["policy"], strict=True)
    except RuntimeError as exc:
        raise ZooError(
            f"{path}: its metadata ({Path(path).with_suffix('.json').name}) does not describe its network: "
            f"{_mismatch(exc)}"
        ) from None
    policy.set_training_mode(False)
    return policy


def restore_model(model: BaseAlgorithm, path: str | Path) -> None:
    """Put the weights and optimiser states of the checkpoint at ``path`` into ``model``, a model built
    like the one that wrote it (``make_model`` from the run's config); :class:`ZooError` if they differ."""
    params, variables = read_weights(path, str(model.device))
    try:
        model.set_parameters(params, exact_match=True, device=model.device)
    except (RuntimeError, ValueError, KeyError) as exc:
        raise ZooError(
            f"{path}: does not fit the run's model: {_mismatch(exc) if isinstance(exc, RuntimeError) else exc}"
        ) from None
    for name in model._get_torch_save_params()[1]:  # e.g. SAC's log_ent_coef
        if variables and variables.get(name) is not None:
            target = model
            for part in name.split("."):
                target = getattr(target, part)
            target.data = variables[name].data.to(model.device)
