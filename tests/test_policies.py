"""The Policy interface, the heuristic baselines and policy-string resolution."""

from __future__ import annotations

import math
import sys
import textwrap

import numpy as np
import pytest
from conftest import all_scenarios

from pecli.errors import PolicyError
from pecli.game import Game
from pecli.policies import BUILTINS, Policy, resolve_policy
from pecli.scenario import Scenario

PURSUERS = ["pure-pursuit", "random-walk"]
EVADERS = ["greedy", "random-walk", "rash"]


@pytest.mark.parametrize("scenario", all_scenarios(), ids=lambda s: f"{s.name}-{s.observation_frame}")
def test_every_baseline_acts_in_range_in_every_scenario(scenario: Scenario) -> None:
    n = 64
    game = Game(scenario, n=n, seed=0, auto_reset=True)
    obs = game.reset()
    for pursuer_name in PURSUERS:
        for evader_name in EVADERS:
            pursuer = resolve_policy(pursuer_name, "pursuer", scenario, seed=1)
            evader = resolve_policy(evader_name, "evader", scenario, seed=2)
            assert isinstance(pursuer, Policy) and isinstance(evader, Policy)
            pursuer.reset(n)
            evader.reset(n)
            for _ in range(60):
                pa, ea = pursuer.act(obs["pursuer"]), evader.act(obs["evader"])
                assert pa.shape == (n, 2) and ea.shape == (n, 2)
                assert np.all(np.abs(pa) <= 1.0) and np.all(np.abs(ea) <= 1.0)
                result = game.step(pa, ea)
                pursuer.reset(n, mask=result.done)
                evader.reset(n, mask=result.done)
                obs = result.obs


def still_evader_state(scenario: Scenario, distance: float, bearing: float) -> np.ndarray:
    """A car pursuer at the origin facing +x and a still point-mass evader at (distance, bearing)."""
    return np.array([[0, 0, 0, 0, 0, distance * math.cos(bearing), distance * math.sin(bearing), 0, 0]], dtype=float)


@pytest.mark.parametrize("bearing", [0.0, 0.5, -0.9])
def test_pure_pursuit_catches_a_still_evader_it_sees(paper: Scenario, bearing: float) -> None:
    game = Game(paper, n=1, seed=0)
    obs = game.set_state(still_evader_state(paper, 4.0, bearing))
    assert obs["pursuer"][0, 9] == 1.0
    pursuer = resolve_policy("pure-pursuit", "pursuer", paper, seed=0)
    pursuer.reset(1)
    for _ in range(100):
        result = game.step(pursuer.act(obs["pursuer"]), np.zeros((1, 2)))
        obs = result.obs
        if result.captured[0]:
            break
    assert result.captured[0]


def test_pure_pursuit_searches_after_losing_sight(paper: Scenario) -> None:
    policy = resolve_policy("pure-pursuit", "pursuer", paper, seed=0)
    game = Game(paper, n=1, seed=0)
    seen = game.set_state(still_evader_state(paper, 3.0, 0.0))["pursuer"]
    policy.reset(1)
    policy.act(seen)
    unseen = game.set_state(still_evader_state(paper, 3.0, math.pi))["pursuer"]
    commands = np.array([policy.act(unseen)[0, 0] for _ in range(30)])
    assert np.all(np.abs(commands[:25]) == 1.0) and len(set(commands[:25])) == 1  # full lock, one direction
    assert policy.search_left[0] == 0


def test_greedy_flees_when_it_sees_and_stops_when_it_does_not(paper: Scenario) -> None:
    greedy = resolve_policy("greedy", "evader", paper)
    game = Game(paper, n=1, seed=0)
    obs = game.set_state(still_evader_state(paper, 3.0, 0.0))["evader"]  # the pursuer is 3 m to its -x
    greedy.reset(1)
    action = greedy.act(obs)[0]
    assert action[0] == 1.0 and abs(action[1]) < 1e-9  # straight away along +x
    state = still_evader_state(paper, 7.0, 0.0)
    state[0, 7:9] = [1.0, -0.5]  # moving, and out of range: brake
    action = greedy.act(game.set_state(state)["evader"])[0]
    assert action[0] < 0 and action[1] > 0


def test_rash_ignores_the_pursuer(paper: Scenario) -> None:
    game = Game(paper, n=1, seed=0)
    a = resolve_policy("rash", "evader", paper, seed=5)
    b = resolve_policy("rash", "evader", paper, seed=5)
    a.reset(1)
    b.reset(1)
    near = game.set_state(still_evader_state(paper, 2.0, 0.0))["evader"]
    far = near.copy()
    far[0, 4:10] = 0.0
    far[0, 9] = -1.0
    np.testing.assert_array_equal(a.act(near), b.act(far))


def test_policies_are_deterministic_under_a_seed(paper: Scenario) -> None:
    obs = Game(paper, n=8, seed=0).observe()["evader"]
    a = resolve_policy("random-walk", "evader", paper, seed=3)
    b = resolve_policy("random-walk", "evader", paper, seed=3)
    a.reset(8)
    b.reset(8)
    np.testing.assert_array_equal(a.act(obs), b.act(obs))


def test_wrong_role_and_unknown_names(paper: Scenario) -> None:
    with pytest.raises(PolicyError, match="'greedy' plays evader, not pursuer"):
        resolve_policy("greedy", "pursuer", paper)
    with pytest.raises(PolicyError, match="'pure-pursuit' plays pursuer, not evader"):
        resolve_policy("pure-pursuit", "evader", paper)
    with pytest.raises(PolicyError, match="unknown policy 'sneaky'"):
        resolve_policy("sneaky", "evader", paper)
    with pytest.raises(PolicyError, match="policy file not found"):
        resolve_policy("zoo/missing.zip", "evader", paper)
    assert set(BUILTINS) == {
        "pure-pursuit",
        "greedy",
        "random-walk",
        "rash",
        "interceptor",
        "circler",
        "blindside",
        "wall-runner",
        "hider",
        "corner-sitter",
    }


@pytest.fixture
def user_module(tmp_path, monkeypatch):
    code = textwrap.dedent(
        """
        import numpy as np

        class Circler:
            role = "evader"
            def __init__(self, scenario):
                self.scenario = scenario
            def reset(self, n, mask=None, seed=None):
                self.n = n
            def act(self, obs):
                return np.tile([0.5, -0.5], (obs.shape[0], 1))

        class NotAPolicy:
            pass
        """
    )
    (tmp_path / "my_policies.py").write_text(code)
    monkeypatch.syspath_prepend(str(tmp_path))
    yield "my_policies"
    sys.modules.pop("my_policies", None)


def test_module_class_policies(paper: Scenario, user_module: str) -> None:
    policy = resolve_policy(f"{user_module}:Circler", "evader", paper)
    policy.reset(3)
    np.testing.assert_array_equal(policy.act(np.zeros((3, 11))), [[0.5, -0.5]] * 3)
    with pytest.raises(PolicyError, match="plays evader, not pursuer"):
        resolve_policy(f"{user_module}:Circler", "pursuer", paper)
    with pytest.raises(PolicyError, match="is not a Policy"):
        resolve_policy(f"{user_module}:NotAPolicy", "evader", paper)
    with pytest.raises(PolicyError, match="has no class 'Missing'"):
        resolve_policy(f"{user_module}:Missing", "evader", paper)
    with pytest.raises(PolicyError, match="cannot import module 'no_such_module'"):
        resolve_policy("no_such_module:Thing", "evader", paper)
