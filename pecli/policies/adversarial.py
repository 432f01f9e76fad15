"""pecli's own adversarial scripted players: evaders that exploit a car's weaknesses, and a pursuer trick.

The paper's baselines (greedy, rash, random-walk) flee or wander; a car-like pursuer that beats them
can still lose to an evader that uses what a car cannot do. These players are this project's, not the
paper's; they are opponents in training and rows in the benchmarks (docs/adversaries.md).

* ``circler`` (evader): a car cannot get closer than its turning radius to the centre of the circle
  it is turning on. Close to the car (1.2 m) the circler goes to the centre of the car's turning
  circle on its own side and stays there as the car moves; farther away it flees like greedy.
* ``blindside`` (evader): the car's wedge sensor is blind behind it. Near the car the blindside evader
  steps out of the wedge sideways and follows the car from behind; seen from afar, it leaves the wedge
  and waits.
* ``wall-runner`` (evader): a car that touches a wall stops dead, and corners force it to slow down and
  turn. The wall-runner runs to the wall and, while the pursuer is near, runs around the arena along
  the walls, away from it.
* ``hider`` (evader): the car sees only a wedge ahead and must find what it cannot see. Whenever it
  sees the pursuer, the hider picks a hiding spot (of a grid 1 m inside the walls) far from the
  pursuer and behind its heading, reached by a path that stays out of the pursuer's sight, goes there
  and keeps still; a pursuer within 2 m makes it flee like greedy.
* ``corner-sitter`` (evader): a corner is the last place a car's wedge reaches, and a car that drives into
  one is stuck against two walls. The corner-sitter keeps still in a corner (one at random, or the one
  farthest from the pursuer if it sees it at the start); a pursuer seen within 3 m makes it step out of
  the car's wedge sideways, past it, and run for the corner farthest from it. The learned evaders of
  ``strength-small`` found this on their own (docs/adversaries.md).
* ``interceptor`` (pursuer): aims where the evader will be (lead pursuit on the evader's seen
  velocity), goes to where a lost evader should be by now, and otherwise sweeps the arena along a
  fixed tour instead of walking randomly.

Against a point-mass pursuer (no turning circle, no blind side) the circler and the blindside flee
like the greedy evader; the hider still hides (a point mass's sensor is a disk, so "behind it" is no
better than elsewhere) and the corner-sitter runs for the far corner without stepping aside. Every
player reads only its own observation, like every other policy.
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

LOST_STEPS = 30  # interceptor: steps it drives to where a lost evader should be before sweeping


class _Evader(HeuristicPolicy):
    """What the adversarial evaders share: the pursuer's heading remembered per game, and moving a
    point-mass or car evader towards a point or along a direction."""

    roles = ("evader",)

    def _allocate(self, n: int) -> None:
        self.heading = np.zeros((n, 2))  # the pursuer's last known heading, unit vectors; zero: unknown

    def _restart(self, mask: np.ndarray) -> None:
        self.heading[mask] = 0.0

    @property
    def pursuer_is_car(self) -> bool:
        return isinstance(self.scenario.pursuer, CarAgent)

    def _pursuer_heading(self, view: Decoded) -> np.ndarray:
        """The seen pursuer's heading ``(n, 2)``: its direction of motion when it moves, else the last known
        one. A motion nearly opposite to the known heading is a car reversing, not turning about."""
        speed = np.linalg.norm(view.opp_vel, axis=1)
        moving = view.seen & (speed > 0.2)
        direction = np.divide(view.opp_vel, speed[:, None], out=np.zeros_like(view.opp_vel), where=speed[:, None] > 0)
        known = np.any(self.heading != 0.0, axis=1)
        reversing = known & (np.einsum("ij,ij->i", direction, self.heading) < -0.5)
        update = moving & ~reversing
        self.heading[update] = direction[update]
        return self.heading

    @staticmethod
    def _flee(view: Decoded) -> np.ndarray:
        """Straight away from the pursuer, as the greedy evader flees."""
        return view.own_pos - view.opp_pos

    def _go(self, view: Decoded, target: np.ndarray, carry: np.ndarray | None = None, gain: float = 3.0) -> np.ndarray:
        """Actions that bring the evader to ``target`` ``(n, 2)``, moving with ``carry`` (m/s) once there."""
        if isinstance(self.params, CarAgent):
            steer = pure_pursuit_steering(view, target, self.params, self.scenario.dt)
            speed = np.clip(gain * np.linalg.norm(target - view.own_pos, axis=1), 0.0, self.params.v_max)
            return np.stack([steer, speed_command(view, speed, self.params, self.scenario.dt)], axis=1)
        wanted = gain * (target - view.own_pos) + (0.0 if carry is None else carry)
        wanted = np.clip(wanted, -self.params.v_max, self.params.v_max)
        return velocity_command(view, wanted, self.params, self.scenario.dt)

    def _wedge_exit(self, view: Decoded, heading: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Whether the evader is inside the car's wedge (with a margin of 20 degrees), ``(n,)``, and the way out of
        it ``(n, 2)``: sideways, to the side it is on, and a little back."""
        rel = view.own_pos - view.opp_pos
        bearing_cos = np.einsum("ij,ij->i", heading, rel) / np.maximum(np.linalg.norm(rel, axis=1), 1e-9)
        inside = bearing_cos >= np.cos(0.5 * self.scenario.pursuer.sensor.fov + 0.35)
        left = np.stack([-heading[:, 1], heading[:, 0]], axis=1)
        side = np.where(np.einsum("ij,ij->i", left, rel) >= 0, 1.0, -1.0)
        return inside, side[:, None] * left - 0.5 * heading

    def _run(self, view: Decoded, direction: np.ndarray) -> np.ndarray:
        """Actions at full speed along ``direction`` ``(n, 2)``; standing still where it is zero."""
        if isinstance(self.params, CarAgent):
            target = view.own_pos + direction
            steer = pure_pursuit_steering(view, target, self.params, self.scenario.dt)
            moving = np.any(direction != 0.0, axis=1)
            return np.stack(
                [
                    np.where(moving, steer, 0.0),
                    speed_command(view, np.where(moving, self.params.v_max, 0.0), self.params, self.scenario.dt),
                ],
                axis=1,
            )
        return velocity_command(view, full_speed_along(direction, self.params), self.params, self.scenario.dt)


