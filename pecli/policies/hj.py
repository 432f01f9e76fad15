"""Hamilton–Jacobi players: bang-bang inputs from the gradient of a solved value function.

The value ``V`` (:mod:`pecli.hj`) is the closest approach, minus the capture distance, the pursuer
can force. Each step a player locates the current state on the solution's grid and reads the
gradient of ``V`` along its own velocity (central differences of the interpolated value, one
node apart). One step of its acceleration ``a`` changes ``V`` by about ``gradient · a dt``, so the
pursuer (which minimises) takes ``a = -a_max sign(...)`` and the evader ``+a_max sign(...)`` per axis.

Where the gradient vanishes (``|∂V/∂v| ≤ 1e-3 s`` on both axes; for example when the players
separate, so that the closest approach is now and no input changes it, or where the horizon
reaches no capture) the player uses the gradient along the relative position instead, which points
along ``r``: the pursuer accelerates towards the evader, the evader away from the pursuer. An axis
whose component is exactly zero gets no input.

The state needs the opponent's position and velocity. While the opponent is seen they come from
the observation. When it is not, the policy uses an estimate: the last sighting moved at its last
velocity (stopping at walls as the game does), or, with a belief checkpoint, the position the
belief's mixture mean gives (the paper's choice, "BiMDN weighted mean") with the last sighting's
velocity. Before the first sighting, without a belief, the estimate is the arena's centre, at rest.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from pecli.errors import ConfigError, PolicyError
from pecli.game.dynamics import PointMassDynamics
from pecli.game.observation import Decoded
from pecli.hj.cache import cache_dir, cache_path
from pecli.hj.problem import Problem
from pecli.hj.solution import Solution, SolutionError
from pecli.io import file_digest
from pecli.policies.base import HeuristicPolicy
from pecli.roles import Role, opponent_of
from pecli.scenario import Scenario

FLAT_GRADIENT = 1e-3  # s: |dV/dv| below this on both axes counts as no gradient
DEAD_BAND = 0.0  # share of the larger |dV/dv| below which an axis gets no input; a 5 % band was tried
                 # and made the HJ evader much weaker (docs/hj.md), so only an exact zero gets none


def bang_bang(drive: np.ndarray) -> np.ndarray:
    """Full input ``sign(drive)`` ``(n, 2)`` on each axis, except axes at or under :data:`DEAD_BAND` of the larger one."""
    larger = np.max(np.abs(drive), axis=1, keepdims=True)
    return np.where(np.abs(drive) > DEAD_BAND * larger, np.sign(drive), 0.0)


class HJPolicy(HeuristicPolicy):
    """Plays either role from an HJ :class:`~pecli.hj.solution.Solution`.

    Args:
        scenario: the game; the solution must have been solved for its numbers.
        role: ``"pursuer"`` or ``"evader"``.
        solution: the value function.
        belief: a learned policy of the same role with a belief (BiMDN...), run alongside for its
            estimate of the unseen opponent's position; its actions are not used.
        belief_id: what identifies the belief (its checkpoint's content hash), for :attr:`identity`.
        seed: unused (the policy is deterministic), accepted like every policy's.

    Attributes:
        identity: what decides its play (the solution's key and the belief's id), for caches of results.
    """

    name = "hj"

    def __init__(
        self,
        scenario: Scenario,
        role: Role,
        solution: Solution,
        belief: Any | None = None,
        belief_id: str = "",
        seed: int | None = None,
    ) -> None:
        super().__init__(scenario, role, seed)
        try:
            solution.check_scenario(scenario)
        except SolutionError as exc:
            raise PolicyError(str(exc)) from None
        self.solution = solution
        self.grid = solution.grid
        self.belief = belief
        self.opponent = PointMassDynamics(scenario.agent(opponent_of(role)))  # type: ignore[arg-type]
        self.half = np.array(scenario.arena.half)
        self.a_goal = -1.0 if role == "pursuer" else 1.0  # the pursuer lowers V, the evader raises it
        self.velocity_axes, self.velocity_sign = self.grid.velocity_axes(role)
        self.position_sign = -1.0 if role == "pursuer" else 1.0  # r = e - p
        self.identity = f"hj:{solution.key}" + (f":belief:{belief_id}" if belief is not None else "")

    # ------------------------------------------------------------------ memory
    def _allocate(self, n: int) -> None:
        self.opp_state = np.zeros((4, n))  # the estimate: (s_x, s_y, v_x, v_y) rows, SI

    def _restart(self, mask: np.ndarray) -> None:
        self.opp_state[:, mask] = 0.0  # the arena's centre, at rest, until the first sighting

    def reset(self, n: int, mask: np.ndarray | None = None, seed: int | None = None) -> None:
        super().reset(n, mask, seed)
        if self.belief is not None:
            self.belief.reset(n, mask, seed)

    def act(self, obs: np.ndarray) -> np.ndarray:
        obs = np.asarray(obs)
        if self.belief is not None and obs.ndim == 2 and obs.shape[1] == self.codec.dim:
            if obs.shape[0] != self.n:
                self.reset(obs.shape[0])
            self.belief.act(obs)  # keeps the belief's history window; the action is not used
        return super().act(obs)

    # ------------------------------------------------------------------ acting
    def _act(self, view: Decoded) -> np.ndarray:
        opp_pos, opp_vel = self._estimate(view)
        # The input changes the velocity after this step's move: V(r, w) = opt V(r + w dt, w + dw), so the
        # value's velocity gradient is read where the positions will be after the move.
        dt = self.scenario.dt
        own_next, opp_next = view.own_pos + dt * view.own_vel, opp_pos + dt * opp_vel
        if self.role == "pursuer":
            points = self.grid.points(own_next, view.own_vel, opp_next, opp_vel)
        else:
            points = self.grid.points(opp_next, opp_vel, own_next, view.own_vel)
        return self.inputs(points)

    def inputs(self, points: np.ndarray) -> np.ndarray:
        """Normalised accelerations ``(n, 2)`` in {-1, 0, 1} at grid coordinates ``points`` ``(n, d)``."""
        axes = (*self.velocity_axes, *self.grid.position_axes())
        gradient = self.grid.gradient(self.solution.values, points, axes)
        drive = self.a_goal * self.velocity_sign * gradient[:, :2]
        flat = np.max(np.abs(drive), axis=1) <= FLAT_GRADIENT
        drive[flat] = self.a_goal * self.position_sign * gradient[flat, 2:]
        return bang_bang(drive)

    def _estimate(self, view: Decoded) -> tuple[np.ndarray, np.ndarray]:
        """The opponent's position and velocity ``(n, 2)`` each: observed, or estimated where unseen."""
        state = self.opp_state
        seen = view.seen
        unseen = ~seen
        if unseen.any():  # move the estimate one step at its velocity; walls stop it as in the game
            moved = self.opponent.step(state, np.zeros((state.shape[1], 2)), self.scenario.dt)
            self.opponent.stop_at_walls(moved, *self.half)
            state[:, unseen] = moved[:, unseen]
        state[0:2, seen] = view.opp_pos[seen].T
        state[2:4, seen] = view.opp_vel[seen].T
        position = state[0:2].T.copy()
        if self.belief is not None and unseen.any():
            position[unseen] = self._belief_mean()[unseen]
        return position, state[2:4].T.copy()

    def _belief_mean(self) -> np.ndarray:
        """The belief's mixture mean ``(n, 2)`` in metres (world frame)."""
        weights, means, _ = self.belief.current_belief()
        return np.sum(weights[..., None] * means, axis=1) * self.half

    def __repr__(self) -> str:
        return f"HJPolicy(role={self.role!r}, {self.solution.problem.describe()})"


# ---------------------------------------------------------------------- policy strings
def parse_options(text: str) -> dict[str, str]:
    """``"FILE.npz"``, ``"model=rel6d"``, ``"belief=CKPT.zip"`` or several joined by commas → a dict.

    A bare item is the solution file. Keys: ``solution``, ``model``, ``belief``.
    """
    options: dict[str, str] = {}
    for item in filter(None, (part.strip() for part in text.split(","))):
        key, sep, value = item.partition("=")
        key, value = (key.strip(), value.strip()) if sep else ("solution", item)
        if key not in ("solution", "model", "belief"):
            raise PolicyError(f"unknown hj option '{key}' (known: solution, model, belief)")
        if not value:
            raise PolicyError(f"hj option '{key}' needs a value")
        options[key] = value
    return options


def load_hj_policy(options: str, role: Role, scenario: Scenario, seed: int | None = None) -> HJPolicy:
    """The HJ policy for ``role`` from a policy string's options (the part after ``hj:``; may be empty).

    Without a solution file it uses the cached solution of the scenario's default problem for
    ``model`` (default ``rel4d``), and says how to make it if there is none.
    """
    settings = parse_options(options)
    if "solution" in settings:
        path = Path(settings["solution"])
        try:
            solution = Solution.load(path)
        except SolutionError as exc:
            raise PolicyError(str(exc)) from None
    else:
        model = settings.get("model", "rel4d")
        try:
            problem = Problem.for_scenario(scenario, model)  # type: ignore[arg-type]
        except ConfigError as exc:  # a scenario without two point masses
            raise PolicyError(str(exc)) from None
        path = cache_path(problem)
        try:
            solution = Solution.load(path)
        except SolutionError:
            flag = "" if model == "rel4d" else f" --model {model}"
            raise PolicyError(
                f"no HJ solution for scenario '{scenario.name}' ({problem.describe()}) in {cache_dir()}: "
                f"run `pecli hj solve --config <this scenario>{flag}` first, or give a file: hj:FILE.npz"
            ) from None
    if "belief" not in settings:
        return HJPolicy(scenario, role, solution, seed=seed)
    belief = _belief_policy(settings["belief"], role, scenario)
    return HJPolicy(scenario, role, solution, belief=belief, belief_id=file_digest(settings["belief"]), seed=seed)


def _belief_policy(path: str, role: Role, scenario: Scenario) -> Any:
    """A learned checkpoint of ``role`` with a belief, loaded for its belief."""
    from pecli.policies.learned import LearnedPolicy  # torch loads only when a belief is asked for

    policy = LearnedPolicy.load(path, role, scenario)
    if policy.meta.belief == "none":
        raise PolicyError(f"{path} has no belief (it was trained with --belief none): it cannot estimate the opponent")
    return policy
