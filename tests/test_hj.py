"""The Hamilton–Jacobi baseline: solver against the closed form, filters, cache, policies, CLI and errors."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from pecli.cli import app
from pecli.errors import ConfigError, PolicyError
from pecli.game import Game
from pecli.hj import Problem, Solution, SolutionError, cache_path, solve, solve_cached
from pecli.hj.filters import window_extreme
from pecli.hj.oracle import continuous_value, discrete_value
from pecli.match import play_match
from pecli.policies import resolve_policy
from pecli.policies.hj import HJPolicy
from pecli.scenario import Scenario, load_scenario

runner = CliRunner()


@pytest.fixture(scope="module")
def point_mass() -> Scenario:
    return load_scenario("point_mass")


@pytest.fixture(scope="module")
def coarse(point_mass: Scenario) -> Solution:
    """A coarse rel4d solution of point_mass.yaml over the full horizon (a fraction of a second)."""
    problem = Problem.for_scenario(point_mass, "rel4d", (21, 11))
    return Solution(problem, solve(problem), {"scenario": point_mass.name})


@pytest.fixture(autouse=True)
def private_cache(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    folder = tmp_path / "hj-cache"
    monkeypatch.setenv("PECLI_HJ_CACHE", str(folder))
    return folder


def random_states(n: int, seed: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """Relative positions within the arena's middle and relative velocities within the speed limits."""
    rng = np.random.default_rng(seed)
    return rng.uniform(-7.0, 7.0, (n, 2)), rng.uniform(-5.0, 5.0, (n, 2))


# ---------------------------------------------------------------------- solver
def test_the_solver_agrees_with_the_closed_form(point_mass: Scenario) -> None:
    """Equal accelerations (SPEC §6): the value is the closest approach at constant relative velocity."""
    problem = Problem.for_scenario(point_mass, "rel4d", (61, 21), "maxmin", steps=50)
    values = solve(problem)
    r, w = random_states(20_000)
    zeros = np.zeros_like(r)
    dp = problem.grid.interpolate(values, problem.grid.points(zeros, zeros, r, w))
    exact = discrete_value(r, w, problem.steps, problem.dt, problem.game.capture_distance)
    assert np.mean((dp <= 0) == (exact <= 0)) >= 0.98
    assert np.mean(np.abs(dp - exact)) <= 0.05  # m
    # captures are a few % of the states: sign agreement alone passes without a DP (0.96) or with
    # linear interpolation (0.985, a third of the captures missed), so the capture set is checked too
    assert np.mean(dp[exact <= 0] <= 0) >= 0.85  # recall of the capture set
    assert np.mean(dp[exact > 0] <= 0) <= 0.01  # false captures
    assert 0.02 < np.mean(exact <= 0) < 0.2  # the sample holds captures and escapes


def test_the_oracles() -> None:
    r = np.array([[-3.0, 0.0], [-3.0, 0.0], [-3.0, 0.6], [2.0, 0.0], [-3.0, 0.0]])
    w = np.array([[1.0, 0.0], [0.1, 0.0], [1.0, 0.0], [1.0, 0.0], [22.0, 0.0]])
    assert np.allclose(continuous_value(r, w, 10.0, 0.5), [-0.5, 1.5, 0.1, 1.5, -0.5])
    # checked every dt = 0.1 s, the fast pass (2.2 m per step: -3, -0.8, 1.4) jumps over the disk
    assert np.allclose(discrete_value(r, w, 100, 0.1, 0.5), [-0.5, 1.5, 0.1, 1.5, 0.3])


@pytest.mark.parametrize("reach", [0.0, 0.4, 1.0, 2.3, 5.7])
@pytest.mark.parametrize("kind", ["max", "min"])
def test_window_extreme_is_the_extreme_of_the_interpolant(reach: float, kind: str) -> None:
    values = np.random.default_rng(0).random((5, 13, 4))
    n = values.shape[1]
    brute = None
    offsets = np.concatenate([np.linspace(-reach, reach, 101), np.arange(-np.floor(reach), np.floor(reach) + 1)])
    for delta in offsets:  # the linear interpolant at i + delta, clamped to the axis
        u = np.clip(np.arange(n) + delta, 0, n - 1)
        low = np.minimum(np.floor(u).astype(int), n - 2)
        t = (u - low)[None, :, None]
        sample = values[:, low] * (1 - t) + values[:, low + 1] * t
        brute = sample if brute is None else (np.maximum if kind == "max" else np.minimum)(brute, sample)
    assert np.allclose(window_extreme(values, 1, reach, kind), brute)