class Circler(_Evader):
    """Near the car, sits at the centre of the car's turning circle on its own side (see the module)."""

    name = "circler"
    engage = 1.2  # m: nearer than this it goes for the turning circle; farther, it flees like greedy

    def _act(self, view: Decoded) -> np.ndarray:
        actions = self._run(view, np.where(view.seen[:, None], self._flee(view), 0.0))
        if not self.pursuer_is_car:
            return actions
        heading = self._pursuer_heading(view)
        car = self.scenario.pursuer
        radius = car.wheelbase / np.tan(car.steer_abs_max)
        rel = view.own_pos - view.opp_pos
        left = np.stack([-heading[:, 1], heading[:, 0]], axis=1)
        side = np.where(np.einsum("ij,ij->i", left, rel) >= 0, 1.0, -1.0)
        centre = view.opp_pos + side[:, None] * radius * left
        near = view.seen & (np.linalg.norm(rel, axis=1) < self.engage) & np.any(heading != 0.0, axis=1)
        orbit = self._go(view, centre, carry=view.opp_vel)
        actions[near] = orbit[near]
        return actions


class Blindside(_Evader):
    """Stays out of the car's field of view, behind it (see the module)."""

    name = "blindside"
    behind = 1.8  # m behind the car where it follows
    engage = 3.5  # m: nearer than this it follows the car; farther, out of the wedge, it waits

    def _act(self, view: Decoded) -> np.ndarray:
        actions = self._run(view, np.where(view.seen[:, None], self._flee(view), 0.0))
        if not self.pursuer_is_car:
            return actions
        heading = self._pursuer_heading(view)
        rel = view.own_pos - view.opp_pos
        distance = np.linalg.norm(rel, axis=1)
        inside, sidestep = self._wedge_exit(view, heading)
        follow = self._go(view, view.opp_pos - self.behind * heading, carry=view.opp_vel)
        leave = self._run(view, sidestep)
        known = view.seen & np.any(heading != 0.0, axis=1)
        near = distance < self.engage
        actions[known & inside] = leave[known & inside]
        actions[known & ~inside & near] = follow[known & ~inside & near]
        wait = known & ~inside & ~near
        actions[wait] = self._run(view, np.zeros_like(rel))[wait]
        return actions


