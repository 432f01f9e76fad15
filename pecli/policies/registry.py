"""Turn a policy string into a :class:`Policy`.

A policy string is one of:

* a built-in name: the paper's ``pure-pursuit`` (pursuer), ``greedy``, ``rash`` (evaders), ``random-walk``
  (either); pecli's adversaries ``interceptor`` (pursuer), ``circler``, ``blindside``, ``wall-runner``,
  ``hider``, ``corner-sitter`` (evaders, :mod:`pecli.policies.adversarial`);
* a family with options, ``NAME`` or ``NAME:OPTIONS``: ``hj`` (either role; ``hj:FILE.npz``,
  ``hj:model=rel6d``, ``hj:FILE.npz,belief=CHECKPOINT.zip``, see :mod:`pecli.policies.hj`), ``nash``
  (``nash:FOLDER``: the Nash mixture of a zoo that ``pecli tournament --nash`` wrote, see
  :mod:`pecli.policies.nash`), ``mix`` (``mix:A,B@2,C``: players or self-play runs as one mixture, see
  :mod:`pecli.policies.mix`);
* ``package.module:ClassName``, a user's class implementing :class:`Policy`; its constructor may
  take any of the keyword arguments ``scenario``, ``role`` and ``seed``;
* a file path, loaded by the loader registered for its suffix: ``.zip`` checkpoints, ``.onnx``
  exported models (``pecli export onnx``), ``.npz`` HJ solutions (``pecli hj solve``).
"""

from __future__ import annotations

import importlib
import inspect
import os
from collections.abc import Callable
from pathlib import Path

from pecli.errors import PecliError, PolicyError
from pecli.io import path_inside
from pecli.policies.adversarial import (
    Blindside,
    Circler,
    CornerSitter,
    Hider,
    Interceptor,
    WallRunner,
)
from pecli.policies.base import HeuristicPolicy, Policy
from pecli.policies.heuristics import Greedy, PurePursuit, RandomWalk, Rash
from pecli.roles import Role
from pecli.scenario import Scenario

BUILTINS: dict[str, type[HeuristicPolicy]] = {
    cls.name: cls
    for cls in (PurePursuit, Greedy, RandomWalk, Rash, Interceptor, Circler, Blindside, WallRunner, Hider, CornerSitter)
}
PAPER_BASELINES = ("pure-pursuit", "greedy", "random-walk", "rash")  # the rest are pecli's adversaries

Loader = Callable[[Path, Role, Scenario, "int | None"], Policy]


def _load_checkpoint(path: Path, role: Role, scenario: Scenario, seed: int | None) -> Policy:
    from pecli.policies.learned import (
        LearnedPolicy,  # torch and SB3 load only when a checkpoint is asked for
    )

    return LearnedPolicy.load(path, role, scenario, seed)


def _load_exported(path: Path, role: Role, scenario: Scenario, seed: int | None) -> Policy:
    from pecli.policies.exported import (
        ExportedPolicy,  # onnxruntime loads only when an export is asked for
    )

    return ExportedPolicy.load(path, role, scenario, seed)


def _load_hj(options: str, role: Role, scenario: Scenario, seed: int | None) -> Policy:
    from pecli.policies.hj import (
        load_hj_policy,  # the HJ solver's modules load only when asked for
    )

    return load_hj_policy(options, role, scenario, seed)


def _load_hj_file(path: Path, role: Role, scenario: Scenario, seed: int | None) -> Policy:
    return _load_hj(f"solution={path}", role, scenario, seed)


def _load_nash(options: str, role: Role, scenario: Scenario, seed: int | None) -> Policy:
    from pecli.policies.nash import (
        load_nash_policy,  # a zoo's Nash mixture (pecli tournament --nash)
    )

    def member(spec: str, folder: Path) -> Policy:
        return resolve_policy(_mixture_member(spec, folder), role, scenario, seed=seed)

    return load_nash_policy(options, role, scenario, member)