def test_rel6d_solves_and_respects_the_target(point_mass: Scenario) -> None:
    problem = Problem.for_scenario(point_mass, "rel6d", (11, 5), steps=10)
    values = solve(problem)
    assert values.shape == problem.grid.shape == (5, 5, 11, 5, 5, 11) and values.dtype == np.float32
    target = solve(Problem.for_scenario(point_mass, "rel6d", (11, 5), steps=1))
    assert np.all(values <= target + 1e-6)  # a longer horizon never raises the value
    still = problem.grid.points(np.zeros((1, 2)), np.zeros((1, 2)), np.zeros((1, 2)), np.zeros((1, 2)))
    assert problem.grid.interpolate(values, still)[0] == pytest.approx(-0.5)


def test_bad_problems_are_refused(point_mass: Scenario, paper: Scenario) -> None:
    with pytest.raises(ConfigError, match="point mass vs point mass"):
        Problem.for_scenario(paper)
    with pytest.raises(ConfigError, match="at least 3 nodes"):
        Problem.for_scenario(point_mass, sizes=(2, 11))
    with pytest.raises(ConfigError, match="unknown order"):
        Problem.for_scenario(point_mass, order="sideways")  # type: ignore[arg-type]


def test_the_hj_reachability_backend_says_how_to_install_it(point_mass: Scenario, monkeypatch) -> None:
    from pecli.errors import PecliError
    from pecli.hj.reachability import solve_with_hj_reachability

    monkeypatch.setitem(sys.modules, "hj_reachability", None)  # as if it were not installed
    problem = Problem.for_scenario(point_mass, "rel4d", (11, 5), steps=3, backend="hj-reachability")
    assert problem.key() != Problem.for_scenario(point_mass, "rel4d", (11, 5), steps=3).key()
    with pytest.raises(PecliError, match='pip install "pecli\\[hj\\]"'):
        solve_with_hj_reachability(problem)
    with pytest.raises(ConfigError, match="rel4d only"):
        Problem.for_scenario(point_mass, "rel6d", backend="hj-reachability")


# ---------------------------------------------------------------------- cache
def test_the_cache_is_reused_and_invalidated(point_mass: Scenario, private_cache: Path) -> None:
    problem = Problem.for_scenario(point_mass, "rel4d", (11, 5), steps=5)
    first, path, reused = solve_cached(problem, point_mass.name)
    assert not reused and path == cache_path(problem) and path.parent == private_cache
    again, _, reused = solve_cached(problem, point_mass.name)
    assert reused and np.array_equal(again.values, first.values)
    for changed in (  # every parameter that decides the value misses the cache
        Problem.for_scenario(point_mass, "rel4d", (11, 5), steps=6),
        Problem.for_scenario(point_mass, "rel4d", (11, 5), "minmax", steps=5),
        Problem.for_scenario(point_mass, "rel4d", (13, 5), steps=5),
        Problem.for_scenario(point_mass.model_copy(update={"dt": 0.05}), "rel4d", (11, 5), steps=5),
    ):
        assert changed.key() != problem.key()
        assert not solve_cached(changed, point_mass.name)[2]
    same_game = point_mass.model_copy(update={"name": "renamed", "horizon": 5})  # name and sensors do not matter
    assert Problem.for_scenario(same_game, "rel4d", (11, 5)).key() == problem.key()
    path.write_bytes(b"not a solution")  # a damaged file is solved again
    assert not solve_cached(problem, point_mass.name)[2]
    assert not solve_cached(problem, point_mass.name, force=True)[2]


