"""The paper's heuristic baselines (section V), batched over games.

Every baseline works for a car or a point mass, in either observation frame: it reads the
decoded observation (SI, world frame) and uses the controllers of :mod:`pecli.policies.control`.
"""

from __future__ import annotations

import numpy as np

from pecli.game.observation import Decoded
from pecli.policies.base import HeuristicPolicy
from pecli.policies.control import (
    full_speed_along,
    pure_pursuit_steering,
    speed_command,
    velocity_command,
)
from pecli.scenario import CarAgent

SEARCH_STEPS = 25  # pure pursuit: steps of full-lock search after losing sight of the evader
PURSUIT_WALK_PERIOD = 8  # pure pursuit: a new random steering command every 8th step while searching
EVADER_WALK_PERIOD = 25  # random-walk evader: a new random action every 25 steps


class PurePursuit(HeuristicPolicy):
    """The paper's modified pure-pursuit pursuer.

    Drives at full forward speed. While it sees the evader it steers by pure pursuit towards
    it. When it loses sight after seeing it for at least one step, it turns at maximum steering
    velocity in a random direction for 25 steps. Otherwise (never seen, or the search is over)
    it walks randomly: a new steering velocity, uniform in [-1, 1], every 8th step.
    A point-mass pursuer runs the same logic with velocity commands instead of steering.
    """

    roles = ("pursuer",)
    name = "pure-pursuit"

    def _allocate(self, n: int) -> None:
        self.was_seen = np.zeros(n, dtype=bool)
        self.search_left = np.zeros(n, dtype=np.int64)
        self.search_command = np.zeros((n, 2))
        self.walk_command = np.zeros((n, 2))
        self.walk_clock = np.zeros(n, dtype=np.int64)

    def _restart(self, mask: np.ndarray) -> None:
        self.was_seen[mask] = False
        self.search_left[mask] = 0
        self.walk_clock[mask] = 0

    def _act(self, view: Decoded) -> np.ndarray:
        lost = self.was_seen & ~view.seen
        self.was_seen = view.seen.copy()
        self.search_left[view.seen] = 0
        if lost.any():
            self.search_left[lost] = SEARCH_STEPS
            self.search_command[lost] = self._random_turn(int(lost.sum()))
        searching = ~view.seen & (self.search_left > 0)
        self.search_left[searching] -= 1
        walking = ~view.seen & ~searching
        renew = walking & (self.walk_clock % PURSUIT_WALK_PERIOD == 0)
        if renew.any():
            self.walk_command[renew] = self._random_walk(int(renew.sum()))
        self.walk_clock[walking] += 1
        self.walk_clock[~walking] = 0

        actions = np.where(searching[:, None], self.search_command, self.walk_command)
        if isinstance(self.params, CarAgent):
            actions[:, 1] = speed_command(view, self.params.v_max, self.params, self.scenario.dt)
            chase = pure_pursuit_steering(view, view.opp_pos, self.params, self.scenario.dt)
            actions[view.seen, 0] = chase[view.seen]
        else:
            velocity = full_speed_along(view.opp_pos - view.own_pos, self.params)
            chase = velocity_command(view, velocity, self.params, self.scenario.dt)
            actions[view.seen] = chase[view.seen]
        return actions

    def _random_turn(self, count: int) -> np.ndarray:
        """Full-lock steering in a random direction (a car), or full speed along a random heading."""
        if isinstance(self.params, CarAgent):
            return np.stack([self.rng.choice([-1.0, 1.0], size=count), np.ones(count)], axis=1)
        angle = self.rng.uniform(-np.pi, np.pi, size=count)
        return np.stack([np.cos(angle), np.sin(angle)], axis=1)

    def _random_walk(self, count: int) -> np.ndarray:
        """A random steering velocity (a car; speed is set separately) or a random acceleration."""
        return self.rng.uniform(-1.0, 1.0, size=(count, 2))


class RandomWalk(HeuristicPolicy):
    """A new action, uniform in [-1, 1]^2, every 25 steps (the paper's random-walk evader)."""

    name = "random-walk"

    def _allocate(self, n: int) -> None:
        self.command = np.zeros((n, 2))
        self.clock = np.zeros(n, dtype=np.int64)

    def _restart(self, mask: np.ndarray) -> None:
        self.clock[mask] = 0

    def _act(self, view: Decoded) -> np.ndarray:
        renew = self.clock % EVADER_WALK_PERIOD == 0
        if renew.any():
            self.command[renew] = self.rng.uniform(-1.0, 1.0, size=(int(renew.sum()), 2))
        self.clock += 1
        return self.command.copy()


class Greedy(HeuristicPolicy):
    """The paper's greedy evader: flee straight away from the pursuer at full speed while it is seen, else stop."""

    roles = ("evader",)
    name = "greedy"

    def _act(self, view: Decoded) -> np.ndarray:
        away = np.where(view.seen[:, None], view.own_pos - view.opp_pos, 0.0)
        dt = self.scenario.dt
        if isinstance(self.params, CarAgent):
            steer = pure_pursuit_steering(view, view.own_pos + away, self.params, dt)
            speed = np.where(view.seen, self.params.v_max, 0.0)
            steer[~view.seen] = 0.0
            return np.stack([steer, speed_command(view, speed, self.params, dt)], axis=1)
        return velocity_command(view, full_speed_along(away, self.params), self.params, dt)


class Rash(HeuristicPolicy):
    """An approximation of the rash evader of Quattrini Li et al. (AAMAS 2018).

    The paper gives no definition and none could be found, so this is pecli's reading: the
    evader ignores the pursuer, heads at full speed to a goal drawn uniformly in the arena, and
    draws a new goal on arrival (within 0.5 m, 1 m for a car, whose turning circle may not let
    it hit the point) or after ``horizon / 4`` steps without arriving.
    """

    roles = ("evader",)
    name = "rash"

    def _allocate(self, n: int) -> None:
        self.goal = np.zeros((n, 2))
        self.goal_age = np.zeros(n, dtype=np.int64)
        self.needs_goal = np.ones(n, dtype=bool)

    def _restart(self, mask: np.ndarray) -> None:
        self.needs_goal[mask] = True

    def _act(self, view: Decoded) -> np.ndarray:
        is_car = isinstance(self.params, CarAgent)
        arrival = 1.0 if is_car else 0.5
        arrived = np.linalg.norm(self.goal - view.own_pos, axis=1) <= arrival
        stale = self.goal_age >= max(1, self.scenario.horizon // 4)
        renew = self.needs_goal | arrived | stale
        if renew.any():
            half_x, half_y = self.scenario.arena.half
            count = int(renew.sum())
            margin = 0.9  # keep goals off the walls
            self.goal[renew] = self.rng.uniform(-1.0, 1.0, size=(count, 2)) * [half_x * margin, half_y * margin]
            self.goal_age[renew] = 0
            self.needs_goal[renew] = False
        self.goal_age += 1
        dt = self.scenario.dt
        if is_car:
            steer = pure_pursuit_steering(view, self.goal, self.params, dt)
            return np.stack([steer, speed_command(view, self.params.v_max, self.params, dt)], axis=1)
        return velocity_command(view, full_speed_along(self.goal - view.own_pos, self.params), self.params, dt)