class WallRunner(_Evader):
    """Runs to the wall, then around the arena along the walls, away from a near pursuer (see the module)."""

    name = "wall-runner"
    margin = 0.3  # m from the walls
    look_ahead = 1.0  # m along the wall
    chased = 5.0  # m: a pursuer nearer than this makes it run

    def _act(self, view: Decoded) -> np.ndarray:
        hx, hy = (h - self.margin for h in self.scenario.arena.half)
        perimeter = 4.0 * (hx + hy)
        own = self._arc(view.own_pos, hx, hy)
        there = self._point(own, hx, hy)
        at_wall = np.linalg.norm(there - view.own_pos, axis=1) < 0.3
        chased = view.seen & (np.linalg.norm(view.own_pos - view.opp_pos, axis=1) < self.chased)
        ahead = (self._arc(view.opp_pos, hx, hy) - own) % perimeter < 0.5 * perimeter  # pursuer ahead anticlockwise
        step = np.where(ahead, -self.look_ahead, self.look_ahead)
        target = np.where((at_wall & chased)[:, None], self._point(own + step, hx, hy), there)
        run = self._run(view, target - view.own_pos)
        settle = self._go(view, there)
        return np.where((at_wall & ~chased)[:, None], settle, run)

    @staticmethod
    def _arc(position: np.ndarray, hx: float, hy: float) -> np.ndarray:
        """Anticlockwise arc length ``(n,)`` from (hx, -hy) of the perimeter point nearest to ``position``."""
        x, y = np.clip(position[:, 0], -hx, hx), np.clip(position[:, 1], -hy, hy)
        gaps = np.stack([hx - x, hy - y, x + hx, y + hy], axis=1)  # right, top, left, bottom
        wall = np.argmin(gaps, axis=1)
        offsets = np.array([0.0, 2 * hy, 2 * hy + 2 * hx, 4 * hy + 2 * hx])
        along = np.choose(wall, [y + hy, hx - x, hy - y, x + hx])
        return offsets[wall] + along

    @staticmethod
    def _point(arc: np.ndarray, hx: float, hy: float) -> np.ndarray:
        """The perimeter point ``(n, 2)`` at anticlockwise arc length ``arc`` from (hx, -hy)."""
        s = arc % (4.0 * (hx + hy))
        right, top, left = 2 * hy, 2 * hy + 2 * hx, 4 * hy + 2 * hx
        x = np.select(
            [s < right, s < top, s < left],
            [np.full_like(s, hx), hx - (s - right), np.full_like(s, -hx)],
            -hx + (s - left),
        )
        y = np.select(
            [s < right, s < top, s < left], [-hy + s, np.full_like(s, hy), hy - (s - top)], np.full_like(s, -hy)
        )
        return np.stack([x, y], axis=1)