def test_a_solution_file_round_trips_and_refuses_other_games(coarse: Solution, tmp_path: Path,
                                                             point_mass: Scenario) -> None:
    path = coarse.save(tmp_path / "s.npz")
    loaded = Solution.load(path)
    assert loaded.key == coarse.key and np.array_equal(loaded.values, coarse.values)
    faster = point_mass.model_copy(update={"evader": point_mass.evader.model_copy(update={"v_max": 3.0})})
    with pytest.raises(SolutionError, match="solved for 'point_mass'"):
        loaded.check_scenario(faster)
    with pytest.raises(SolutionError, match="must end in .npz"):
        coarse.save(tmp_path / "s.txt")
    with pytest.raises(SolutionError, match="no HJ solution"):
        Solution.load(tmp_path / "missing.npz")


# ---------------------------------------------------------------------- policies
def test_hj_pursuer_captures_the_greedy_evader(coarse: Solution, point_mass: Scenario) -> None:
    pursuer = HJPolicy(point_mass, "pursuer", coarse)
    result, _ = play_match(point_mass, pursuer, resolve_policy("greedy", "evader", point_mass), episodes=200)
    assert result.capture_rate >= 0.5
    far = point_mass.pursuer.sensor.model_copy(update={"range": 30.0})
    seeing = point_mass.model_copy(update={  # with the evader always in sight the pursuer corners it
        "pursuer": point_mass.pursuer.model_copy(update={"sensor": far}),
        "evader": point_mass.evader.model_copy(update={"sensor": far}),
    })
    greedy = resolve_policy("greedy", "evader", seeing)
    result, _ = play_match(seeing, HJPolicy(seeing, "pursuer", coarse), greedy, episodes=100)
    assert result.capture_rate >= 0.95


def test_a_vanishing_gradient_falls_back_to_the_relative_position(coarse: Solution, point_mass: Scenario) -> None:
    """Players separating along x: no input changes the closest approach (now), so dV/dv = 0."""
    game = Game(point_mass, n=2)
    state = np.array([[0.0, 0.0, 0.0, 0.0, 2.0, 0.0, 2.0, 0.0],  # evader 2 m ahead, moving away
                      [0.0, 0.0, 0.0, 0.0, 0.0, -2.0, 0.0, -2.0]])  # evader 2 m below, moving away
    obs = game.set_state(state)
    pursuer, evader = HJPolicy(point_mass, "pursuer", coarse), HJPolicy(point_mass, "evader", coarse)
    p_points = coarse.grid.points(state[:, :2], state[:, 2:4], state[:, 4:6], state[:, 6:8])
    gradient = coarse.grid.gradient(coarse.values, p_points, pursuer.velocity_axes)
    assert np.abs(gradient).max() <= 1e-3
    assert np.array_equal(pursuer.act(obs["pursuer"]), [[1.0, 0.0], [0.0, -1.0]])  # towards the evader
    assert np.array_equal(evader.act(obs["evader"]), [[1.0, 0.0], [0.0, -1.0]])  # away from the pursuer


def test_the_pursuer_chases_with_the_gradient(coarse: Solution, point_mass: Scenario) -> None:
    """Closing in head-on with a lateral offset: the pursuer steers into the evader's path, the evader out."""
    game = Game(point_mass, n=1)
    state = np.array([[0.0, 0.0, 1.0, 0.0, 3.0, 0.6, -1.0, 0.0]])
    obs = game.set_state(state)
    assert HJPolicy(point_mass, "pursuer", coarse).act(obs["pursuer"])[0, 1] == 1.0
    assert HJPolicy(point_mass, "evader", coarse).act(obs["evader"])[0, 1] == 1.0


