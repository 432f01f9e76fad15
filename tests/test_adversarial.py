"""pecli's adversarial scripted players: they act in every scenario and do what their exploit says."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import all_scenarios

from pecli.game import Game
from pecli.policies import resolve_policy
from pecli.policies.adversarial import Interceptor, WallRunner
from pecli.scenario import Scenario

EVADERS = ["circler", "blindside", "wall-runner", "hider", "corner-sitter"]


@pytest.mark.parametrize("scenario", all_scenarios(), ids=lambda s: f"{s.name}-{s.observation_frame}")
def test_every_adversary_acts_in_range_in_every_scenario(scenario: Scenario) -> None:
    n = 32
    game = Game(scenario, n=n, seed=0, auto_reset=True)
    obs = game.reset()
    for pursuer_name in ("interceptor", "pure-pursuit"):
        pursuer = resolve_policy(pursuer_name, "pursuer", scenario, seed=1)
        evaders = [resolve_policy(name, "evader", scenario, seed=2) for name in EVADERS]
        for policy in (pursuer, *evaders):
            policy.reset(n)
        for step in range(40):
            evader = evaders[step % len(evaders)]
            pa, ea = pursuer.act(obs["pursuer"]), evader.act(obs["evader"])
            assert pa.shape == ea.shape == (n, 2) and np.all(np.abs(pa) <= 1) and np.all(np.abs(ea) <= 1)
            assert np.all(np.isfinite(pa)) and np.all(np.isfinite(ea))
            result = game.step(pa, ea)
            for policy in (pursuer, *evaders):
                policy.reset(n, mask=result.done)
            obs = result.obs


def car_and_mass(paper: Scenario, car: tuple, mass: tuple) -> dict[str, np.ndarray]:
    """Observations of one game: the car (x, y, steer, speed, yaw) and the point mass (x, y, vx, vy)."""
    return Game(paper, n=1, seed=0).set_state(np.array([[*car, *mass]], dtype=float))


def acceleration(policy_name: str, paper: Scenario, obs: dict[str, np.ndarray], steps: int = 1) -> np.ndarray:
    policy = resolve_policy(policy_name, "evader", paper, seed=0)
    policy.reset(1)
    for _ in range(steps):
        action = policy.act(obs["evader"])
    return action[0]


def test_the_circler_goes_for_the_centre_of_the_cars_turning_circle(paper: Scenario) -> None:
    radius = paper.pursuer.wheelbase / np.tan(paper.pursuer.steer_abs_max)  # 0.85 m
    obs = car_and_mass(paper, (0.0, 0.0, 0.0, 2.0, 0.0), (0.6, 0.4, 0.0, 0.0))  # close, on the car's left
    action = acceleration("circler", paper, obs)
    centre = np.array([0.0, radius])
    wanted = centre - np.array([0.6, 0.4]) + np.array([2.0, 0.0]) / 3.0  # towards it, carried along with the car
    assert np.dot(action, wanted) / (np.linalg.norm(action) * np.linalg.norm(wanted)) > 0.9
    far = car_and_mass(paper, (0.0, 0.0, 0.0, 2.0, 0.0), (3.0, 0.0, 0.0, 0.0))  # farther: flees like greedy
    assert np.allclose(acceleration("circler", paper, far), acceleration("greedy", paper, far))


def test_the_blindside_steps_out_of_the_wedge_and_follows_from_behind(paper: Scenario) -> None:
    ahead = car_and_mass(paper, (0.0, 0.0, 0.0, 2.0, 0.0), (2.0, 0.3, 0.0, 0.0))  # in front, slightly left
    action = acceleration("blindside", paper, ahead)
    assert action[1] > 0.5 and action[0] < 0  # sideways, to its own side, and back
    behind = car_and_mass(paper, (0.0, 0.0, 0.0, 2.0, 0.0), (-3.0, 0.0, 0.0, 0.0))
    action = acceleration("blindside", paper, behind)
    assert action[0] > 0.5  # behind the car, it keeps up with it


def test_the_wall_runner_runs_along_the_wall_away_from_the_pursuer(paper: Scenario) -> None:
    hx = paper.arena.half[0] - WallRunner.margin
    centre = car_and_mass(paper, (5.0, 5.0, 0.0, 0.0, 3.0), (1.0, 0.0, 0.0, 0.0))  # nobody near: to the wall
    assert acceleration("wall-runner", paper, centre)[0] > 0.5  # the right wall is the nearest
    chased = car_and_mass(paper, (hx - 1.5, -2.0, 0.0, 2.0, np.pi / 2), (hx, 0.0, 0.0, 0.0))  # car below, same wall
    action = acceleration("wall-runner", paper, chased)
    assert action[1] > 0.5 and abs(action[0]) < 0.5  # up the wall, away from it
    arc = WallRunner._arc(np.array([[hx, 0.0], [0.0, 7.7], [-7.7, 0.0]]), hx, 7.7)
    assert np.allclose(WallRunner._point(arc, hx, 7.7), [[hx, 0.0], [0.0, 7.7], [-7.7, 0.0]])


def test_the_hider_goes_far_behind_the_car_remembers_its_spot_and_keeps_still(paper: Scenario) -> None:
    car = (0.0, 0.0, 0.0, 2.0, 0.0)  # at the centre, heading +x
    hider = resolve_policy("hider", "evader", paper, seed=0)
    hider.reset(1)
    unseen = car_and_mass(paper, car, (-7.0, -7.0, 0.0, 0.0))  # 9.9 m away: out of the hider's sensor range
    assert np.allclose(hider.act(unseen["evader"]), 0.0)  # never seen it: keeps still
    behind = car_and_mass(paper, car, (-4.0, 1.0, 0.0, 0.0))  # seen, behind the car
    action = hider.act(behind["evader"])[0]
    spot = hider.spot[0].copy()
    assert spot[0] < -5.0 and np.linalg.norm(spot) > 8.0  # far, on the car's blind side
    towards = spot - np.array([-4.0, 1.0])
    assert np.dot(action, towards) / (np.linalg.norm(action) * np.linalg.norm(towards)) > 0.9
    gone = car_and_mass(paper, (7.0, -7.0, 0.0, 2.0, 0.0), (-4.0, 1.0, 0.0, 0.0))  # the car out of its sight now
    action = hider.act(gone["evader"])[0]
    assert np.allclose(hider.spot[0], spot) and np.dot(action, towards) > 0  # still on its way to the same spot
    there = car_and_mass(paper, (7.0, -7.0, 0.0, 2.0, 0.0), (*spot, 0.0, 0.0))
    assert np.allclose(hider.act(there["evader"]), 0.0)  # at its spot: keeps still
    close = car_and_mass(paper, car, (1.5, 0.0, 0.0, 0.0))  # within 2 m: flees like greedy
    assert np.allclose(hider.act(close["evader"]), acceleration("greedy", paper, close))


def test_the_corner_sitter_keeps_still_in_a_corner_and_steps_past_a_car_that_comes_for_it(paper: Scenario) -> None:
    hx, hy = paper.arena.half
    sitter = resolve_policy("corner-sitter", "evader", paper, seed=0)
    sitter.reset(1)
    far = car_and_mass(paper, (-7.0, -7.0, 0.0, 2.0, 0.0), (1.0, 2.0, 0.0, 0.0))  # out of its sensor's 6 m
    action = sitter.act(far["evader"])[0]
    corner = sitter.corner[0].copy()
    assert np.allclose(np.abs(corner), [hx, hy])  # a corner drawn at random
    assert np.dot(action, corner - np.array([1.0, 2.0])) > 0  # on its way there
    there = car_and_mass(paper, (-7.0, -7.0, 0.0, 2.0, 0.0), (*corner, 0.0, 0.0))
    assert np.allclose(sitter.act(there["evader"]), 0.0)  # in its corner: keeps still
    sitter.reset(1)
    seen = car_and_mass(paper, (-2.0, 3.0, 0.0, 2.0, 0.0), (0.0, 0.0, 0.0, 0.0))  # sees the car at the start
    sitter.act(seen["evader"])
    assert np.allclose(sitter.corner[0], [hx, -hy])  # the corner farthest from it
    yaw = np.pi / 4  # the car drives into the sitter's corner, 2.8 m away, the sitter in the middle of its wedge
    coming = car_and_mass(paper, (hx - 2.0, hy - 2.0, 0.0, 2.0, yaw), (hx, hy, 0.0, 0.0))
    action = sitter.act(coming["evader"])[0]
    assert np.allclose(sitter.corner[0], [-hx, -hy])  # now bound for the corner farthest from the car
    assert action[0] < -0.5 and action[1] > 0  # out of the wedge sideways, along the wall and past the car
    assert np.allclose(action, acceleration("blindside", paper, coming))  # the blindside's way out of the wedge


def test_the_interceptor_leads_a_moving_evader(paper: Scenario) -> None:
    obs = car_and_mass(paper, (0.0, 0.0, 0.0, 2.0, 0.0), (4.0, 0.0, 0.0, 1.5))  # ahead, crossing to the left
    lead = resolve_policy("interceptor", "pursuer", paper, seed=0)
    plain = resolve_policy("pure-pursuit", "pursuer", paper, seed=0)
    lead.reset(1)
    plain.reset(1)
    assert lead.act(obs["pursuer"])[0, 0] > 0.1 and abs(plain.act(obs["pursuer"])[0, 0]) < 1e-6  # it steers left
    t = Interceptor._time_to_meet(np.array([[4.0, 0.0]]), np.array([[0.0, 1.5]]), 2.5)
    assert np.linalg.norm([4.0, 1.5 * t[0]]) == pytest.approx(2.5 * t[0])
