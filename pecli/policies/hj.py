"""Hamilton–Jacobi players: each step, the input whose outcomes the solved value function rates best.

A solution (:mod:`pecli.hj`) rates every state with a **score**
(:meth:`~pecli.hj.solution.Solution.scores`): the fewest steps in which the pursuer forces a
capture, or, where it cannot within the solution's horizon, the horizon plus one plus the closest
approach (m) it can force. Each step a player plays the game's own step
(:class:`~pecli.game.dynamics.PointMassDynamics`, walls included) for its nine inputs
``{-1, 0, 1}²`` against the opponent's nine, reads the score of each of the 81 outcomes (an outcome
that is a capture scores -1), and rates each of its inputs over the opponent's nine: the pursuer by
the average (it takes the lowest), the evader by the best outcome the pursuer's inputs leave it
(it takes the highest: the value already assumes the pursuer's best play from the next state on),
where the value knows the walls (``abs8d``); with a relative model, whose value leads it into walls
it does not know, the evader averages too. Ratings within :data:`TIE` of the best are ties, which
the average distance one step after the outcome decides: the pursuer closes in, the evader draws
away. That is also the whole rule where the score is flat, for example where the value cannot tell
the inputs apart in the open plane of a relative model. Where some input forces a capture within
:data:`FORCE_STEPS` steps whatever the evader does (its worst outcome over the evader's nine inputs
says so), the pursuer rates every input by its worst outcome instead of the average, and so takes
the forcing one: near the capture set an average lets the evader's one escaping input through.

The state needs the opponent's position and velocity. While the opponent is seen they come from
the observation. When it is not, the policy uses an estimate: the last sighting moved at its last
velocity (stopping at walls as the game does), or, with a belief checkpoint, the position the
belief's mixture mean gives (the paper's choice, "BiMDN weighted mean") with the last sighting's
velocity. Before the first sighting, without a belief, the estimate is the arena's centre, at rest.
An estimate within the player's own sensing range is moved out to the range's edge (the player
would see the opponent there). The value is that of the full-information game, so it rates
outcomes only while both players see each other; otherwise (an estimate, or an opponent that
cannot see this player) only the distance decides. See ``docs/hj.md`` for the measurements
behind each rule.
"""

from __future__ import annotations

import functools
from pathlib import Path
from typing import Any

import numpy as np

from pecli.errors import ConfigError, PolicyError
from pecli.game.dynamics import PointMassDynamics
from pecli.game.observation import Decoded
from pecli.hj.cache import cache_dir, cache_path
from pecli.hj.grid import DEFAULT_MODEL
from pecli.hj.problem import Problem
from pecli.hj.solution import Solution, SolutionError
from pecli.io import file_digest
from pecli.policies.base import HeuristicPolicy
from pecli.roles import Role, opponent_of
from pecli.scenario import Scenario

LEVELS = np.array([-1.0, 0.0, 1.0])  # normalised input per axis; the candidates are their 3 x 3 pairs
INPUTS = np.array([(x, y) for x in LEVELS for y in LEVELS])  # (9, 2), row 3 i + j = (LEVELS[i], LEVELS[j])
TIE = 1e-3  # score differences below this are ties (steps, or m of closest approach)
CAPTURED = -1.0  # the score of an outcome that is a capture: better than any state
FORCE_STEPS = 10.0  # where the worst case forces a capture within this many steps, the pursuer plays it
RULES = 3  # the players' rule, in their identity: results cached under an older rule are not reused


def _pair_norm(gap: np.ndarray) -> np.ndarray:
    """``(n, px, ex, py, ey)`` distances from per-axis gaps ``(3 pursuer inputs, 3 evader inputs, 2 axes, n)``."""
    return np.hypot(
        gap[:, :, 0].transpose(2, 0, 1)[:, :, :, None, None], gap[:, :, 1].transpose(2, 0, 1)[:, None, None]
    )