def test_an_unseen_opponent_is_dead_reckoned(coarse: Solution, point_mass: Scenario) -> None:
    game = Game(point_mass, n=1)
    pursuer = HJPolicy(point_mass, "pursuer", coarse)
    pursuer.reset(1)
    assert np.array_equal(pursuer.opp_state[:, 0], [0, 0, 0, 0])  # never seen: the centre, at rest
    obs = game.set_state(np.array([[0.0, 0.0, 0.0, 0.0, 3.0, 0.0, 2.0, 1.0]]))
    pursuer.act(obs["pursuer"])
    obs = game.set_state(np.array([[-4.5, 0.0, 0.0, 0.0, 3.0, 0.0, 2.0, 1.0]]))  # now out of range
    for step in range(1, 4):
        pursuer.act(obs["pursuer"])
        assert np.allclose(pursuer.opp_state[:, 0], [3.0 + 0.2 * step, 0.1 * step, 2.0, 1.0])
    for _ in range(20):  # at the wall (x = 5) the estimate stops moving into it, as the game does
        pursuer.act(obs["pursuer"])
    assert np.allclose(pursuer.opp_state[[0, 2, 3], 0], [5.0, 0.0, 1.0])
    pursuer.reset(1, mask=np.array([True]))
    assert np.array_equal(pursuer.opp_state[:, 0], [0, 0, 0, 0])


@pytest.fixture(scope="module")
def belief_checkpoint(tmp_path_factory, point_mass: Scenario) -> Path:
    """A tiny BiMDN pursuer trained for a few hundred steps on point_mass.yaml."""
    from pecli.rl.train import TrainJob, train, with_overrides

    scenario = with_overrides(point_mass, {
        "belief": "bimdn", "steps": 300, "learning_starts": 100, "batch_size": 16, "buffer_size": 500, "n_envs": 2,
        "net_arch": [16], "belief_settings.warmup": 50, "belief_settings.batch_size": 16,
        "belief_settings.hidden": 8, "belief_settings.fc": 8, "history_length": 20, "history_stride": 10,
    })
    job = TrainJob(role="pursuer", scenario=scenario, opponent="greedy", zoo=tmp_path_factory.mktemp("zoo"),
                   name="b", progress=False)
    return train(job)


def test_a_belief_checkpoint_estimates_the_unseen_opponent(coarse: Solution, point_mass: Scenario, tmp_path: Path,
                                                          belief_checkpoint: Path) -> None:
    path = coarse.save(tmp_path / "s.npz")
    pursuer = resolve_policy(f"hj:{path},belief={belief_checkpoint}", "pursuer", point_mass)
    assert isinstance(pursuer, HJPolicy) and pursuer.belief is not None
    assert pursuer.identity.startswith(f"hj:{coarse.key}:belief:")
    game = Game(point_mass, n=4, seed=3)
    obs = game.reset()
    pursuer.reset(4)
    for _ in range(5):
        actions = pursuer.act(obs["pursuer"])
        assert actions.shape == (4, 2) and set(np.unique(actions)) <= {-1.0, 0.0, 1.0}
        obs = game.step(actions, np.zeros((4, 2))).obs
    mean = pursuer._belief_mean()
    view = pursuer.codec.decode(obs["pursuer"])
    position, _ = pursuer._estimate(view)
    unseen = ~view.seen
    assert np.allclose(position[unseen], mean[unseen]) and np.allclose(position[~unseen], view.opp_pos[~unseen])
    with pytest.raises(PolicyError, match="cannot play evader"):
        resolve_policy(f"hj:{path},belief={belief_checkpoint}", "evader", point_mass)


def test_policy_strings(coarse: Solution, point_mass: Scenario, tmp_path: Path) -> None:
    with pytest.raises(PolicyError, match="pecli hj solve"):
        resolve_policy("hj", "pursuer", point_mass)  # nothing cached yet
    with pytest.raises(PolicyError, match="point mass vs point mass"):
        resolve_policy("hj", "pursuer", load_scenario("paper"))
    with pytest.raises(PolicyError, match="unknown hj option 'grid'"):
        resolve_policy("hj:grid=3", "pursuer", point_mass)
    with pytest.raises(PolicyError, match="no HJ solution at"):
        resolve_policy(f"hj:{tmp_path / 'missing.npz'}", "evader", point_mass)
    with pytest.raises(PolicyError, match="unknown HJ model"):
        resolve_policy("hj:model=rel9d", "evader", point_mass)
    path = coarse.save(tmp_path / "s.npz")
    for spec in (str(path), f"hj:{path}", f"hj:solution={path}"):
        for role in ("pursuer", "evader"):
            policy = resolve_policy(spec, role, point_mass)
            assert isinstance(policy, HJPolicy) and policy.role == role and policy.identity == f"hj:{coarse.key}"
    coarse.save(cache_path(Problem.for_scenario(point_mass)))  # stands in for the default solution
    assert isinstance(resolve_policy("hj", "evader", point_mass), HJPolicy)


