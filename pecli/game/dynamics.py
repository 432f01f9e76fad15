"""Batched player dynamics: the CommonRoad kinematic single-track car (KS) and the point mass (PM).

States are stored row-wise, shape ``(rows, n)`` for ``n`` games, so that every state
variable is one contiguous row. The first ``state_dim`` rows are the model's state; a car
keeps two more rows, ``cos psi`` and ``sin psi``, so that each step evaluates the
trigonometry of the heading once. Actions arrive normalised, shape ``(n, 2)`` in [-1, 1],
and are scaled to physical inputs here. Integration is explicit Euler at the game's
``dt``; steering angle and speed are clipped to their limits after each step, and
yaw is wrapped to [-pi, pi).
"""

from __future__ import annotations

import math

import numpy as np

from pecli.scenario import CarAgent, PointMassAgent


def wrap_angle(angle: np.ndarray) -> np.ndarray:
    """Wrap angles (rad) to [-pi, pi)."""
    return (angle + math.pi) % (2.0 * math.pi) - math.pi


def wrap_near(angle: np.ndarray) -> np.ndarray:
    """Wrap angles in [-3 pi, 3 pi) to [-pi, pi), in place; cheaper than :func:`wrap_angle`."""
    angle[angle >= math.pi] -= 2.0 * math.pi
    angle[angle < -math.pi] += 2.0 * math.pi
    return angle