def _mixture_member(spec: str, folder: Path) -> str:
    """A mixture member's policy string (``nash:``, ``mix:``), a relative file read from ``folder``; refuses what
    a data file may not name."""
    from pecli.trust import trusted

    if spec in BUILTINS:
        return spec
    if family_of(spec) in ("nash", "mix"):
        raise PolicyError(f"{spec}: a mixture does not nest another")
    if family_of(spec) is not None:  # hj: an HJ player, whose solution is read as data
        return spec
    path = Path(spec)
    if path.suffix.lower() in _LOADERS:
        member = path if path.is_absolute() else folder / path
        if not member.is_file():  # else resolve_policy would take 'module:x.zip' for code to import
            raise PolicyError(f"the mixture names the policy file {spec}, which is not there")
        return str(member)
    if ":" not in spec:  # a misspelt name or a missing file, not code
        if "/" in spec or os.sep in spec:
            raise PolicyError(f"the mixture names {spec}, which is not there")
        raise PolicyError(
            f"the mixture names '{spec}', which is neither a built-in ({', '.join(builtin_names())}) nor a policy file"
        )
    if not trusted():
        raise PolicyError(
            f"the mixture names '{spec}', which is neither a built-in nor a policy file: pecli imports "
            "no code a mixture or a file names unless you pass `pecli --trust`"
        )
    return spec


def _load_mix(options: str, role: Role, scenario: Scenario, seed: int | None) -> Policy:
    from pecli.policies.mix import load_mix_policy  # several players as one

    def member(spec: str) -> Policy:
        return resolve_policy(_mixture_member(spec, Path()), role, scenario, seed=seed)

    return load_mix_policy(options, role, scenario, member)


_LOADERS: dict[str, Loader] = {".zip": _load_checkpoint, ".onnx": _load_exported, ".npz": _load_hj_file}

Family = Callable[[str, Role, Scenario, "int | None"], Policy]
_FAMILIES: dict[str, Family] = {"hj": _load_hj, "nash": _load_nash, "mix": _load_mix}


def register_loader(suffix: str, loader: Loader) -> None:
    """Load files ending in ``suffix`` (e.g. ``".zip"``) with ``loader(path, role, scenario, seed)``."""
    _LOADERS[suffix.lower()] = loader


def register_family(name: str, factory: Family) -> None:
    """Resolve ``name`` and ``name:OPTIONS`` with ``factory(options, role, scenario, seed)`` (options may be "")."""
    _FAMILIES[name] = factory


def family_of(spec: str) -> str | None:
    """The family a policy string names (``"hj"`` for ``hj`` and ``hj:...``), or ``None``."""
    name = spec.strip().partition(":")[0]
    return name if name in _FAMILIES else None


def builtin_names(role: Role | None = None, paper_only: bool = False) -> list[str]:
    """Names of the built-in policies, those that can play ``role`` if given, the paper's only if asked."""
    return [
        name
        for name, cls in BUILTINS.items()
        if (role is None or role in cls.roles) and (not paper_only or name in PAPER_BASELINES)
    ]


def resolve_policy(spec: str, role: Role, scenario: Scenario, seed: int | None = None) -> Policy:
    """The policy named by ``spec``, playing ``role`` in ``scenario``; :class:`PolicyError` if it cannot."""
    spec = spec.strip()
    if spec in BUILTINS:
        cls = BUILTINS[spec]
        if role not in cls.roles:
            plays = " or ".join(cls.roles)
            raise PolicyError(f"'{spec}' plays {plays}, not {role} (for {role}: {', '.join(builtin_names(role))})")
        return cls(scenario, role, seed=seed)
    if (family := family_of(spec)) is not None:
        return _FAMILIES[family](spec.partition(":")[2], role, scenario, seed)
    path = Path(spec)
    if path.is_dir():
        raise PolicyError(f"{spec} is a folder: give a checkpoint in it, such as {path / role / 'final.zip'}")
    if path.exists():
        return _load_file(path, role, scenario, seed)
    if ":" in spec:
        return _load_class(spec, role, scenario, seed)
    if path.suffix:
        raise PolicyError(f"policy file not found: {spec}")
    raise PolicyError(
        f"unknown policy '{spec}' for {role}: use one of {', '.join(builtin_names(role) + sorted(_FAMILIES))}, "
        "a file, or module:Class"
    )


