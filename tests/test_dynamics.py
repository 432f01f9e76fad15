"""The batched dynamics against CommonRoad's reference implementation, integrated the same way (Euler)."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest
from vehiclemodels.utils.acceleration_constraints import acceleration_constraints
from vehiclemodels.utils.steering_constraints import steering_constraints
from vehiclemodels.vehicle_dynamics_ks import vehicle_dynamics_ks

from pecli.game.dynamics import CarDynamics, PointMassDynamics, wrap_angle, wrap_near
from pecli.scenario import CarAgent, PointMassAgent, Sensor, load_scenario


def commonroad_parameters(car: CarAgent) -> SimpleNamespace:
    """A CommonRoad parameter structure with our car's values."""
    return SimpleNamespace(
        a=car.lf,
        b=car.lr,
        steering=SimpleNamespace(
            min=car.steer_min, max=car.steer_max, v_min=-car.steer_rate_max, v_max=car.steer_rate_max
        ),
        longitudinal=SimpleNamespace(
            v_min=car.v_min,
            v_max=car.v_max,
            v_switch=math.inf if car.v_switch is None else car.v_switch,
            a_max=car.a_max,
        ),
    )


def reference_step(x: list[float], u: list[float], car: CarAgent, dt: float) -> list[float]:
    """One Euler step of CommonRoad's KS model, then the same limit clipping and yaw wrap as pecli."""
    f = vehicle_dynamics_ks(x, u, commonroad_parameters(car))
    new = [xi + dt * fi for xi, fi in zip(x, f)]
    new[2] = min(max(new[2], car.steer_min), car.steer_max)
    new[3] = min(max(new[3], car.v_min), car.v_max)
    new[4] = (new[4] + math.pi) % (2 * math.pi) - math.pi
    return new


CARS = {
    "paper": load_scenario("paper").pursuer,
    "f1tenth": load_scenario("robots").pursuer,
    "with_v_switch": load_scenario("paper").pursuer.model_copy(update={"v_switch": 1.2}),
}


@pytest.mark.parametrize("car_name", sorted(CARS))
@pytest.mark.parametrize("inputs", ["random", "limits"])
def test_car_matches_commonroad(car_name: str, inputs: str) -> None:
    car = CARS[car_name]
    dyn = CarDynamics(car)
    rng = np.random.default_rng(7)
    n, steps, dt = 16, 150, 0.1
    start = np.zeros((5, n))
    start[0:2] = rng.uniform(-3, 3, (2, n))
    start[2] = rng.uniform(car.steer_min, car.steer_max, n)
    start[3] = rng.uniform(car.v_min, car.v_max, n)
    start[4] = rng.uniform(-math.pi, math.pi, n)
    rows = dyn.from_state(start)
    reference = [list(start[:, i]) for i in range(n)]
    for _ in range(steps):
        if inputs == "random":
            action = rng.uniform(-1.2, 1.2, (n, 2))  # a little beyond the limits, to exercise clipping
        else:
            action = rng.choice([-1.0, 1.0], size=(n, 2))  # hug the limits: bang-bang inputs
        rows = dyn.step(rows, action, dt)
        for i in range(n):
            clipped = np.clip(action[i], -1, 1)
            u = [clipped[0] * car.steer_rate_max, clipped[1] * car.a_max]
            reference[i] = reference_step(reference[i], u, car, dt)
    np.testing.assert_allclose(rows[:5].T, np.array(reference), atol=1e-9)
    np.testing.assert_allclose(rows[5], np.cos(rows[4]), atol=1e-12)


def test_car_constraints_match_commonroad_functions() -> None:
    car = CARS["with_v_switch"]
    p = commonroad_parameters(car)
    dyn = CarDynamics(car)
    rng = np.random.default_rng(3)
    n = 400
    state = np.zeros((5, n))
    # states at, inside and beyond the limits
    state[2] = rng.choice([car.steer_min, car.steer_max, 0.0, 0.1, car.steer_min - 0.01], n)
    state[3] = rng.choice([car.v_min, car.v_max, 0.0, 1.5, 2.2, car.v_max + 0.1], n)
    action = rng.uniform(-1, 1, (n, 2))
    action[::5] = 0.0
    steer_rate, accel = dyn.inputs(dyn.from_state(state), action)
    for i in range(n):
        assert steer_rate[i] == pytest.approx(
            steering_constraints(state[2, i], action[i, 0] * car.steer_rate_max, p.steering)
        )
        assert accel[i] == pytest.approx(
            acceleration_constraints(state[3, i], action[i, 1] * car.a_max, p.longitudinal)
        )


def test_point_mass_euler_and_limits() -> None:
    mass = PointMassAgent(v_max=1.5, a_max=9.81, sensor=Sensor(range=6.0))
    dyn = PointMassDynamics(mass)
    state = np.array([[0.0, 1.0], [0.0, -1.0], [1.4, -1.5], [0.0, 0.5]])
    new = dyn.step(state, np.array([[1.0, 1.0], [-1.0, -1.0]]), dt=0.1)
    np.testing.assert_allclose(new[0:2], state[0:2] + 0.1 * state[2:4])  # positions use the old velocity
    assert new[2, 0] == pytest.approx(1.5)  # clipped at the limit
    assert new[3, 0] == pytest.approx(0.981)
    assert new[2, 1] == pytest.approx(-1.5)  # at the limit and pushing outward: no acceleration
    assert new[3, 1] == pytest.approx(0.5 - 0.981)
    slow = dyn.step(state, np.array([[1.0, 1.0], [1.0, 1.0]]), dt=0.1, speed_scale=0.0)
    np.testing.assert_allclose(slow[2:4], 0.0)  # curriculum speed scale 0: cannot move


def test_walls_stop_a_car_and_drop_a_point_mass_normal_velocity() -> None:
    paper = load_scenario("paper")
    car = CarDynamics(paper.pursuer)
    rows = car.from_state(np.array([[8.5, 0.0], [0.0, -8.2], [0.0, 0.0], [2.0, 1.0], [0.0, -1.5]]))
    car.stop_at_walls(rows, 8.0, 8.0)
    np.testing.assert_allclose(rows[0:2], [[8.0, 0.0], [0.0, -8.0]])
    np.testing.assert_allclose(rows[3], 0.0)
    mass = PointMassDynamics(paper.evader)
    state = np.array([[8.3, -2.0], [1.0, -8.1], [1.0, -0.5], [0.7, -1.0]])
    mass.stop_at_walls(state, 8.0, 8.0)
    np.testing.assert_allclose(state, [[8.0, -2.0], [1.0, -8.0], [0.0, -0.5], [0.7, 0.0]])


def test_wrap_angle() -> None:
    angles = np.array([-3 * math.pi, -math.pi, -0.5, 0.0, math.pi, 2.9 * math.pi])
    wrapped = wrap_angle(angles)
    assert np.all(wrapped >= -math.pi) and np.all(wrapped < math.pi)
    np.testing.assert_allclose(np.cos(wrapped), np.cos(angles), atol=1e-12)
    np.testing.assert_allclose(wrap_near(angles.copy()), wrapped, atol=1e-12)
