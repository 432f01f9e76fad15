"""The meta-game of a zoo: the Nash equilibrium of its capture matrix, exploitability within it, and its mixture as
a player (``pecli tournament --nash``, ``nash:FOLDER``)."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from pecli.cli import app
from pecli.errors import PolicyError
from pecli.metagame import max_entropy, maximin, nash_conv, solve, with_meta_solvers
from pecli.policies import resolve_policy
from pecli.scenario import Scenario

runner = CliRunner()


def test_a_symmetric_cycle_is_solved_by_the_uniform_mixture() -> None:
    # each pursuer catches one evader surely and another never: rock-paper-scissors in capture rates
    m = np.array([[0.5, 1.0, 0.0], [0.0, 0.5, 1.0], [1.0, 0.0, 0.5]])
    game = solve(["a", "b", "c"], ["x", "y", "z"], m)
    assert game.value == pytest.approx(0.5)
    np.testing.assert_allclose(game.pursuer_mixture, [1 / 3] * 3, atol=1e-7)
    np.testing.assert_allclose(game.evader_mixture, [1 / 3] * 3, atol=1e-7)
    assert nash_conv(m, game.pursuer_mixture, game.evader_mixture) == pytest.approx(0.0, abs=1e-7)
    assert all(value == pytest.approx(0.5) for value in game.exploitability().values())  # each pure one loses 0.5


def test_a_dominated_player_gets_no_weight_and_the_value_is_a_saddle_point() -> None:
    m = np.array([[0.9, 0.6], [0.4, 0.3]])  # pursuer a dominates b; evader y dominates x
    game = solve(["a", "b"], ["x", "y"], m)
    assert game.value == pytest.approx(0.6)
    assert game.support("pursuer") == {"a": pytest.approx(1.0)} and game.support("evader") == {"y": pytest.approx(1.0)}
    assert game.exploitability() == pytest.approx({"a": 0.0, "b": 0.3, "x": 0.3, "y": 0.0})


def test_the_equilibrium_guarantees_the_value_against_every_reply() -> None:
    rng = np.random.default_rng(0)
    for _ in range(20):
        m = rng.uniform(size=(int(rng.integers(1, 7)), int(rng.integers(1, 7))))
        game = solve([f"p{i}" for i in range(m.shape[0])], [f"e{j}" for j in range(m.shape[1])], m)
        assert (game.pursuer_mixture @ m).min() >= game.value - 1e-7  # no evader holds the mixture below v
        assert (m @ game.evader_mixture).max() <= game.value + 1e-7  # no pursuer beats the evaders' mixture
        assert game.pursuer_mixture.sum() == pytest.approx(1.0) and game.pursuer_mixture.min() >= 0


@pytest.mark.parametrize("bad", [np.zeros((0, 2)), np.array([[0.5, np.nan]]), np.array([[1.5]]), np.ones(3)])
def test_what_is_no_capture_matrix_is_refused(bad: np.ndarray) -> None:
    with pytest.raises(ValueError):
        maximin(bad)


@pytest.fixture(scope="module")
def played(tmp_path_factory) -> Path:
    """A tournament of scripted players with --nash, played once for the module."""
    out = tmp_path_factory.mktemp("nash") / "t"
    result = runner.invoke(
        app,
        [
            "tournament",
            "pure-pursuit",
            "interceptor",
            "greedy",
            "hider",
            "corner-sitter",
            "-c",
            "quick",
            "-n",
            "60",
            "--seeds",
            "1",
            "-w",
            "1",
            "--out",
            str(out),
            "--nash",
        ],
    )
    assert result.exit_code == 0, result.output
    assert "Nash equilibrium" in result.stdout and f"nash:{out}" in result.output
    return out


def _tournament(played: Path, tmp_path: Path) -> Path:
    """A copy of the played tournament's folder, to change."""
    shutil.copytree(played, tmp_path / "t")
    return tmp_path / "t"


