"""The two players."""

from __future__ import annotations

from typing import Literal

Role = Literal["pursuer", "evader"]
ROLES: tuple[Role, Role] = ("pursuer", "evader")


def opponent_of(role: Role) -> Role:
    """The other player."""
    return "evader" if role == "pursuer" else "pursuer"


def check_role(role: str) -> Role:
    """Return ``role`` if it names a player, else raise ``ValueError``."""
    if role not in ROLES:
        raise ValueError(f"role must be 'pursuer' or 'evader', not {role!r}")
    return role  # type: ignore[return-value]


# the scripted opponent a role trains against, is evaluated and checked against when none is named
DEFAULT_OPPONENT: dict[Role, str] = {"pursuer": "greedy", "evader": "pure-pursuit"}