class Hider(_Evader):
    """Hides from the pursuer: far from it, behind it, out of its sight, and still (see the module)."""

    name = "hider"
    margin = 1.0  # m from the walls of the hiding spots
    grid = 5  # hiding spots per side: a 5 x 5 grid
    danger = 2.0  # m: a seen pursuer nearer than this makes it flee like greedy
    clearance = 3.0  # m: its path to a spot keeps at least this far from the pursuer
    behind_weight = 3.0  # m of distance a spot right behind the pursuer is worth
    path_points = 8  # points of the straight path to a spot that are checked against the pursuer's sight
    sight_weight = 10.0  # sensor ranges of distance a path wholly in the pursuer's sight costs

    def _allocate(self, n: int) -> None:
        super()._allocate(n)
        hx, hy = (h - self.margin for h in self.scenario.arena.half)
        xs, ys = np.meshgrid(np.linspace(-hx, hx, self.grid), np.linspace(-hy, hy, self.grid))
        self.spots = np.stack([xs.ravel(), ys.ravel()], axis=1)  # (k, 2)
        self.spot = np.full((n, 2), np.nan)  # the hiding spot it goes to, per game; NaN: none yet, keep still

    def _restart(self, mask: np.ndarray) -> None:
        super()._restart(mask)
        self.spot[mask] = np.nan

    def _act(self, view: Decoded) -> np.ndarray:
        heading = self._pursuer_heading(view)
        seen = view.seen
        if seen.any():
            self.spot[seen] = self._choose(view.own_pos[seen], view.opp_pos[seen], heading[seen])
        target = np.where(np.isnan(self.spot), view.own_pos, self.spot)
        actions = self._go(view, target)
        near = seen & (np.linalg.norm(view.own_pos - view.opp_pos, axis=1) < self.danger)
        actions[near] = self._run(view, self._flee(view))[near]
        return actions

    def _choose(self, own: np.ndarray, pursuer: np.ndarray, heading: np.ndarray) -> np.ndarray:
        """The best hiding spot ``(m, 2)`` for ``m`` games: far from the pursuer, behind its ``heading`` (zero:
        unknown), and reached by a path the pursuer does not see (it is taken to stay where it is)."""
        rel = self.spots[None] - pursuer[:, None]  # (m, k, 2)
        distance = np.linalg.norm(rel, axis=2)
        ahead = np.einsum("mj,mkj->mk", heading, rel) / np.maximum(distance, 1e-9)  # cos bearing; 0 if unknown
        fractions = np.linspace(1.0 / self.path_points, 1.0, self.path_points)
        path = own[:, None, None] + fractions[None, None, :, None] * (self.spots[None, :, None] - own[:, None, None])
        offset = path - pursuer[:, None, None]  # (m, k, points, 2)
        gap = np.linalg.norm(offset, axis=3)
        sensor = self.scenario.pursuer.sensor
        known = np.any(heading != 0.0, axis=1)[:, None, None]
        in_wedge = np.einsum("mj,mkpj->mkp", heading, offset) >= np.cos(0.5 * sensor.fov) * gap
        sighted = (gap <= sensor.range) & (in_wedge | ~known) | (gap < self.clearance)
        score = distance + self.behind_weight * (1.0 - ahead) - self.sight_weight * sensor.range * sighted.mean(axis=2)
        return self.spots[np.argmax(score, axis=1)]


class CornerSitter(_Evader):
    """Keeps still in a corner; steps past a car that comes for it and runs for the farthest corner (see the module)."""

    name = "corner-sitter"
    alert = 3.0  # m: a seen pursuer nearer than this makes it leave for the corner farthest from it

    def _allocate(self, n: int) -> None:
        super()._allocate(n)
        hx, hy = self.scenario.arena.half
        self.corners = np.array([[hx, hy], [-hx, hy], [-hx, -hy], [hx, -hy]])
        self.corner = np.full((n, 2), np.nan)  # the corner it goes to or sits in, per game; NaN: a new game

    def _restart(self, mask: np.ndarray) -> None:
        super()._restart(mask)
        self.corner[mask] = np.nan

    def _act(self, view: Decoded) -> np.ndarray:
        heading = self._pursuer_heading(view)
        distance = np.linalg.norm(view.own_pos - view.opp_pos, axis=1)
        fresh = np.isnan(self.corner[:, 0])
        blind = fresh & ~view.seen
        self.corner[blind] = self.corners[self.rng.integers(len(self.corners), size=int(blind.sum()))]
        leave = view.seen & (fresh | (distance < self.alert))
        farthest = np.argmax(np.linalg.norm(self.corners[None] - view.opp_pos[:, None], axis=2), axis=1)
        self.corner[leave] = self.corners[farthest[leave]]
        actions = self._go(view, self.corner)
        if self.pursuer_is_car:
            inside, sidestep = self._wedge_exit(view, heading)
            dodge = leave & inside
            actions[dodge] = self._run(view, sidestep)[dodge]
        return actions


