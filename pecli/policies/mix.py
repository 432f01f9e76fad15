"""``mix:A,B,...``: several players as one, each game played by one member drawn uniformly when it starts.

A member is a built-in name, a policy file (``.zip``, ``.onnx``, ``.npz``) or a self-play run's folder, which
stands for what the run hands over for the role asked (``<run>/<role>/average.zip``). So
``mix:runs/zoo/a,runs/zoo/b,runs/zoo/c`` plays the pursuers (or evaders) of three runs as one mixed strategy.

A population of independently trained players is harder to exploit than any one of them: a best response has
to beat every member with one behaviour, without knowing which it faces, and independent runs leave different
holes (docs/benchmarks/exploitability.md). This is the uniform meta-strategy over a population; ``nash:FOLDER``
(:mod:`pecli.policies.nash`) weighs the members by a meta-game instead.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING

from pecli.errors import PolicyError
from pecli.roles import ROLES, Role
from pecli.zoo import AVERAGE_FILE

if TYPE_CHECKING:
    from pecli.policies.base import Policy
    from pecli.scenario import Scenario

MAX_MEMBERS = 64


def mix_members(options: str) -> list[str]:
    """The member strings of ``mix:OPTIONS``, stripped; :class:`PolicyError` in one line for an empty or
    oversized list, a repeated member, or a member that is itself a mixture."""
    members = [part.strip() for part in options.split(",")]
    if not options.strip() or not all(members):
        raise PolicyError("mix: needs players separated by commas, e.g. mix:runs/zoo/a,runs/zoo/b,runs/zoo/c")
    if len(members) > MAX_MEMBERS:
        raise PolicyError(f"mix: takes at most {MAX_MEMBERS} players, got {len(members)}")
    for member in members:
        if member.partition(":")[0] in ("mix", "nash"):
            raise PolicyError(f"mix: {member}: a mixture does not nest another")
    if len(set(members)) != len(members):
        raise PolicyError("mix: names a player twice; give each once (the draw is uniform)")
    return members


def first_member(spec: str) -> str:
    """A policy string itself, or a mixture's first member (what names its group, what a response starts from)."""
    family, _, options = spec.strip().partition(":")
    return mix_members(options)[0] if family == "mix" else spec


def member_file(member: str, role: Role) -> Path | None:
    """The file a member plays ``role`` from: a run folder's handed-over player, or the member itself when it is
    a file; ``None`` for a name (a built-in, ``module:Class``). :class:`PolicyError` for a folder that hands over
    no player of ``role``."""
    path = Path(member)
    if path.is_dir():
        handed = path / role / AVERAGE_FILE
        if not handed.is_file():
            raise PolicyError(
                f"mix: {member} cannot play {role}: it is no self-play run that hands over one ({handed} is "
                "missing); name a checkpoint instead"
            )
        return handed
    return path if path.is_file() else None


def member_paths(options: str) -> list[Path]:
    """What the members of ``mix:OPTIONS`` name, in order: a run folder's handed-over players that are there
    (pursuer, then evader), any other member as it is written. :class:`PolicyError` for a malformed mixture."""
    paths = []
    for spec in mix_members(options):
        path = Path(spec)
        if path.is_dir():
            paths += [path / role / AVERAGE_FILE for role in ROLES if (path / role / AVERAGE_FILE).is_file()]
        else:
            paths.append(path)
    return paths


def load_mix_policy(options: str, role: Role, scenario: Scenario, member: Callable[[str], Policy]) -> Policy:
    """The ``mix:`` family: ``role``'s uniform mixture of the players in ``options``.

    ``member(spec)`` resolves one member's policy string (a built-in name, a file path, ``module:Class``).
    """
    from pecli.io import file_digest
    from pecli.policies.mixed import MixedPolicy

    specs = mix_members(options)
    files = [member_file(spec, role) for spec in specs]
    policies = [member(str(file) if file is not None else spec) for spec, file in zip(specs, files)]
    mixture = MixedPolicy(role, policies, specs)
    keys = sorted(file_digest(file) if file is not None else f"spec:{spec}" for spec, file in zip(specs, files))
    mixture.identity = "mix:" + ",".join(keys)  # what a tournament's cache knows it by: its members' content
    return mixture
