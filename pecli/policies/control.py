"""Low-level controllers the heuristics share: steer a car, drive a point mass at a velocity.

Each returns normalised commands in [-1, 1] for a batch of games, from SI quantities.
"""

from __future__ import annotations

import numpy as np

from pecli.game.observation import Decoded
from pecli.scenario import CarAgent, PointMassAgent


def pure_pursuit_steering(view: Decoded, target: np.ndarray, car: CarAgent, dt: float) -> np.ndarray:
    """Normalised steering velocity ``(n,)`` that turns the wheels towards the pure-pursuit angle.

    Pure pursuit (Coulter 1992): with the target at ``(x, y)`` in the body frame and look-ahead
    ``L = |(x, y)|``, the arc through it has curvature ``2y / L^2`` and needs the steering angle
    ``atan(wheelbase * 2y / L^2)``. A target behind the car asks for full lock towards its side.
    """
    rel = target - view.own_pos
    c, s = np.cos(view.own_heading), np.sin(view.own_heading)
    x = c * rel[:, 0] + s * rel[:, 1]
    y = c * rel[:, 1] - s * rel[:, 0]
    look_ahead_sq = np.maximum(x * x + y * y, 1e-9)
    wanted = np.arctan(car.wheelbase * 2.0 * y / look_ahead_sq)
    behind = x < 0
    wanted[behind] = np.where(y[behind] >= 0, car.steer_max, car.steer_min)
    wanted = np.clip(wanted, car.steer_min, car.steer_max)
    return np.clip((wanted - view.own_steer) / (dt * car.steer_rate_max), -1.0, 1.0)


def speed_command(view: Decoded, speed: float | np.ndarray, car: CarAgent, dt: float) -> np.ndarray:
    """Normalised acceleration ``(n,)`` that brings a car's speed to ``speed`` m/s as fast as allowed."""
    return np.clip((speed - view.own_speed) / (dt * car.a_max), -1.0, 1.0)


def velocity_command(view: Decoded, velocity: np.ndarray, mass: PointMassAgent, dt: float) -> np.ndarray:
    """Normalised accelerations ``(n, 2)`` that bring a point mass to ``velocity`` ``(n, 2)`` m/s."""
    return np.clip((velocity - view.own_vel) / (dt * mass.a_max), -1.0, 1.0)


def full_speed_along(direction: np.ndarray, mass: PointMassAgent) -> np.ndarray:
    """The fastest velocity ``(n, 2)`` along ``direction`` under per-axis limits; zero for a zero direction."""
    largest = np.max(np.abs(direction), axis=1, keepdims=True)
    return np.divide(direction * mass.v_max, largest, out=np.zeros_like(direction), where=largest > 1e-12)