class Interceptor(HeuristicPolicy):
    """Lead pursuit on the evader's seen velocity; dead reckoning when it is lost; a sweep of the arena
    when it was never seen or the trail is cold (see the module)."""

    roles = ("pursuer",)
    name = "interceptor"
    horizon = 2.0  # s: the furthest ahead it leads a target

    def _allocate(self, n: int) -> None:
        self.last_pos = np.zeros((n, 2))
        self.last_vel = np.zeros((n, 2))
        self.since_seen = np.full(n, LOST_STEPS, dtype=np.int64)
        self.waypoint = np.zeros(n, dtype=np.int64)
        hx, hy = (0.6 * h for h in self.scenario.arena.half)
        self.tour = np.array([[-hx, -hy], [hx, -hy], [hx, 0.0], [-hx, 0.0], [-hx, hy], [hx, hy], [0.0, 0.0]])

    def _restart(self, mask: np.ndarray) -> None:
        self.since_seen[mask] = LOST_STEPS
        self.waypoint[mask] = self.rng.integers(0, len(self.tour), size=int(mask.sum()))

    def _act(self, view: Decoded) -> np.ndarray:
        seen = view.seen
        self.last_pos[seen], self.last_vel[seen] = view.opp_pos[seen], view.opp_vel[seen]
        self.since_seen = np.where(seen, 0, self.since_seen + 1)
        speed = self.params.v_max
        rel = self.last_pos - view.own_pos
        lead = np.minimum(self._time_to_meet(rel, self.last_vel, speed), self.horizon)
        elapsed = self.since_seen * self.scenario.dt
        target = self.last_pos + self.last_vel * (lead + np.minimum(elapsed, self.horizon))[:, None]
        half = np.array(self.scenario.arena.half)
        target = np.clip(target, -half, half)
        trail = self.since_seen < LOST_STEPS
        sweep = self.tour[self.waypoint]
        arrived = ~trail & (np.linalg.norm(sweep - view.own_pos, axis=1) < 1.0)
        self.waypoint[arrived] = (self.waypoint[arrived] + 1) % len(self.tour)
        target = np.where(trail[:, None], target, self.tour[self.waypoint])
        dt = self.scenario.dt
        if isinstance(self.params, CarAgent):
            steer = pure_pursuit_steering(view, target, self.params, dt)
            return np.stack([steer, speed_command(view, self.params.v_max, self.params, dt)], axis=1)
        return velocity_command(view, full_speed_along(target - view.own_pos, self.params), self.params, dt)

    @staticmethod
    def _time_to_meet(rel: np.ndarray, velocity: np.ndarray, speed: float) -> np.ndarray:
        """Smallest ``t >= 0`` with ``|rel + velocity t| = speed t`` (``(n,)``, s); ``|rel| / speed`` if none."""
        a = np.einsum("ij,ij->i", velocity, velocity) - speed**2
        b = 2.0 * np.einsum("ij,ij->i", rel, velocity)
        c = np.einsum("ij,ij->i", rel, rel)
        fallback = np.sqrt(c) / speed
        disc = b * b - 4 * a * c
        with np.errstate(invalid="ignore", divide="ignore"):
            roots = np.stack([(-b - np.sqrt(disc)) / (2 * a), (-b + np.sqrt(disc)) / (2 * a)], axis=1)
        roots = np.where((roots >= 0) & np.isfinite(roots), roots, np.inf).min(axis=1)
        return np.where(np.isfinite(roots) & (np.abs(a) > 1e-9), roots, fallback)
