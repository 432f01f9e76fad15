"""Parity: an exported model against the checkpoint it came from, over recorded games.

The checkpoint plays ``episodes`` games (one batch) against a heuristic opponent; every
observation it saw and every action it took is recorded. The exported model then replays the
same observations from the same seed (so a mixed belief draws the same numbers) and the largest
differences of the actions, and of the SI commands, are reported.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from pecli.game import Game
from pecli.match import policy_seeds
from pecli.policies.base import Policy
from pecli.policies.exported import ExportedPolicy
from pecli.policies.registry import resolve_policy
from pecli.roles import DEFAULT_OPPONENT, ROLES, opponent_of
from pecli.scenario import Scenario

TOLERANCE = 1e-5  # the largest action difference an export may show


@dataclass(frozen=True)
class ParityReport:
    """The largest differences between an export and its checkpoint over recorded games."""

    episodes: int
    steps: int  # game steps replayed (the longest episode)
    decisions: int  # (game, step) pairs at which both decided
    opponent: str
    seed: int
    max_action_difference: float  # in [-1, 1] action units, over the actions both gave as finite numbers
    max_command_difference: float  # in the command's units (rad/s, m/s^2), likewise
    tolerance: float = TOLERANCE
    non_finite: int = 0  # (game, step) pairs where either side's action or the export's command was NaN or inf

    @property
    def passed(self) -> bool:
        return self.non_finite == 0 and self.max_action_difference <= self.tolerance

    def failure(self) -> str:
        """Why the check failed, in words (empty when it passed)."""
        if self.non_finite:
            return f"{self.non_finite} actions or commands were NaN or infinite"
        if not self.passed:
            return f"actions differ by up to {self.max_action_difference:.3g} (tolerance {self.tolerance:g})"
        return ""

    def to_dict(self) -> dict[str, float | int | str | bool]:
        return {**asdict(self), "passed": self.passed}


def record_games(
    scenario: Scenario, player: Policy, opponent: Policy, episodes: int, seed: int
) -> tuple[list[np.ndarray], list[np.ndarray]]:
    """Play ``player`` against ``opponent`` as :func:`pecli.match.play_match` does; returns the player's
    observations ``(episodes, dim)`` and actions ``(episodes, 2)``, one pair per step."""
    game = Game(scenario, n=episodes, seed=seed)
    obs = game.reset(seed=seed)
    seeds = dict(zip(ROLES, policy_seeds(seed)))
    role, other = player.role, opponent_of(player.role)
    player.reset(episodes, seed=seeds[role])
    opponent.reset(episodes, seed=seeds[other])
    observations, actions = [], []
    for _ in range(scenario.horizon):
        observations.append(obs[role].copy())
        actions.append(player.act(obs[role]))
        moves = {role: actions[-1], other: opponent.act(obs[other])}
        obs = game.step(moves["pursuer"], moves["evader"]).obs
        if game.finished.all():
            break
    return observations, actions


def check_parity(
    exported: ExportedPolicy,
    checkpoint: Policy,
    scenario: Scenario,
    episodes: int = 8,
    seed: int = 0,
    opponent: str | None = None,
) -> ParityReport:
    """Record ``checkpoint``'s games against ``opponent`` (a policy string;
    default :data:`~pecli.roles.DEFAULT_OPPONENT`) and replay them through ``exported``."""
    opponent = opponent or DEFAULT_OPPONENT[checkpoint.role]
    other = resolve_policy(opponent, opponent_of(checkpoint.role), scenario)
    observations, actions = record_games(scenario, checkpoint, other, episodes, seed)
    exported.reset(episodes, seed=dict(zip(ROLES, policy_seeds(seed)))[exported.role])
    limits = exported.model.limits
    action_gap = command_gap = 0.0
    decisions = non_finite = 0
    for step, (obs, action) in enumerate(zip(observations, actions)):
        played = exported.act(obs)
        # compare finite numbers only: NaN - NaN is NaN, and max(0.0, NaN) is 0.0, a silent pass
        finite = np.isfinite(played).all(1) & np.isfinite(action).all(1) & np.isfinite(exported.command).all(1)
        non_finite += int((~finite).sum())
        if finite.any():
            action_gap = max(action_gap, float(np.abs(played - action)[finite].max()))
            command_gap = max(command_gap, float(np.abs(exported.command - action * limits)[finite].max()))
        decisions += episodes if step % exported.frame_skip == 0 else 0
    return ParityReport(
        episodes=episodes,
        steps=len(observations),
        decisions=decisions,
        opponent=opponent,
        seed=seed,
        max_action_difference=action_gap,
        max_command_difference=command_gap,
        non_finite=non_finite,
    )
