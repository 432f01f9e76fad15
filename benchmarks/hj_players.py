"""The players the Hamilton–Jacobi benchmarks share (``bench_hj_matrix.py``, ``bench_hj_ablations.py``).

"chase" is the rule the first HJ players fell back on: full acceleration along the sign of ∂V/∂r of the
default rel4d value, per axis (a lead pursuit towards the closest approach, or a flight from it).
"""

from __future__ import annotations

import sys
import time

import numpy as np

from pecli.hj import Problem, Solution, solve_cached
from pecli.match import play_match
from pecli.policies import resolve_policy
from pecli.policies.base import Policy
from pecli.policies.hj import HJPolicy
from pecli.scenario import Scenario


class GradientRule(HJPolicy):
    """The first HJ players: per axis, full input along the sign of ∂V/∂v (read where the positions
    will be after this step), and where that gradient is flat (≤ 1e-3 s on both axes) along the sign of ∂V/∂r.
    rel4d and rel6d only (their last axis per half is the relative position)."""

    name = "hj-gradient"
    chase_only = False  # True: the flat-gradient rule everywhere ("chase")

    def _act(self, view):
        opp_pos, opp_vel = self._estimate(view)
        dt = self.scenario.dt
        own_next, opp_next = view.own_pos + dt * view.own_vel, opp_pos + dt * opp_vel
        if self.role == "pursuer":
            points = self.grid.points(own_next, view.own_vel, opp_next, opp_vel)
        else:
            points = self.grid.points(opp_next, opp_vel, own_next, view.own_vel)
        half = len(self.grid.x_axes)
        goal = -1.0 if self.role == "pursuer" else 1.0  # the pursuer lowers V
        velocity_sign = -1.0 if self.grid.model == "rel4d" and self.role == "pursuer" else 1.0  # w = v_e - v_p
        position_sign = -1.0 if self.role == "pursuer" else 1.0  # r = e - p
        drive = goal * velocity_sign * self._gradient(points, self.grid.velocity_axes(self.role))
        flat = np.max(np.abs(drive), axis=1) <= 1e-3
        if self.chase_only:
            flat[:] = True
        drive[flat] = goal * position_sign * self._gradient(points[flat], (half - 1, 2 * half - 1))
        return np.sign(drive)

    def _gradient(self, points: np.ndarray, axes: tuple[int, int]) -> np.ndarray:
        """Central differences of the interpolated value along ``axes``, one node apart (one-sided at the edges)."""
        out = np.empty((points.shape[0], 2))
        points = np.clip(points, [a.low for a in self.grid.axes], [a.high for a in self.grid.axes])
        for j, k in enumerate(axes):
            axis = self.grid.axes[k]
            ahead, behind = points.copy(), points.copy()
            ahead[:, k] = np.minimum(points[:, k] + axis.spacing, axis.high)
            behind[:, k] = np.maximum(points[:, k] - axis.spacing, axis.low)
            values = self.solution.values
            out[:, j] = (self.grid.interpolate(values, ahead) - self.grid.interpolate(values, behind)) / (
                ahead[:, k] - behind[:, k]
            )
        return out


class Chase(GradientRule):
    """ "chase": the old players' fallback everywhere (needs a rel4d or rel6d solution)."""

    name = "chase"
    chase_only = True


def solution_for(
    scenario: Scenario,
    model: str,
    sizes: tuple[int, int] | None = None,
    steps: int | None = None,
) -> Solution:
    """The cached solution of that problem (solved and cached if missing)."""
    problem = Problem.for_scenario(scenario, model, sizes, steps=steps)  # type: ignore[arg-type]
    started = time.process_time()
    solution, path, reused = solve_cached(problem, scenario.name)
    if not reused:
        print(f"solved {problem.describe()} in {time.process_time() - started:.0f} CPU s: {path}", file=sys.stderr)
    return solution


def rate(scenario: Scenario, pursuer: Policy, evader: Policy, episodes: int, seed: int = 0) -> tuple[float, float]:
    """Capture rate and mean time-to-capture (a share of the horizon) of ``episodes`` games."""
    result, _ = play_match(scenario, pursuer, evader, episodes=episodes, seed=seed)
    return result.capture_rate, result.time_to_capture_mean


def make_player(spec: str, role: str, scenario: Scenario, base: Scenario, seed: int) -> Policy:
    """The player ``spec`` names; "chase" plays on ``base``'s default rel4d solution."""
    if spec == "chase":
        return Chase(scenario, role, solution_for(base, "rel4d"))
    return resolve_policy(spec, role, scenario, seed=seed)  # type: ignore[arg-type]