def test_hj_joins_both_sides_of_a_tournament(coarse: Solution, point_mass: Scenario, tmp_path: Path) -> None:
    from pecli.tournament import find_players, run_tournament, schedule

    path = coarse.save(tmp_path / "s.npz")
    found = find_players([f"hj:{path}", "greedy"], point_mass)
    assert [p.name for p in found.players["pursuer"]] == [f"hj:{path}/pursuer"]
    assert [p.name for p in found.players["evader"]] == [f"hj:{path}/evader", "greedy"]
    assert {p.identity for p in found.players["pursuer"]} == {f"hj:{coarse.key}"}
    results = run_tournament(point_mass, found.players, schedule(found.players), 20, [0], tmp_path / "t")
    assert len(results.pairings) == 2
    from pecli.reports import table_two

    table = table_two(json.loads(json.dumps(results.to_json())))
    assert [c.header for c in table.columns][1:] == ["time: optimal control", "rate: optimal control"]


# ---------------------------------------------------------------------- CLI
def test_cli_solve_reuses_and_errors_are_one_line(private_cache: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    args = ["hj", "solve", "-g", "11,5", "--steps", "3", "--json"]
    first = runner.invoke(app, args)
    assert first.exit_code == 0, first.output
    data = json.loads(first.stdout)
    assert not data["reused"] and Path(data["path"]).parent == private_cache and data["grid"] == "13x11x13x11"
    again = json.loads(runner.invoke(app, args).stdout)
    assert again["reused"] and again["key"] == data["key"]
    listed = runner.invoke(app, ["hj", "list"])
    assert listed.exit_code == 0 and "point_mass" in listed.output
    for bad, message in (
        (["hj", "solve", "-c", "paper"], "point mass vs point mass"),
        (["hj", "solve", "-g", "abc"], "--grid takes two whole numbers"),
        (["hj", "solve", "--model", "rel5d"], "unknown HJ model"),
        (["hj", "solve", "-o", "out.txt"], "--out must end in .npz"),
        (["hj", "show", "nothing.npz"], "no HJ solution at"),
        (["hj", "table", "nothing.json"], "nothing.json"),
        (["play", "-p", "hj", "-c", "point_mass"], "pecli hj solve"),
        (["hj", "solve", "-g", "11,5", "--backend", "hj-reachability"], 'pip install "pecli[hj]"'),
    ):
        monkeypatch.setitem(sys.modules, "hj_reachability", None)  # not installed, where it is
        result = runner.invoke(app, bad)
        assert result.exit_code == 1, (bad, result.output)
        assert message in result.output and "Traceback" not in result.output


def test_requested_sizes_that_snap_to_one_grid_share_a_cache_key(point_mass: Scenario) -> None:
    a = Problem.for_scenario(point_mass, "rel4d", sizes=(15, 21))
    b = Problem.for_scenario(point_mass, "rel4d", sizes=(15, 25))
    assert a.grid.describe() == b.grid.describe() and a.cache_key() == b.cache_key()
    assert cache_path(a) == cache_path(b)
    short_a, short_b = (Problem.for_scenario(point_mass, "rel4d", sizes=p.sizes, steps=3) for p in (a, b))
    first, _, reused = solve_cached(short_a, point_mass.name)
    again, _, reused_again = solve_cached(short_b, point_mass.name)
    assert not reused and reused_again and np.array_equal(first.values, again.values)
    assert Problem.for_scenario(point_mass, "rel4d", sizes=(15, 41)).cache_key() != a.cache_key()
    assert Problem.for_scenario(point_mass, "rel4d", sizes=(17, 21)).cache_key() != a.cache_key()
