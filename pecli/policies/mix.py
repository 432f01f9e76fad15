"""``mix:A,B,...``: several players as one, each game played by one member drawn when it starts.

A member is a built-in name, a policy file (``.zip``, ``.onnx``, ``.npz``) or a self-play run's folder, which
stands for what the run hands over for the role asked (``<run>/<role>/average.zip``). So
``mix:runs/zoo/a,runs/zoo/b,runs/zoo/c`` plays the pursuers (or evaders) of three runs as one mixed strategy.
The draw is uniform unless members carry weights: ``mix:runs/zoo/a@2,runs/zoo/b,runs/zoo/c`` draws ``a`` in half
the games (a member's weight is 1 unless it ends in ``@W``; weights are normalised).

A population of independently trained players is harder to exploit than any one of them: a best response has
to beat every member with one behaviour, without knowing which it faces, and independent runs leave different
holes (docs/benchmarks/exploitability.md). Unweighted, this is the uniform meta-strategy over a population;
``nash:FOLDER`` (:mod:`pecli.policies.nash`) weighs the members by a meta-game.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING

from pecli.errors import PolicyError
from pecli.io import text_digest
from pecli.roles import ROLES, Role
from pecli.zoo import AVERAGE_FILE

if TYPE_CHECKING:
    from pecli.policies.base import Policy
    from pecli.scenario import Scenario

MAX_MEMBERS = 64
MAX_LABEL = 80  # a longer policy string is named by its size and a digest (player_label)
MIN_WEIGHT, MAX_WEIGHT = 1e-6, 1e6  # a weight a million times off 1 is a typo, not a mixture


def check_weight(weight: float, what: str) -> None:
    """:class:`PolicyError` in one line unless ``weight`` lies in [``MIN_WEIGHT``, ``MAX_WEIGHT``] (not NaN)."""
    if not MIN_WEIGHT <= weight <= MAX_WEIGHT:
        raise PolicyError(f"{what}: a weight must lie between 0.000001 and 1000000, got {weight}")


def _weighed(part: str) -> tuple[str, float]:
    """One member of ``mix:`` and its weight: ``A@W`` (``W`` a positive number) or ``A`` (weight 1). An ``@`` that
    belongs to a path (``zoo/a@b/run``, or a file or folder that is there) is no weight."""
    member, at, tail = part.strip().rpartition("@")
    if not at or "/" in tail or "\\" in tail or Path(part.strip()).exists():
        return part.strip(), 1.0
    try:
        weight = float(tail)
    except ValueError:
        raise PolicyError(f"mix: {part.strip()}: a weight after @ must be a number, e.g. runs/zoo/a@2") from None
    check_weight(weight, f"mix: {part.strip()}")
    return member.strip(), weight


def mix_weighted(options: str) -> list[tuple[str, float]]:
    """The members of ``mix:OPTIONS`` with their weights (not normalised), in order; :class:`PolicyError` in one
    line for an empty or oversized list, a bad weight, a repeated member, or a member that is itself a mixture."""
    parts = options.split(",")
    if not options.strip() or not all(part.strip() for part in parts):
        raise PolicyError("mix: needs players separated by commas, e.g. mix:runs/zoo/a,runs/zoo/b,runs/zoo/c")
    if len(parts) > MAX_MEMBERS:
        raise PolicyError(f"mix: takes at most {MAX_MEMBERS} players, got {len(parts)}")
    weighted = [_weighed(part) for part in parts]
    members = [member for member, _ in weighted]
    for member in members:
        if not member:
            raise PolicyError("mix: a weight needs its player before the @, e.g. runs/zoo/a@2")
        if member.partition(":")[0] in ("mix", "nash"):
            raise PolicyError(f"mix: {member}: a mixture does not nest another")
    if len(set(members)) != len(members):
        raise PolicyError("mix: names a player twice; give each once (weigh it with @W instead)")
    return weighted


def mix_members(options: str) -> list[str]:
    """The member strings of ``mix:OPTIONS``, stripped of their weights; :class:`PolicyError` as
    :func:`mix_weighted`."""
    return [member for member, _ in mix_weighted(options)]


def player_label(spec: str, limit: int = MAX_LABEL) -> str:
    """How a line or a table names a player: its policy string, or past ``limit`` characters a mixture by its size
    and a digest, e.g. ``mix of 22 (1f0c9a2b)``, anything else by its end (a file's name) and a digest."""
    spec = spec.strip()
    if len(spec) <= limit:
        return spec
    family, _, options = spec.partition(":")
    label = f"mix of {len(mix_members(options))}" if family == "mix" else "…" + spec[-max(limit - 13, 1) :]
    return f"{label} ({text_digest(spec, 8)})"


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
    """The ``mix:`` family: ``role``'s mixture of the players in ``options``, drawn by their weights.

    ``member(spec)`` resolves one member's policy string (a built-in name, a file path, ``module:Class``).
    """
    from pecli.io import file_digest
    from pecli.policies.mixed import MixedPolicy

    weighted = mix_weighted(options)
    specs = [spec for spec, _ in weighted]
    weights = [weight for _, weight in weighted]
    files = [member_file(spec, role) for spec in specs]
    policies = [member(str(file) if file is not None else spec) for spec, file in zip(specs, files)]
    uniform = len(set(weights)) == 1  # all alike (no @W, or the same @W everywhere): the unweighted mixture
    mixture = MixedPolicy(role, policies, specs, None if uniform else weights)
    keys = [file_digest(file) if file is not None else f"spec:{spec}" for spec, file in zip(specs, files)]
    if not uniform:  # the same members drawn otherwise are another player
        keys = [f"{key}@{weight / sum(weights):.9g}" for key, weight in zip(keys, weights)]
    mixture.identity = "mix:" + ",".join(sorted(keys))  # what a tournament's cache knows it by: its content
    return mixture