def choose(scores: np.ndarray, distances: np.ndarray) -> np.ndarray:
    """Per game, the candidate ``(n,)`` with the lowest score ``(n, k)``; scores within :data:`TIE` of the lowest
    are ties, and the lowest distance ``(n, k)`` among them wins."""
    tied = scores <= scores.min(axis=1, keepdims=True) + TIE
    return np.argmin(np.where(tied, distances, np.inf), axis=1)


def pursuer_choice(
    scores: np.ndarray, distances: np.ndarray, mutual: np.ndarray, force: float = FORCE_STEPS
) -> np.ndarray:
    """The pursuer's input ``(n,)`` from the scores and distances ``(n, 9 own, 9 evader inputs)``: the best
    average over the evader's inputs, or, in a game of ``mutual`` sight where some input's score is at most
    ``force`` (a capture within that many steps) against every evader input, the best worst case."""
    worst = scores.max(axis=2)
    forced = mutual & (worst.min(axis=1) <= force)
    return choose(np.where(forced[:, None], worst, scores.mean(axis=2)), distances.mean(axis=2))


def evader_choice(scores: np.ndarray, distances: np.ndarray, *, best: bool) -> np.ndarray:
    """The evader's input ``(n,)`` from the scores and distances ``(n, 9 pursuer, 9 own inputs)``: the highest
    best outcome over the pursuer's inputs (``best``) or the highest average; the largest average distance
    among ties."""
    rating = scores.max(axis=1) if best else scores.mean(axis=1)
    return choose(-rating, -distances.mean(axis=1))


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

    Variants (the benchmarks' ablations) subclass it and override its steps, as Stable-Baselines3's
    callbacks override ``_on_step``: :meth:`_act` (the whole decision), :meth:`_estimate` (where the unseen
    opponent is), :meth:`_out_of_sight` (what the player's own sensor rules out) and :meth:`_evader_choice`
    (how the evader rates outcomes). A variant gives itself another class ``name``: it begins its
    :attr:`identity`, so that results cached for the built-in rules are not taken for the variant's.
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
        self.scores = solution.scores()
        # a score at most this is a forced capture: capture steps within the solution's horizon, or, for a
        # solution scored by its value alone (no capture steps), a state in the capture set
        self.force = min(FORCE_STEPS, solution.problem.steps) if solution.capture_steps is not None else 0.0
        self.best = self.grid.model == "abs8d"  # the evader rates by the best outcome where the value knows walls
        self.belief = belief
        self.dynamics = {r: PointMassDynamics(scenario.agent(r)) for r in ("pursuer", "evader")}  # type: ignore[arg-type]
        self.opponent = self.dynamics[opponent_of(role)]
        self.half = np.array(scenario.arena.half)
        belief_part = f":belief:{belief_id}" if belief is not None else ""
        self.identity = f"{self.name}:{solution.key}:rules{RULES}{belief_part}"

    # ------------------------------------------------------------------ memory
    def _allocate(self, n: int) -> None:
        self.opp_state = np.zeros((4, n))  # the estimate: (s_x, s_y, v_x, v_y) rows, SI

    def _restart(self, mask: np.ndarray) -> None:
        self.opp_state[:, mask] = 0.0  # the arena's centre, at rest, until the first sighting

    def reset(self, n: int, mask: np.ndarray | None = None, seed: int | None = None) -> None:
        super().reset(n, mask, seed)
        if self.belief is not None:
            self.belief.reset(n, mask, seed)

    def end(self, mask: np.ndarray) -> None:
        """The games in ``mask`` have ended: a belief's network skips them (the policy itself is cheap)."""
        if self.belief is not None:
            self.belief.end(mask)

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
        own = np.concatenate([view.own_pos, view.own_vel], axis=1).T  # (4, n) rows s_x, s_y, v_x, v_y
        opp = np.concatenate([opp_pos, opp_vel], axis=1).T
        pursuer, evader = (own, opp) if self.role == "pursuer" else (opp, own)
        scores, distances = self.outcomes(pursuer, evader)
        mutual = self._mutual(view)
        scores[~mutual] = 0.0  # only the distance decides (see the module)
        if self.role == "pursuer":  # own inputs on axis 1, the opponent's on axis 2
            return INPUTS[pursuer_choice(scores, distances, mutual, self.force)]
        return INPUTS[self._evader_choice(scores, distances)]

    def _evader_choice(self, scores: np.ndarray, distances: np.ndarray) -> np.ndarray:
        """The evader's input index ``(n,)`` from the outcomes ``(n, 9 pursuer, 9 own inputs)``."""
        return evader_choice(scores, distances, best=self.best)

    def outcomes(self, pursuer: np.ndarray, evader: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Scores after one step and distances (m) one step later still, ``(n, 9, 9)`` each: pursuer input ×
        evader input (rows of :data:`INPUTS`), from both players' states ``(4, n)`` (s_x, s_y, v_x, v_y; SI).

        The distance is taken a step after the outcome, at the velocities the inputs gave, because
        the positions after one step follow from the current velocities alone: it tells how an
        input opens or closes the gap, which breaks ties of the score.

        A point mass moves along x and y independently, so three steps per player (the inputs
        ``(u, u)``, ``u`` in :data:`LEVELS`) give every outcome, and its x half depends only on the
        two players' x inputs: the 81 outcomes are the 9 × 9 pairings of 9 x halves with 9 y halves.
        """
        n, dt, half = pursuer.shape[1], self.scenario.dt, len(self.grid.x_axes)
        moved = {}
        for role, state in (("pursuer", pursuer), ("evader", evader)):
            dynamics = self.dynamics[role]
            steps = [dynamics.step(state, np.full((n, 2), u), dt) for u in LEVELS]
            for step in steps:
                dynamics.stop_at_walls(step, *self.half)
            moved[role] = np.stack(steps)  # (3, 4, n)
        p, e = moved["pursuer"][:, None], moved["evader"][None, :]  # (3 pursuer, 3 evader, 4, n)
        points = self.grid.points(
            *(
                np.broadcast_to(rows, (3, 3, 2, n)).transpose(0, 1, 3, 2).reshape(-1, 2)
                for rows in (p[:, :, 0:2], p[:, :, 2:4], e[:, :, 0:2], e[:, :, 2:4])
            )
        )
        points = points.reshape(3, 3, n, -1).transpose(2, 0, 1, 3).reshape(n, 9, -1)  # (n, 3 i + j, d)
        scores = self.grid.interpolate_pairs(self.scores, points[:, :, :half], points[:, :, half:])
        gap = e[:, :, 0:2] - p[:, :, 0:2]  # (3, 3, 2, n): per axis, depends on that axis's inputs only
        ahead = gap + (e[:, :, 2:4] - p[:, :, 2:4]) * dt  # one more step at the new velocities
        scores = scores.reshape(n, 3, 3, 3, 3)
        scores[_pair_norm(gap) <= self.scenario.capture_distance] = CAPTURED
        order = (0, 1, 3, 2, 4)  # (n, px, py, ex, ey): pursuer input 3 px + py, evader input 3 ex + ey
        return scores.transpose(order).reshape(n, 9, 9), _pair_norm(ahead).transpose(order).reshape(n, 9, 9)

    def _mutual(self, view: Decoded) -> np.ndarray:
        """``(n,)`` bool: the games in which both players see each other, the full-information game the value solves.

        This player's sensor says whether it sees the opponent; the opponent's (a disk, the opponent
        being a point mass) whether it can see this player, from the seen opponent's distance.
        Where this player sees nothing the state is an estimate; where only this player sees, the
        opponent plays blind. Either way the value's assumption fails and only the distance decides.
        """
        gap = view.opp_pos - view.own_pos
        in_range = np.hypot(gap[:, 0], gap[:, 1]) <= self.opponent.params.sensor.range + 1e-3  # float32 slack
        return view.seen & in_range

    def _estimate(self, view: Decoded) -> tuple[np.ndarray, np.ndarray]:
        """The opponent's position and velocity ``(n, 2)`` each: observed, or estimated where unseen."""
        state = self.opp_state
        seen = view.seen
        unseen = ~seen
        if unseen.any():  # move the estimate one step at its velocity; walls stop it as in the game
            moved = self.opponent.step(state, np.zeros((state.shape[1], 2)), self.scenario.dt)
            self.opponent.stop_at_walls(moved, *self.half)
            state[:, unseen] = moved[:, unseen]
            state[0:2, unseen] = self._out_of_sight(view, state[0:2].T)[unseen].T
        state[0:2, seen] = view.opp_pos[seen].T
        state[2:4, seen] = view.opp_vel[seen].T
        position = state[0:2].T.copy()
        if self.belief is not None and unseen.any():
            position[unseen] = self._out_of_sight(view, self._belief_mean())[unseen]
        return position, state[2:4].T.copy()

    def _out_of_sight(self, view: Decoded, estimate: np.ndarray) -> np.ndarray:
        """``estimate`` ``(n, 2)`` where the player's own sensor allows an unseen opponent to be.

        An estimate within sensing range of a player that sees nothing is wrong, so it moves out
        along the line from the player to the range's edge (along the player's velocity, or +x,
        when it sits on the player), and into the arena. Chasing it sweeps the pursuer onwards.
        """
        offset = estimate - view.own_pos
        distance = np.hypot(offset[:, 0], offset[:, 1])
        inside = distance < self.params.sensor.range
        if not inside.any():
            return estimate
        speed = np.hypot(view.own_vel[:, 0], view.own_vel[:, 1])
        fallback = np.where(speed[:, None] > 1e-6, view.own_vel, [1.0, 0.0])
        direction = np.where(distance[:, None] > 1e-6, offset, fallback)
        direction /= np.hypot(direction[:, 0], direction[:, 1])[:, None]
        edge = np.clip(view.own_pos + self.params.sensor.range * direction, -self.half, self.half)
        return np.where(inside[:, None], edge, estimate)

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
    ``model`` (default ``abs8d``), and says how to make it if there is none.
    """
    settings = parse_options(options)
    if "solution" in settings:
        path = Path(settings["solution"])
        try:
            solution = _load(path)
        except SolutionError as exc:
            raise PolicyError(str(exc)) from None
    else:
        model = settings.get("model", DEFAULT_MODEL)
        try:
            problem = Problem.for_scenario(scenario, model)  # type: ignore[arg-type]
        except ConfigError as exc:  # a scenario without two point masses
            raise PolicyError(str(exc)) from None
        path = cache_path(problem)
        flag = "" if model == DEFAULT_MODEL else f" --model {model}"
        if not path.is_file():
            raise PolicyError(
                f"no HJ solution for scenario '{scenario.name}' ({problem.describe()}) in {cache_dir()}: "
                f"run `pecli hj solve --config <this scenario>{flag}` first, or give a file: hj:FILE.npz"
            )
        try:
            solution = _load(path)
        except SolutionError as exc:  # a damaged file; solving again replaces it
            raise PolicyError(f"{exc} (`pecli hj solve --config <this scenario>{flag}` does)") from None
    if "belief" not in settings:
        return HJPolicy(scenario, role, solution, seed=seed)
    belief = _belief_policy(settings["belief"], role, scenario)
    return HJPolicy(scenario, role, solution, belief=belief, belief_id=file_digest(settings["belief"]), seed=seed)


def _load(path: Path) -> Solution:
    """:meth:`Solution.load`, kept for the next call while the file is unchanged: a tournament's or a match's
    two HJ players share one copy of the (large) arrays."""
    stat = path.stat() if path.is_file() else None
    return _load_once(path.resolve(), stat.st_mtime_ns if stat else 0, stat.st_size if stat else 0)


@functools.lru_cache(maxsize=2)
def _load_once(path: Path, mtime_ns: int, size: int) -> Solution:
    return Solution.load(path)


def _belief_policy(path: str, role: Role, scenario: Scenario) -> Any:
    """A learned checkpoint of ``role`` with a belief, loaded for its belief."""
    from pecli.policies.learned import (
        LearnedPolicy,  # torch loads only when a belief is asked for
    )

    policy = LearnedPolicy.load(path, role, scenario)
    if policy.meta.belief == "none":
        raise PolicyError(f"{path} has no belief (it was trained with --belief none): it cannot estimate the opponent")
    return policy