class CarDynamics:
    """CommonRoad KS: state (s_x, s_y, delta, v, psi), input (steering velocity, acceleration).

    Inputs pass through CommonRoad's ``steering_constraints`` and ``acceleration_constraints``:
    an input that pushes a state beyond its limit is zeroed, and acceleration above
    ``v_switch`` is capped at ``a_max * v_switch / v``.
    """

    kind = "car"
    state_dim = 5
    rows = 7  # the state, then cos(psi) and sin(psi)
    labels = ("s_x", "s_y", "delta", "v", "psi")
    has_heading = True

    def __init__(self, params: CarAgent) -> None:
        self.params = params
        self.wheelbase = params.wheelbase
        # normalisation constants of each state row (positions are set by the arena)
        self.steer_scale = params.steer_abs_max
        self.speed_max = params.speed_max

    def inputs(self, state: np.ndarray, action: np.ndarray, speed_scale: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
        """Physical inputs (steering velocity rad/s, acceleration m/s^2) after CommonRoad's constraints."""
        p = self.params
        delta, v = state[2], state[3]
        v_min, v_max = p.v_min * speed_scale, p.v_max * speed_scale
        steer_rate = np.clip(action[:, 0], -1.0, 1.0) * p.steer_rate_max
        steer_rate[((delta <= p.steer_min) & (steer_rate <= 0)) | ((delta >= p.steer_max) & (steer_rate >= 0))] = 0.0
        accel = np.clip(action[:, 1], -1.0, 1.0) * p.a_max
        if p.v_switch is not None:
            fast = v > p.v_switch
            accel = np.where(fast, np.minimum(accel, p.a_max * p.v_switch / np.where(fast, v, 1.0)), accel)
        accel[((v <= v_min) & (accel <= 0)) | ((v >= v_max) & (accel >= 0))] = 0.0
        return steer_rate, accel

    def step(self, state: np.ndarray, action: np.ndarray, dt: float, speed_scale: float = 1.0) -> np.ndarray:
        """One Euler step of ``dt`` s; returns the new ``(5, n)`` state."""
        p = self.params
        steer_rate, accel = self.inputs(state, action, speed_scale)
        x, y, delta, v, psi, cos_psi, sin_psi = state
        new = np.empty_like(state)
        v_dt = v * dt
        np.multiply(v_dt, cos_psi, out=new[0])
        new[0] += x
        np.multiply(v_dt, sin_psi, out=new[1])
        new[1] += y
        np.clip(delta + steer_rate * dt, p.steer_min, p.steer_max, out=new[2])
        np.clip(v + accel * dt, p.v_min * speed_scale, p.v_max * speed_scale, out=new[3])
        new[4] = wrap_near(psi + v_dt * np.tan(delta) / self.wheelbase)
        self.refresh(new)
        return new

    def refresh(self, state: np.ndarray) -> None:
        """Recompute the cached ``cos psi`` and ``sin psi`` rows after the heading changed."""
        np.cos(state[4], out=state[5])
        np.sin(state[4], out=state[6])

    def velocity(self, state: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """World-frame velocity (v_x, v_y), m/s."""
        return state[3] * state[5], state[3] * state[6]

    def heading(self, state: np.ndarray) -> np.ndarray:
        return state[4]

    def heading_cos_sin(self, state: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return state[5], state[6]

    def stop_at_walls(self, state: np.ndarray, half_x: float, half_y: float) -> None:
        """Clip the position to the arena in place; a car that touched a wall stops (v = 0)."""
        hit = (np.abs(state[0]) > half_x) | (np.abs(state[1]) > half_y)
        if hit.any():
            np.clip(state[0], -half_x, half_x, out=state[0])
            np.clip(state[1], -half_y, half_y, out=state[1])
            state[3, hit] = 0.0

    def scale(self, half_x: float, half_y: float) -> np.ndarray:
        """Per-row normalisation constants: the state divided by these lies in [-1, 1]."""
        return np.array([half_x, half_y, self.steer_scale, self.speed_max, math.pi])

    def from_state(self, state: np.ndarray) -> np.ndarray:
        """Internal rows ``(7, n)`` from an SI state ``(5, n)``."""
        rows = np.empty((self.rows, state.shape[1]))
        rows[:5] = state
        self.refresh(rows)
        return rows


class PointMassDynamics:
    """CommonRoad PM: state (s_x, s_y, v_x, v_y), input (a_x, a_y), limits per axis."""

    kind = "point_mass"
    state_dim = 4
    rows = 4
    labels = ("s_x", "s_y", "v_x", "v_y")
    has_heading = False

    def __init__(self, params: PointMassAgent) -> None:
        self.params = params
        self.speed_max = params.speed_max

    def inputs(self, state: np.ndarray, action: np.ndarray, speed_scale: float = 1.0) -> np.ndarray:
        """Physical accelerations ``(2, n)`` in m/s^2; an input pushing past the speed limit is zeroed."""
        v_lim = self.params.v_max * speed_scale
        accel = np.clip(action.T, -1.0, 1.0) * self.params.a_max
        vel = state[2:4]
        accel[((vel <= -v_lim) & (accel <= 0)) | ((vel >= v_lim) & (accel >= 0))] = 0.0
        return accel

    def step(self, state: np.ndarray, action: np.ndarray, dt: float, speed_scale: float = 1.0) -> np.ndarray:
        """One Euler step of ``dt`` s; returns the new ``(4, n)`` state."""
        v_lim = self.params.v_max * speed_scale
        accel = self.inputs(state, action, speed_scale)
        new = np.empty_like(state)
        new[0:2] = state[0:2] + state[2:4] * dt
        np.clip(state[2:4] + accel * dt, -v_lim, v_lim, out=new[2:4])
        return new

    def velocity(self, state: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return state[2], state[3]

    def heading(self, state: np.ndarray) -> None:
        return None

    def heading_cos_sin(self, state: np.ndarray) -> None:
        return None

    def stop_at_walls(self, state: np.ndarray, half_x: float, half_y: float) -> None:
        """Clip the position to the arena in place and drop the velocity component into the wall."""
        for axis, half in ((0, half_x), (1, half_y)):
            out = np.abs(state[axis]) > half
            if out.any():
                np.clip(state[axis], -half, half, out=state[axis])
                vel = state[2 + axis]
                vel[out & (vel * state[axis] > 0)] = 0.0

    def scale(self, half_x: float, half_y: float) -> np.ndarray:
        """Per-row normalisation constants: the state divided by these lies in [-1, 1]."""
        v = self.params.v_max
        return np.array([half_x, half_y, v, v])

    def from_state(self, state: np.ndarray) -> np.ndarray:
        """Internal rows ``(4, n)`` from an SI state ``(4, n)``."""
        return np.array(state, dtype=np.float64)


Dynamics = CarDynamics | PointMassDynamics


def make_dynamics(params: CarAgent | PointMassAgent) -> Dynamics:
    """The dynamics model for one player's parameters."""
    return CarDynamics(params) if isinstance(params, CarAgent) else PointMassDynamics(params)
