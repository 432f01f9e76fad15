"""Everything that acts: the :class:`Policy` interface, the paper's heuristics, HJ players, and name resolution."""

from pecli.policies.base import HeuristicPolicy, Policy
from pecli.policies.heuristics import Greedy, PurePursuit, RandomWalk, Rash
from pecli.policies.registry import (
    BUILTINS,
    builtin_names,
    register_family,
    register_loader,
    resolve_policy,
    stored_scenario,
)

__all__ = [
    "BUILTINS",
    "Greedy",
    "HeuristicPolicy",
    "Policy",
    "PurePursuit",
    "RandomWalk",
    "Rash",
    "builtin_names",
    "register_family",
    "register_loader",
    "resolve_policy",
    "stored_scenario",
]