def test_tournament_nash_writes_a_mixture_that_plays_as_one_player(
    played: Path, tmp_path: Path, quick: Scenario
) -> None:
    out = _tournament(played, tmp_path)
    record = json.loads((out / "nash.json").read_text())
    weights = {m["name"]: m["weight"] for m in record["pursuer"]}
    assert set(weights) <= {"pure-pursuit", "interceptor"} and sum(weights.values()) == pytest.approx(1.0)
    assert set(record["exploitability"]) == {"pure-pursuit", "interceptor", "greedy", "hider", "corner-sitter"}
    assert record["solvers"] == {"pursuer": "nash", "evader": "nash"}
    assert record["held_to"]["pursuer"] == pytest.approx(record["value"], abs=1e-6)  # the equilibrium's: the value
    mixture = resolve_policy(f"nash:{out}", "evader", quick, seed=0)
    assert sorted(mixture.names) == sorted(m["name"] for m in record["evader"])
    played = runner.invoke(
        app, ["play", "-p", f"nash:{out}", "-e", f"nash:{out}/nash.json", "-c", "quick", "-n", "40", "--json"]
    )
    assert played.exit_code == 0, played.output
    again = runner.invoke(
        app,
        [
            "tournament",
            f"nash:{out}",
            "greedy",
            "-c",
            "quick",
            "-n",
            "40",
            "--seeds",
            "1",
            "-w",
            "1",
            "--out",
            str(tmp_path / "t2"),
        ],
    )
    assert again.exit_code == 0, again.output  # the mixture takes part in a tournament like any player


@pytest.mark.parametrize(
    "change, message",
    [
        (lambda r: {**r, "scenario_hash": "x"}, "not 'quick'"),
        (lambda r: {**r, "pursuer": [{"name": "m", "spec": "os:system", "weight": 1.0}]}, "imports no code"),
        (lambda r: {**r, "pursuer": [{"name": "m", "spec": "nash:elsewhere", "weight": 1.0}]}, "does not nest"),
        (lambda r: {**r, "value": float("nan")}, "not a Nash mixture"),
        (lambda r: {**r, "pursuer": []}, "not a Nash mixture"),
        (lambda r: {**r, "slack": 0.05}, "a slack goes with a maxent mixture"),
        (lambda r: {**r, "slack": 0.0, "solvers": {"pursuer": "maxent", "evader": "nash"}}, "not a Nash mixture"),
        (lambda r: {**r, "slack": None, "solvers": {"pursuer": "maxent", "evader": "nash"}}, "a slack goes with"),
        (lambda r: json.loads("[" * 100_000 + "]" * 100_000), "nested too deep"),
    ],
)
def test_a_bad_mixture_file_is_refused_in_one_line(
    played: Path, tmp_path: Path, quick: Scenario, change, message: str
) -> None:
    out = _tournament(played, tmp_path)
    record = json.loads((out / "nash.json").read_text())
    try:
        changed = json.dumps(change(record))
    except RecursionError:
        changed = "[" * 100_000 + "]" * 100_000
    (out / "nash.json").write_text(changed)
    with pytest.raises(PolicyError, match=message):
        resolve_policy(f"nash:{out}", "pursuer", quick, seed=0)


def test_nash_refuses_a_sampled_tournament(tmp_path: Path) -> None:
    result = runner.invoke(
        app, ["tournament", "--baselines", "-c", "quick", "--sample", "1", "--nash", "--out", str(tmp_path)]
    )
    assert result.exit_code == 1 and "--nash needs every pairing" in result.output


def test_nash_conv_is_what_the_best_replies_gain_on_a_pair_of_mixtures() -> None:
    m = np.array([[0.9, 0.2], [0.3, 0.6]])
    pure = nash_conv(m, np.array([1.0, 0.0]), np.array([1.0, 0.0]))
    assert pure == pytest.approx(0.9 - 0.2)  # the best pursuer against x catches 0.9; the best evader holds a to 0.2
    game = solve(["a", "b"], ["x", "y"], m)
    assert nash_conv(m, game.pursuer_mixture, game.evader_mixture) == pytest.approx(0.0, abs=1e-7)