def recorded_policy(spec: str, inside: Path | None, source: str) -> str:
    """A policy string that a file records (``run.json``, ``selfplay.json``, a study), checked before anything
    resolves it: a zoo from a stranger is data. Built-in names and families play; a policy file only when it lies
    inside ``inside`` (links resolved; ``None``: anywhere, read as data); ``module:Class``, which imports code, only
    with ``--trust``. Anything else is :class:`PolicyError` naming ``source`` and what to do instead."""
    from pecli.trust import trusted

    spec = spec.strip()
    if family_of(spec) == "mix":  # each member as if the record named it (a run folder: its handed-over files)
        from pecli.policies.mix import member_paths

        for member in member_paths(spec.partition(":")[2]):
            recorded_policy(str(member), inside, source)
        return spec
    if spec in BUILTINS or family_of(spec) is not None:
        return spec
    path = Path(spec)
    if path.suffix.lower() in _LOADERS:
        if not path.is_file():  # else resolve_policy would take 'module:x.zip' for code to import
            raise PolicyError(f"{source} names the policy file {spec}, which is not there")
        if inside is None:
            return spec
        if path_inside(path, inside):
            return spec
        raise PolicyError(
            f"{source} names the policy file {spec}, outside {inside}: pecli follows no path a record "
            "names out of its folder; name the opponent yourself (--opponent) to use it"
        )
    if ":" in spec and trusted():
        return spec
    raise PolicyError(
        f"{source} names the policy '{spec}', neither a built-in nor a policy file: pecli imports "
        "no code a file names unless you pass `pecli --trust`"
    )


def stored_scenario(spec: str) -> Scenario | None:
    """The scenario a policy file records, if it records one readably: an export's sidecar, or a
    checkpoint's run ``config.yaml`` (``<run>/<role>/<name>.zip``) when its game is the one the
    checkpoint learned. ``None`` otherwise: loading the file then reports what is wrong with it."""
    if family_of(spec) == "mix":  # the first member that records one
        from pecli.policies.mix import member_paths

        try:
            paths = member_paths(spec.strip().partition(":")[2])
        except PolicyError:
            return None
        return next((found for path in paths if (found := stored_scenario(str(path))) is not None), None)
    path = Path(spec.strip())
    suffix = path.suffix.lower()
    try:
        if suffix == ".onnx" and path.is_file():
            from pecli.policies.exported import exported_scenario
            from pecli.runtime import read_sidecar, sidecar_path

            return exported_scenario(read_sidecar(path), source=str(sidecar_path(path)))
        if suffix == ".zip" and path.is_file():
            from pecli.zoo import read_metadata, run_of

            if (run := run_of(path)) is None:
                return None
            scenario = run.scenario()
            return scenario if scenario.fingerprint() == read_metadata(path).scenario_hash else None
    except PecliError:
        return None
    return None


def _load_file(path: Path, role: Role, scenario: Scenario, seed: int | None) -> Policy:
    if not path.is_file():  # a FIFO would block its reader, a device never end
        raise PolicyError(f"cannot load {path}: not a regular file")
    loader = _LOADERS.get(path.suffix.lower())
    if loader is None:
        kinds = ", ".join(sorted(_LOADERS)) or "none yet"
        raise PolicyError(f"cannot load {path}: no policy loader for '{path.suffix}' files (known: {kinds})")
    return loader(path, role, scenario, seed)


def _load_class(spec: str, role: Role, scenario: Scenario, seed: int | None) -> Policy:
    module_name, _, class_name = spec.partition(":")
    try:
        module = importlib.import_module(module_name)
    except ImportError as exc:
        raise PolicyError(f"cannot import module '{module_name}' for policy '{spec}': {exc}") from None
    cls = getattr(module, class_name, None)
    if cls is None or not callable(cls):
        raise PolicyError(f"module '{module_name}' has no class '{class_name}'")
    offered = {"scenario": scenario, "role": role, "seed": seed}
    try:
        params = inspect.signature(cls).parameters
        accepts_any = any(p.kind is inspect.Parameter.VAR_KEYWORD for p in params.values())
        kwargs = {k: v for k, v in offered.items() if accepts_any or k in params}
        policy = cls(**kwargs)
    except (TypeError, ValueError) as exc:
        raise PolicyError(f"cannot create '{spec}': {exc}") from None
    if not isinstance(policy, Policy):
        raise PolicyError(f"'{spec}' is not a Policy: it needs a 'role' attribute and reset() and act() methods")
    if policy.role != role:
        raise PolicyError(f"'{spec}' plays {policy.role}, not {role}")
    return policy