def test_a_mixture_is_held_to_what_the_zoos_strongest_reply_gives_it() -> None:
    m = np.array([[0.9, 0.2, 0.5], [0.1, 0.8, 0.5]])
    game = solve(["p0", "p1"], ["e0", "e1", "e2"], m)
    assert game.pursuer_held_to == pytest.approx(game.value) == pytest.approx(game.evader_caught_at_most)
    uniform = with_meta_solvers(game, "uniform", "last")
    assert uniform.pursuer_held_to == pytest.approx(0.5)  # (0.5, 0.5, 0.5): every evader alike
    assert uniform.evader_caught_at_most == pytest.approx(0.5)  # e2 alone: 0.5 by either pursuer
    caught = solve(["p"], [f"e{j}" for j in range(9)], np.ones((1, 9)))  # 9 x (1/9) sums past 1 in floating point
    assert with_meta_solvers(caught, "nash", "uniform").evader_caught_at_most <= 1.0
    newest = with_meta_solvers(game, "last", "uniform")
    assert newest.pursuer_held_to == pytest.approx(0.1)  # p1 alone: e0 holds it to 0.1
    assert newest.evader_caught_at_most == pytest.approx(max(1.6 / 3, 1.4 / 3))


def test_a_meta_solver_picks_the_mixture_and_leaves_the_equilibriums_measures() -> None:
    game = solve(["p0", "p1"], ["e0", "e1", "e2"], np.array([[0.9, 0.2, 0.5], [0.1, 0.8, 0.5]]))
    assert with_meta_solvers(game, "nash", "nash") is game
    other = with_meta_solvers(game, "last", "uniform")
    assert other.support("pursuer") == {"p1": 1.0}  # the newest member alone
    assert (other.pursuer_solver, other.evader_solver, game.pursuer_solver) == ("last", "uniform", "nash")
    assert other.evader_mixture == pytest.approx([1 / 3] * 3)
    assert other.mixtures_rate == pytest.approx((0.1 + 0.8 + 0.5) / 3)
    assert (other.value, other.exploitability()) == (game.value, game.exploitability())
    assert game.mixtures_rate == pytest.approx(game.value)
    with pytest.raises(ValueError, match="no meta-solver 'best'"):
        with_meta_solvers(game, "best", "nash")


def _entropy(x: np.ndarray) -> float:
    kept = x[x > 0]
    return float(-(kept * np.log(kept)).sum())


def test_the_maxent_mixture_spreads_over_members_nearly_as_good_and_keeps_its_floor() -> None:
    # three near-clones and one member that a single evader exploits: the LP picks a vertex, maxent spreads
    m = np.array([[0.80, 0.80], [0.80, 0.80], [0.79, 0.79], [0.20, 0.95]])
    game = solve(["a", "b", "c", "d"], ["x", "y"], m)
    spread = with_meta_solvers(game, "maxent", "maxent", slack=0.05)
    x = spread.pursuer_mixture
    assert (x @ m).min() >= game.value - 0.05 - 1e-9  # gives up at most the slack
    assert x[0] == pytest.approx(x[1], abs=1e-6) and x[2] > 0.2  # clones share alike; the near-clone joins them
    assert 0.0 < x[3] < 0.1  # the exploited member gets only what the floor leaves
    assert _entropy(x) > _entropy(game.pursuer_mixture)
    y = spread.evader_mixture
    assert (m @ y).max() <= game.value + 0.05 + 1e-9  # the evaders' side concedes at most value + slack
    assert (spread.pursuer_solver, spread.slack, game.slack) == ("maxent", 0.05, None)
    assert (spread.value, spread.exploitability()) == (game.value, game.exploitability())


def test_maxent_is_uniform_when_the_floor_allows_and_holds_its_floor_on_random_games() -> None:
    m = np.array([[0.9, 0.1], [0.5, 0.5]])
    np.testing.assert_allclose(max_entropy(m, 0.0, np.array([0.0, 1.0])), [0.5, 0.5], atol=1e-6)
    rng = np.random.default_rng(1)
    for _ in range(20):
        m = rng.uniform(size=(int(rng.integers(1, 9)), int(rng.integers(1, 9))))
        game = solve([f"p{i}" for i in range(m.shape[0])], [f"e{j}" for j in range(m.shape[1])], m)
        for slack in (1e-4, 0.05, 0.3):
            spread = with_meta_solvers(game, "maxent", "maxent", slack=slack)
            assert (spread.pursuer_mixture @ m).min() >= game.value - slack - 1e-9
            assert (m @ spread.evader_mixture).max() <= game.value + slack + 1e-9
            assert spread.pursuer_mixture.sum() == pytest.approx(1.0) and spread.pursuer_mixture.min() >= 0
            assert _entropy(spread.pursuer_mixture) >= _entropy(game.pursuer_mixture) - 1e-6
    with pytest.raises(ValueError, match="slack"):
        with_meta_solvers(game, "maxent", "nash", slack=0.0)


def test_tournament_writes_the_maxent_mixture_on_request(played: Path, tmp_path: Path, quick: Scenario) -> None:
    out = _tournament(played, tmp_path)
    args = ["tournament", "pure-pursuit", "interceptor", "greedy", "hider", "corner-sitter", "-c", "quick"]
    args += ["-n", "60", "--seeds", "1", "-w", "1", "--out", str(out), "--resume", "--nash"]
    result = runner.invoke(app, [*args, "--mixture", "maxent", "--slack", "0.5"])
    assert result.exit_code == 0, result.output
    assert "most spread mixtures that keep within 0.5" in " ".join(result.stdout.split())
    record = json.loads((out / "nash.json").read_text())
    assert record["solvers"] == {"pursuer": "maxent", "evader": "maxent"} and record["slack"] == 0.5
    assert len(record["pursuer"]) == 2 and len(record["evader"]) == 3  # a slack of 0.5 leaves room for everyone
    assert sorted(resolve_policy(f"nash:{out}", "evader", quick, seed=0).names) == ["corner-sitter", "greedy", "hider"]
    refused = runner.invoke(app, ["tournament", "greedy", "--mixture", "maxent"])
    assert refused.exit_code == 1 and "add --nash" in refused.output
    refused = runner.invoke(app, ["tournament", "greedy", "--nash", "--slack", "0.3"])
    assert refused.exit_code == 1 and "add --mixture maxent" in refused.output


def test_maxent_meets_its_floor_when_the_solver_stops_short(monkeypatch: pytest.MonkeyPatch) -> None:
    import scipy.optimize

    class Stopped:
        x = np.zeros(2)  # multipliers of 0: the uniform mixture, which misses a floor near the value

    monkeypatch.setattr(scipy.optimize, "minimize", lambda *args, **kwargs: Stopped())
    m = np.array([[0.9, 0.8], [0.8, 0.9], [0.1, 0.1]])
    anchor = np.array([0.5, 0.5, 0.0])  # the equilibrium: 0.85 against both
    x = max_entropy(m, 0.8, anchor)
    assert (x @ m).min() >= 0.8 - 1e-12 and x.sum() == pytest.approx(1.0)
    third = np.full(3, 1 / 3)
    t = (x[2] - third[2]) / (anchor[2] - third[2])  # on the segment from the uniform mixture to the anchor
    np.testing.assert_allclose(x, (1 - t) * third + t * anchor)
    with pytest.raises(ValueError, match="anchor misses the floor"):
        max_entropy(m, 0.9, anchor)
