"""ONNX export: every belief kind passes onnx.checker and parity, the runtime plays as the checkpoint does,
units round-trip, an export is a Policy in tournaments, damaged files give one clear line."""

from __future__ import annotations

import json
import math
import re
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import onnx
import pytest
import torch as th
from conftest import all_scenarios
from typer.testing import CliRunner

from pecli.belief import BELIEF_KINDS
from pecli.belief.image import GRID, rasterise
from pecli.belief.mixture import Mixture
from pecli.belief.ukf import WindowUKF
from pecli.belief.window import WindowDecoder
from pecli.cli import app
from pecli.errors import ExportError, PecliError, PolicyError
from pecli.export import check_export, export_checkpoint
from pecli.export.beliefs import KalmanWindow, RasterImage
from pecli.export.encoder import SIEncoder, WindowGeometry
from pecli.game import Game
from pecli.game.memory import HistoryWindow
from pecli.game.observation import ObservationCodec
from pecli.game.si import SILayout
from pecli.policies import resolve_policy
from pecli.policies.exported import ExportedPolicy
from pecli.rl.train import (
    DEFAULT_OPPONENT,
    TrainJob,
    checkpoint_meta,
    make_learner,
    with_overrides,
)
from pecli.roles import Role, opponent_of
from pecli.runtime import Controller, ExportedModel, sidecar_path
from pecli.scenario import Scenario
from pecli.tournament import find_players, run_tournament, schedule
from pecli.zoo import Run

ROOT = Path(__file__).resolve().parents[1]
runner = CliRunner()
TINY = {
    "buffer_size": 500,
    "batch_size": 16,
    "learning_starts": 50,
    "net_arch": [32, 32],
    "belief_settings.hidden": 16,
    "belief_settings.fc": 16,
}


def make_checkpoint(zoo: Path, scenario: Scenario, belief: str, role: Role = "pursuer") -> Path:
    """A tiny checkpoint in a zoo run, trained for a few gradient steps (parity needs no good policy,
    but trained weights are less regular than initial ones)."""
    scenario = with_overrides(scenario, {**TINY, "belief": belief, "n_envs": 4})
    name = f"{belief}-{role}"
    job = TrainJob(role=role, scenario=scenario, opponent=DEFAULT_OPPONENT[role], zoo=zoo, name=name)
    _, model, _ = make_learner(
        job, resolve_policy(job.opponent, opponent_of(role), scenario), seed=0
    )  # nothing to fit yet
    model.learn(80)  # 50 transitions of warm-up, then a few updates
    return Run.create(zoo, name, scenario, {"command": "test"}).save(
        model, role, "final", checkpoint_meta(job, model, 0)
    )


@pytest.fixture(scope="module")
def exports(tmp_path_factory, quick: Scenario) -> dict[str, tuple[Path, Path]]:
    """(checkpoint, export) per belief kind (pursuers), plus an evader without a belief."""
    th.set_num_threads(1)
    zoo = tmp_path_factory.mktemp("zoo")
    made = {}
    for kind in BELIEF_KINDS:
        checkpoint = make_checkpoint(zoo, quick, kind)
        made[kind] = (checkpoint, export_checkpoint(checkpoint, episodes=2).model)
    checkpoint = make_checkpoint(zoo, quick, "none", role="evader")
    made["evader"] = (checkpoint, export_checkpoint(checkpoint, episodes=2).model)
    return made


@pytest.mark.parametrize("kind", BELIEF_KINDS)
def test_every_belief_kind_exports_valid_checked_and_equal(exports, kind: str) -> None:
    checkpoint, model = exports[kind]
    assert model == checkpoint.with_suffix(".onnx") and model.is_file()
    onnx.checker.check_model(onnx.load(str(model)), full_check=True)
    sidecar = json.loads(sidecar_path(model).read_text())
    assert sidecar["role"] == "pursuer" and sidecar["belief"] == kind and sidecar["scenario"]["name"] == "quick"
    assert sidecar["control"]["dt_s"] == 0.1 and sidecar["control"]["rate_hz"] == pytest.approx(10.0)
    assert sidecar["parity"]["passed"] and sidecar["parity"]["max_action_difference"] <= 1e-5
    assert [f["unit"] for f in sidecar["layout"]["row"]] == [
        "m",
        "m",
        "rad",
        "m/s",
        "rad",
        "m",
        "m",
        "m/s",
        "m/s",
        "1",
        "s",
    ]
    assert sidecar["outputs"][0]["fields"] == [
        {"name": "steering_velocity", "unit": "rad/s"},
        {"name": "acceleration", "unit": "m/s^2"},
    ]
    inputs = [i["name"] for i in sidecar["inputs"]]
    assert inputs == ["obs"] + (["history"] if kind != "none" else []) + (
        ["uniform", "normal"] if kind == "bimdn-mixed" else []
    )
    report = check_export(model, checkpoint, episodes=2, seed=5)  # other games than the export's own check
    assert report.passed and report.max_action_difference <= 1e-5 and report.decisions > 0


def test_the_exported_belief_is_the_checkpoints(exports, quick: Scenario) -> None:
    checkpoint, model = exports["bimdn"]
    learned = resolve_policy(str(checkpoint), "pursuer", quick)
    exported = resolve_policy(str(model), "pursuer", quick)
    game = Game(quick, n=3, seed=1)
    obs = game.reset()
    for _ in range(12):
        actions = learned.act(obs["pursuer"])
        exported.act(obs["pursuer"])
        obs = game.step(actions, np.zeros((3, 2))).obs
    for mine, theirs in zip(exported.current_belief(2), learned.current_belief(2)):
        np.testing.assert_allclose(mine, theirs, atol=1e-5)


def test_mixed_draws_follow_the_inverse_cdf() -> None:
    mixture = Mixture(
        th.log(th.tensor([[0.2, 0.5, 0.3]])), th.tensor([[[0.0, 0.0], [1.0, 1.0], [2.0, 2.0]]]), th.full((1, 3, 2), 0.5)
    )
    uniform = th.tensor([[0.0, 0.19, 0.2, 0.69, 0.71, 0.999]])
    draws = mixture.sample_with(uniform, th.ones((1, 6, 2)))
    np.testing.assert_allclose(draws[0, :, 0].numpy(), [0.5, 0.5, 1.5, 1.5, 2.5, 2.5], atol=1e-6)


@pytest.mark.parametrize("scenario", all_scenarios()[:4], ids=lambda s: f"{s.name}-{s.observation_frame}")
def test_the_graphs_ukf_and_rasteriser_match_numpys(scenario: Scenario) -> None:
    """The torch twins of the NumPy beliefs, for a car and a point mass, in both frames, on windows with padding."""
    game = Game(scenario, n=32, seed=2)
    rng = np.random.default_rng(2)
    for role in ("pursuer", "evader"):
        window = HistoryWindow(32, game.obs_dim[role], 200, 10)
        window.reset(game.reset(seed=2)[role])
        for _ in range(120):  # 12 of 20 samples: the oldest are padding
            window.push(game.step(rng.uniform(-1, 1, (32, 2)), rng.uniform(-1, 1, (32, 2))).obs[role])
        history = window.get().copy()
        decoder = WindowDecoder(scenario, role)
        geometry = WindowGeometry(SILayout(scenario, role))
        rows = th.as_tensor(history.reshape(32, 20, -1))
        expected = WindowUKF(decoder)(history)
        _, means, stds = KalmanWindow(geometry, decoder.dt)(rows)
        np.testing.assert_allclose(means.numpy(), expected.means.numpy(), rtol=0, atol=1e-6)
        np.testing.assert_allclose(stds.numpy(), expected.stds.numpy(), rtol=0, atol=1e-6)
        image = RasterImage(geometry, decoder, GRID)(rows).numpy()
        np.testing.assert_array_equal(image, rasterise(decoder(history), decoder))


def test_the_ukf_belief_stays_in_the_arena(paper: Scenario) -> None:
    """A sighting's velocity carried on for 16 s leaves the 16 m arena; the belief's mean stops at the wall."""
    codec = ObservationCodec(paper, "pursuer")
    own = np.zeros((7, 20))
    own[5] = 1.0  # at the centre, facing +x: cos psi = 1
    opp = np.zeros((4, 20))
    opp[0] = np.minimum(1.0 + 1.5 * np.arange(20), 7.9)  # m; the truth stops at the wall
    opp[2] = 1.5  # m/s towards +x
    seen = (np.arange(20) < 4).astype(float)  # seen for the first 4 s, within range
    rows = codec.encode(own, opp, opp[0] - own[0], opp[1] - own[1], seen, np.zeros(20))
    history = rows.reshape(1, -1)
    decoder = WindowDecoder(paper, "pursuer")
    unclamped = 1.0 + 1.5 * 19  # what the constant-velocity filter extrapolates to, m
    assert unclamped / paper.arena.half[0] > 1.5
    mean = WindowUKF(decoder)(history).means[0, 0].numpy()
    np.testing.assert_allclose(mean, [1.0, 0.0], atol=0.02)  # at the wall, not 20 m beyond it
    _, graph_means, _ = KalmanWindow(WindowGeometry(SILayout(paper, "pursuer")), decoder.dt)(th.as_tensor(rows[None]))
    np.testing.assert_allclose(graph_means[0, 0].numpy(), mean, atol=1e-6)


@pytest.mark.parametrize("scenario", all_scenarios(), ids=lambda s: f"{s.name}-{s.observation_frame}")
def test_units_round_trip(scenario: Scenario) -> None:
    """SI rows from the game's true state normalise to the game's observations, in NumPy and in the graph's
    encoder; normalised observations go to SI and back."""
    game = Game(scenario, n=64, seed=3)
    obs = game.reset()
    rng = np.random.default_rng(0)
    for _ in range(30):
        obs = game.step(rng.uniform(-1, 1, (64, 2)), rng.uniform(-1, 1, (64, 2))).obs
    state, seen = game.state(), game.seen()
    k = game.dynamics["pursuer"].state_dim
    for role, own, opp in (("pursuer", state[:, :k], state[:, k:]), ("evader", state[:, k:], state[:, :k])):
        layout = SILayout(scenario, role)
        si = np.column_stack(
            [own, np.where(seen[role][:, None], opp, 0.0), np.where(seen[role], 1.0, -1.0), game.t * scenario.dt]
        )
        si = np.concatenate([si, np.zeros((1, layout.dim))])  # a padding row stays zero
        expected = np.concatenate([obs[role], np.zeros((1, layout.dim), np.float32)])
        np.testing.assert_allclose(layout.from_si(si), expected, rtol=0, atol=1e-6)
        encoded = SIEncoder(layout)(th.as_tensor(si)).numpy()
        np.testing.assert_allclose(encoded, expected, rtol=0, atol=1e-6)
        np.testing.assert_allclose(layout.from_si(layout.to_si(obs[role])), obs[role], rtol=0, atol=1e-6)
        back = layout.to_si(obs[role])
        np.testing.assert_allclose(back[:, : layout.k], own, atol=1e-4)  # float32 observations: about 1e-6 relative
        if layout.opp.has_heading and scenario.observation_frame == "own":
            opp = opp.copy()
            opp[:, 2] = 0.0  # the own frame does not observe a car opponent's steering angle
        np.testing.assert_allclose(back[seen[role], layout.k : layout.k + layout.m], opp[seen[role]], atol=1e-4)
    car = SILayout(scenario, "pursuer")
    if car.own.has_heading:  # headings outside [-pi, pi) are wrapped, in NumPy and in the graph
        si = car.to_si(obs["pursuer"][:4])
        turned = si.copy()
        turned[:, 4] += 2 * math.pi
        np.testing.assert_allclose(car.from_si(turned), car.from_si(si), atol=1e-6)
        np.testing.assert_allclose(SIEncoder(car)(th.as_tensor(turned)).numpy(), car.from_si(si), atol=1e-6)


def record_game(
    scenario: Scenario, policy, seed: int, steps: int = 60
) -> tuple[list[np.ndarray], list[np.ndarray], list]:
    """One game of ``policy`` (a pursuer) against greedy: SI states, actions, and the pursuer's sensor verdicts."""
    game = Game(scenario, n=1, seed=seed)
    obs = game.reset(seed=seed)
    greedy = resolve_policy("greedy", "evader", scenario)
    policy.reset(1, seed=seed)
    greedy.reset(1, seed=seed)
    states, actions, seen = [], [], []
    for _ in range(steps):
        states.append(game.state()[0])
        seen.append(bool(game.seen()["pursuer"][0]))
        actions.append(policy.act(obs["pursuer"])[0])
        result = game.step(actions[-1][None], greedy.act(obs["evader"]))
        obs = result.obs
        if result.done[0]:
            break
    return states, actions, seen


@pytest.mark.parametrize("kind", ["bimdn-mixed", "ukf"])
def test_runtime_plays_a_recorded_game_as_the_checkpoint_and_the_export(exports, quick: Scenario, kind: str) -> None:
    checkpoint, model = exports[kind]
    states, actions, seen = record_game(quick, resolve_policy(str(checkpoint), "pursuer", quick), seed=4)
    exported = resolve_policy(str(model), "pursuer", quick)
    replayed = record_game(quick, exported, seed=4)[1]
    controller = Controller.load(model, seed=4)
    k = SILayout(quick, "pursuer").k
    limits = controller.model.limits
    for state, action, again, verdict in zip(states, actions, replayed, seen):
        assert controller.model.sees(state[:k], state[k:]) == verdict
        command = controller.step(state[:k], state[k:])
        np.testing.assert_allclose(command / limits, action, rtol=0, atol=1e-5)
        np.testing.assert_allclose(again, action, rtol=0, atol=1e-5)
    assert len(states) > 20 and any(seen) and not all(seen)
    controller.reset()
    assert controller.ticks == 0 and not controller.window().any()


def test_runtime_memory_matches_the_simulations_over_long_games(exports, quick: Scenario) -> None:
    """Past the window's 200 ticks (the ring wraps) and across a restart, the runtime's window and frame
    stack give the commands that the batched policy's (pecli.game.memory) give."""
    _, model = exports["bimdn"]
    layout = SILayout(quick, "pursuer")
    controller = Controller.load(model)
    policy = resolve_policy(str(model), "pursuer", quick)
    policy.reset(1)
    rng = np.random.default_rng(7)
    half = np.array(quick.arena.half)
    for tick in range(450):
        if tick == 300:
            controller.reset()
            policy.reset(1, mask=np.array([True]))
        t = tick if tick < 300 else tick - 300
        own = np.array([*rng.uniform(-half, half), rng.uniform(-0.3, 0.3), rng.uniform(-1, 2.5), rng.uniform(-3, 3)])
        opp = np.array([*rng.uniform(-half, half), *rng.uniform(-1.5, 1.5, 2)])
        seen = bool(rng.random() < 0.5)
        command = controller.step(own, opp, seen=seen, time=t * quick.dt)
        row = np.concatenate([own, opp if seen else np.zeros(4), [1.0 if seen else -1.0, t * quick.dt]])
        policy.act(layout.from_si(row[None]))
        np.testing.assert_allclose(command, policy.command[0], rtol=0, atol=1e-5, err_msg=f"tick {tick}")


def test_runtime_needs_neither_torch_nor_the_simulator(exports, tmp_path: Path) -> None:
    _, model = exports["bimdn"]
    blocked = [
        "torch",
        "stable_baselines3",
        "sb3_contrib",
        "gymnasium",
        "pettingzoo",
        "pydantic",
        "yaml",
        "scipy",
        "filterpy",
        "matplotlib",
        "typer",
        "rich",
        "onnx",
        "pecli.game",
        "pecli.scenario",
        "pecli.policies",
    ]
    script = textwrap.dedent(f"""
        import importlib.abc, sys
        BLOCKED = {blocked!r}
        class Block(importlib.abc.MetaPathFinder):
            def find_spec(self, name, path=None, target=None):
                if any(name == b or name.startswith(b + ".") for b in BLOCKED):
                    raise ImportError("blocked: " + name)
        sys.meta_path.insert(0, Block())
        from pecli.runtime import Controller
        controller = Controller.load({str(model)!r}, seed=0)
        command = controller.step([1.0, 0.5, 0.0, 0.3, 0.2], [2.0, 1.0, 0.5, -0.2])
        assert command.shape == (2,) and abs(command[0]) <= 3.2 and controller.belief()[1].shape == (3, 2)
        print("ok", sorted(m for m in BLOCKED if m in sys.modules))
        ours = sorted(m for m in sys.modules if m == "pecli" or m.startswith("pecli."))
        outside = sorted({{m.split(".")[0] for m in sys.modules}} - set(sys.stdlib_module_names)
                         - {{"numpy", "onnxruntime", "pecli", "cython_runtime"}}
                         - {{m.split(".")[0] for m in sys.builtin_module_names}})
        print("pecli", ours)
        print("others", [m for m in outside if not m.startswith("_")])
    """)
    result = subprocess.run(
        [sys.executable, "-c", script],
        capture_output=True,
        text=True,
        cwd=tmp_path,
        env={"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin"},
        timeout=60,
    )
    assert result.returncode == 0, result.stderr
    lines = result.stdout.strip().splitlines()
    assert lines[0] == "ok []"
    assert (
        lines[1] == "pecli ['pecli', 'pecli.errors', 'pecli.onnx_guard', 'pecli.runtime']"
    )  # what docs/export.md says to copy
    assert lines[2] == "others []", lines[2]  # nothing beyond the standard library, NumPy and ONNX Runtime


def test_a_tournament_of_a_checkpoint_and_its_export_gives_the_same_results(
    exports, quick: Scenario, tmp_path: Path
) -> None:
    """An evader without a belief and a pursuer with a mixed belief (its draws seeded by the match), each
    entered twice: as the checkpoint and as its export."""
    paths = [str(path) for key in ("evader", "bimdn-mixed") for path in exports[key]]
    found = find_players(paths, quick, baselines=True)
    results = run_tournament(quick, found.players, schedule(found.players), episodes=6, seeds=[0, 1], out=tmp_path)
    grid = {pair: (r.captures, r.time_to_capture_mean, r.time_to_capture_std) for pair, r in results.grid().items()}
    for role, name in (("evader", "none-evader/evader/final"), ("pursuer", "bimdn-mixed-pursuer/pursuer/final")):
        others = [p.name for p in found.players[opponent_of(role)]]
        for other in others:
            pair, twin = (
                ((other, name), (other, name + ".onnx"))
                if role == "evader"
                else ((name, other), (name + ".onnx", other))
            )
            assert grid[pair] == grid[twin], (pair, grid[pair], grid[twin])
        outcomes = [grid[(other, name) if role == "evader" else (name, other)][0] for other in others]
        assert 0 < sum(outcomes) < 12 * len(others)  # captures and escapes: the players' moves decide
    ratings = {r.name: (r.elo, r.stderr) for r in results.ratings}
    for name in ("none-evader/evader/final", "bimdn-mixed-pursuer/pursuer/final"):
        assert ratings[name] == pytest.approx(ratings[name + ".onnx"], rel=1e-9)  # the same games, one fit


def test_export_cli_writes_the_model_and_checks_it(exports, tmp_path: Path) -> None:
    checkpoint, _ = exports["none"]
    out = tmp_path / "robot" / "pursuer.onnx"
    result = runner.invoke(app, ["export", "onnx", str(checkpoint), "--out", str(out), "-n", "2", "--json"])
    assert result.exit_code == 0, result.output
    report = json.loads(result.stdout)
    assert report["parity"]["passed"] and Path(report["model"]) == out and report["bytes"] == out.stat().st_size
    assert sorted(p.name for p in out.parent.iterdir()) == ["pursuer.onnx", "pursuer.onnx.json"]  # no temporaries
    result = runner.invoke(app, ["export", "check", str(out), str(checkpoint), "-n", "2"])
    assert result.exit_code == 0 and "ok" in result.output
    result = runner.invoke(app, ["play", "-p", str(out), "-c", "quick", "-n", "4", "--json"])
    assert result.exit_code == 0 and json.loads(result.stdout)["episodes"] == 4


def test_an_export_that_fails_parity_is_not_written(exports, tmp_path: Path, monkeypatch) -> None:
    checkpoint, model = exports["none"]
    original = ExportedPolicy._decide
    monkeypatch.setattr(ExportedPolicy, "_decide", lambda self, *args: original(self, *args) + 1e-4)
    out = tmp_path / "off.onnx"
    result = runner.invoke(app, ["export", "onnx", str(checkpoint), "--out", str(out), "-n", "1"])
    assert result.exit_code == 1 and "parity check failed" in result.output and "nothing written" in result.output
    assert not list(tmp_path.iterdir())
    result = runner.invoke(app, ["export", "check", str(model), str(checkpoint), "-n", "1"])
    assert result.exit_code == 1 and "FAILED" in result.output and "parity check failed" in result.output


def test_missing_or_damaged_models_give_one_clear_line(
    exports, tmp_path: Path, quick: Scenario, paper: Scenario
) -> None:
    checkpoint, model = exports["none"]
    copy = tmp_path / "m.onnx"

    def fresh() -> None:
        copy.write_bytes(model.read_bytes())
        sidecar_path(copy).write_text(sidecar_path(model).read_text())

    cases = []
    cases.append(("no exported model at", lambda: None))
    cases.append(("no sidecar m.onnx.json", lambda: (fresh(), sidecar_path(copy).unlink())))
    cases.append(("damaged sidecar", lambda: (fresh(), sidecar_path(copy).write_text("{not json"))))
    cases.append(("does not match its sidecar", lambda: (fresh(), copy.write_bytes(model.read_bytes()[:-100]))))

    def garbage() -> None:
        fresh()
        copy.write_bytes(b"not an onnx graph")
        data = json.loads(sidecar_path(copy).read_text())
        import hashlib

        data["model_sha256"] = hashlib.sha256(b"not an onnx graph").hexdigest()
        sidecar_path(copy).write_text(json.dumps(data))

    cases.append(("not an ONNX model", garbage))

    def zero_skip() -> None:
        fresh()
        data = json.loads(sidecar_path(copy).read_text())
        data["control"]["frame_skip"] = 0
        sidecar_path(copy).write_text(json.dumps(data))

    cases.append(("damaged sidecar: frame_skip = 0", zero_skip))

    def no_layout() -> None:
        fresh()
        data = json.loads(sidecar_path(copy).read_text())
        del data["layout"]
        sidecar_path(copy).write_text(json.dumps(data))

    cases.append((r"m.onnx: incomplete sidecar \(no 'layout'\)", no_layout))

    def edited(change: dict) -> None:
        fresh()
        data = json.loads(sidecar_path(copy).read_text())
        for key, value in change.items():
            *parents, last = key.split(".")
            part = data
            for name in parents:
                part = part[name]
            part[last] = value
        sidecar_path(copy).write_text(json.dumps(data))

    for change, message in (
        ({"command_limits": [float("nan"), 2.0]}, r"command_limits = \[nan, 2.0\], not two positive numbers"),
        ({"sensor.fov_rad": float("inf")}, "sensor.fov_rad = inf, not a positive number"),
        ({"role": ["pursuer"]}, r"role = \['pursuer'\], not a string"),
        ({"layout.own_heading": "no"}, "layout.own_heading is not true or false"),
        ({"control.history_length": 10**40}, r"history_length = 1000000000000000000000000000000000000\.\.\."),
    ):
        cases.append((f"m.onnx: damaged sidecar: {message}", lambda change=change: edited(change)))
    cases.append(
        (r"not a pecli sidecar of format .* \(no 'format'\)", lambda: (fresh(), sidecar_path(copy).write_text("{}")))
    )
    for message, damage in cases:
        copy.unlink(missing_ok=True)
        damage()
        with pytest.raises(ExportError, match=message):
            ExportedModel.load(copy)
        as_policy = "policy file not found" if message.startswith("no exported model") else message
        with pytest.raises(PolicyError, match=as_policy):
            resolve_policy(str(copy), "pursuer", quick)
        result = runner.invoke(app, ["play", "-p", str(copy), "-c", "quick"])
        assert result.exit_code == 1 and re.search(as_policy, result.output) and "Traceback" not in result.output
    fresh()
    graph = onnx.load(model)
    graph.graph.output[0].name = "renamed"  # its command: only an output of that name is read
    for node in graph.graph.node:
        node.output[:] = ["renamed" if name == "command" else name for name in node.output]
    with pytest.raises(ExportError, match=r"m.onnx: the graph has no output 'command' \(its outputs: "):
        ExportedModel.from_bytes(
            graph.SerializeToString(), json.loads(sidecar_path(copy).read_text()), source=str(copy)
        )
    policy = resolve_policy(str(model), "pursuer", quick)
    policy.model.run = lambda *args: {"command": np.zeros((1, 2)), "action": np.zeros((1, 2))}
    with pytest.raises(PolicyError, match=r"its graph answered actions of shape \(1, 2\), not \(2, 2\)"):
        game = Game(quick, n=2)
        game.reset(seed=0)
        policy.act(game.observe()["pursuer"])
    copy.write_bytes(model.read_bytes()[:-100])
    with pytest.raises(PecliError, match="does not match its sidecar"):  # named in a tournament
        find_players([str(copy)], quick)
    with pytest.raises(PolicyError, match="exported pursuer; it cannot play evader"):
        resolve_policy(str(model), "evader", quick)
    with pytest.raises(PolicyError, match="exported for scenario 'quick'"):
        resolve_policy(str(model), "pursuer", paper)
    for args, message in (
        (["export", "onnx", str(tmp_path / "nope.zip")], "no checkpoint at"),
        (["export", "onnx", str(checkpoint), "--out", str(tmp_path / "x.txt"), "-n", "1"], "must end in .onnx"),
        (["export", "onnx", str(checkpoint), "--opset", "3", "-n", "1"], "--opset must be between 13 and"),
        (["export", "check", str(model), str(exports["bimdn"][0])], "exported from another checkpoint"),
        (["export", "check", str(tmp_path / "nope.onnx"), str(checkpoint)], "no exported model at"),
    ):
        result = runner.invoke(app, args)
        assert result.exit_code == 1 and message in result.output and "Traceback" not in result.output, result.output


def test_robots_config_trains_then_exports(tmp_path: Path) -> None:
    """configs/robots.yaml end to end: F1TENTH vs JetRacer, car vs car in the own frame, with a BiMDN."""
    zoo = tmp_path / "zoo"
    train = [
        "train",
        "pursuer",
        "--config",
        str(ROOT / "configs" / "robots.yaml"),
        "--zoo",
        str(zoo),
        "--name",
        "r",
        "-q",
        "--steps",
        "240",
        "--belief",
        "bimdn",
        "--set",
        "learning_starts=80",
        "--set",
        "batch_size=16",
        "--set",
        "n_envs=4",
        "--set",
        "net_arch=[32, 32]",
        "--set",
        "belief_settings.hidden=16",
        "--set",
        "belief_settings.warmup=80",
        "--set",
        "belief_settings.batch_size=16",
    ]
    result = runner.invoke(app, train)
    assert result.exit_code == 0, result.output
    result = runner.invoke(app, ["export", "onnx", str(zoo / "r" / "pursuer" / "final.zip"), "-n", "2", "--json"])
    assert result.exit_code == 0, result.output
    sidecar = json.loads(sidecar_path(zoo / "r" / "pursuer" / "final.onnx").read_text())
    assert sidecar["scenario"]["name"] == "robots" and sidecar["sensor"]["range_m"] == 5.0
    assert sidecar["sensor"]["fov_rad"] == pytest.approx(1.5 * math.pi) and sidecar["layout"]["dim"] == 12
    assert sidecar["command_limits"] == [3.2, 2.0]


def test_the_ros2_example_is_valid_python() -> None:
    source = (ROOT / "examples" / "ros2_node.py").read_text()
    compile(source, "ros2_node.py", "exec")
    assert "from pecli.runtime import Controller" in source and "create_timer" in source


def test_a_large_batch_runs_in_chunks_with_the_same_answers(exports, monkeypatch) -> None:
    import pecli.runtime

    _, model = exports["bimdn"]
    loaded = ExportedModel.load(model)
    rng = np.random.default_rng(0)
    obs = rng.normal(size=(7, loaded.frame_stack, loaded.dim))
    history = rng.normal(size=(7, loaded.window, loaded.dim))
    whole = loaded.run(obs, history)
    monkeypatch.setattr(pecli.runtime, "RUN_CHUNK", 3)  # 3 + 3 + 1 games
    chunked = loaded.run(obs, history)
    assert whole.keys() == chunked.keys()
    for name in whole:
        np.testing.assert_allclose(chunked[name], whole[name], rtol=1e-6, atol=1e-6)


def test_a_graph_that_asks_for_memory_at_run_time_fails_in_one_line(exports) -> None:
    """Sizes computed at run time from the input's shape pass the graph check (an export's own are so computed);
    the arena's cap refuses the allocation of a graph that joins large constants to them."""
    from onnx import TensorProto, helper, numpy_helper

    _, model = exports["none"]
    graph = onnx.load(model)
    graph.graph.initializer.extend(numpy_helper.from_array(np.array([n], np.int64), f"big{n}") for n in (4096, 8192))
    graph.graph.node.extend(
        [
            helper.make_node("Shape", ["obs"], ["obs_shape"]),
            helper.make_node("Concat", ["obs_shape", "big4096", "big8192"], ["huge_shape"], axis=0),
            helper.make_node("ConstantOfShape", ["huge_shape"], ["huge"]),
            helper.make_node("ReduceSum", ["huge"], ["huge_sum"], keepdims=0),
        ]
    )
    graph.graph.output.append(helper.make_tensor_value_info("huge_sum", TensorProto.FLOAT, None))
    loaded = ExportedModel.from_bytes(graph.SerializeToString(), json.loads(sidecar_path(model).read_text()))
    with pytest.raises(ExportError, match=r"it asked for [\d,]+ bytes, more than exported graphs may hold") as failed:
        loaded.run(np.zeros((1, loaded.frame_stack, loaded.dim)))
    assert "\n" not in str(failed.value)


def test_exported_policies_are_policies(exports, quick: Scenario) -> None:
    _, model = exports["none"]
    policy = resolve_policy(str(model), "pursuer", quick)
    assert isinstance(policy, ExportedPolicy)
    policy.reset(3)
    actions = policy.act(np.zeros((3, 11), dtype=np.float32))
    assert actions.shape == (3, 2) and np.all(np.abs(actions) <= 1)
    np.testing.assert_allclose(policy.command, actions * policy.model.limits, rtol=1e-6)


# -- never export or command a broken policy ---------------------------------------------------------------
def poisoned_copy(checkpoint: Path, name: str) -> Path:
    """A copy of ``checkpoint`` beside it whose actor's first layer is NaN (what a diverged training leaves)."""
    import io
    import shutil
    import zipfile

    out = checkpoint.with_name(f"{name}.zip")
    with zipfile.ZipFile(checkpoint) as source, zipfile.ZipFile(out, "w") as copy:
        for entry in source.infolist():
            data = source.read(entry)
            if entry.filename == "policy.pth":
                weights = th.load(io.BytesIO(data), weights_only=True)
                weights["actor.mu.0.weight"].fill_(math.nan)
                buffer = io.BytesIO()
                th.save(weights, buffer)
                data = buffer.getvalue()
            copy.writestr(entry, data)
    shutil.copy(checkpoint.with_suffix(".json"), out.with_suffix(".json"))
    return out


@pytest.fixture(scope="module")
def broken(exports, quick: Scenario) -> dict:
    """The 'none' pursuer's checkpoint, a copy of it with NaN weights in its run, and that network as an ONNX graph
    (loaded past the graph check, which refuses its NaN constants: what the runtime does with NaN is checked too)."""
    import onnxruntime as ort

    from pecli.export.exporter import onnx_bytes
    from pecli.export.sidecar import build_sidecar
    from pecli.policies.learned import LearnedPolicy

    checkpoint, _ = exports["none"]
    diverged = poisoned_copy(checkpoint, "diverged")
    learned = LearnedPolicy.load(checkpoint, "pursuer", quick)
    with th.no_grad():
        learned.actor.mu[0].weight.fill_(math.nan)
    graph, data = onnx_bytes(learned, SILayout(quick, "pursuer"), 17)
    sidecar = build_sidecar(graph, quick, learned.meta, checkpoint, 17, learned.draws)
    with pytest.raises(ExportError, match="NaN or infinite values"):
        ExportedModel.from_bytes(data, sidecar)
    session = ort.InferenceSession(data, providers=["CPUExecutionProvider"])
    return {"checkpoint": checkpoint, "diverged": diverged, "model": ExportedModel(session, sidecar)}


def test_a_network_with_nan_weights_is_not_exported(broken) -> None:
    diverged = broken["diverged"]
    result = runner.invoke(app, ["export", "onnx", str(diverged), "-n", "1"])
    assert result.exit_code == 1 and "damaged policy weights" in result.output and "NaN or infinite" in result.output
    assert len(result.output.strip().splitlines()) == 1
    assert not diverged.with_suffix(".onnx").exists()


def test_parity_fails_when_either_side_is_not_finite(broken, quick: Scenario) -> None:
    """NaN - NaN is NaN and max(0.0, NaN) is 0.0: a NaN export used to pass with a difference of 0."""
    from pecli.export.check import check_parity

    healthy = resolve_policy(str(broken["checkpoint"]), "pursuer", quick)
    report = check_parity(ExportedPolicy(broken["model"], quick), healthy, quick, episodes=2)
    assert not report.passed and report.non_finite > 0 and "NaN or infinite" in report.failure()
    assert math.isfinite(report.max_action_difference) and json.dumps(report.to_dict(), allow_nan=False)


def test_the_runtime_never_returns_a_nan_command(broken) -> None:
    controller = Controller(broken["model"], seed=0)
    with pytest.raises(ExportError, match="never sent to the motors"):
        controller.step(np.zeros(5), np.array([1.0, 1.0, 0.0, 0.0]))


@pytest.mark.parametrize(
    ("edit", "expected"),
    [
        (lambda s: s["sensor"].update(fov_rad=1.0), r"sensor\.fov_rad is 1\.0, not 2\.09"),
        (lambda s: s.update(command_limits=[9.0, 2.0]), r"command_limits\[0\] is 9\.0, not 3\.2"),
        (
            lambda s: s["scenario"].update(fingerprint="0123456789abcdef"),
            r"scenario\.fingerprint is '0123456789abcdef'",
        ),
        (lambda s: s["control"].update(dt_s=0.05), r"control\.dt_s is 0\.05, not 0\.1"),
        (lambda s: s["scenario"]["config"]["pursuer"]["sensor"].update(range=9.0), "the sidecar was edited"),
    ],
)
def test_export_check_refuses_an_edited_sidecar(exports, tmp_path: Path, edit, expected: str) -> None:
    checkpoint, model = exports["none"]
    copy = tmp_path / "m.onnx"
    copy.write_bytes(model.read_bytes())
    sidecar = json.loads(sidecar_path(model).read_text())
    edit(sidecar)
    sidecar_path(copy).write_text(json.dumps(sidecar))
    result = runner.invoke(app, ["export", "check", str(copy), str(checkpoint), "-n", "1"])
    assert result.exit_code == 1 and len(result.output.strip().splitlines()) == 1, result.output
    assert re.search(expected, result.output.replace("\n", "")), result.output


def test_the_runtime_refuses_a_time_that_is_not_a_number(exports) -> None:
    """A NaN time is the caller's mistake, named as such, not a NaN command blamed on the model."""
    controller = Controller.load(exports["none"][1])
    with pytest.raises(ValueError, match="time must be a finite number"):
        controller.step(np.zeros(5), np.array([1.0, 1.0, 0.0, 0.0]), seen=True, time=float("nan"))


def test_a_mixed_controller_plays_each_game_by_one_member(exports) -> None:
    from pecli.runtime import MixedController

    models = [exports["none"][1], exports["bimdn"][1]]
    mixture = MixedController.load(models, seed=3)
    own, opponent = np.zeros(5), np.array([1.0, 1.0, 0.0, 0.0])
    drawn = set()
    for _game in range(12):
        mixture.reset()
        drawn.add(mixture.member)
        alone = Controller.load(models[mixture.member])  # the member alone, from the same start
        for _ in range(3):
            assert np.array_equal(mixture.step(own, opponent), alone.step(own, opponent))
    assert drawn == {0, 1}
    weighed = MixedController.load(models, seed=3, weights=[3, 1])  # as mix:A@3,B: A in three games of four
    assert sum(weighed.reset() or weighed.member == 0 for _ in range(400)) in range(270, 331)
    with pytest.raises(ExportError, match="non-negative numbers"):
        MixedController.load(models, weights=[1, float("nan")])
    with pytest.raises(ExportError, match="one role of one game"):
        MixedController.load([exports["none"][1], exports["evader"][1]])


@pytest.mark.parametrize("key, value", [("history_length", 10**12), ("frame_stack", 10**9), ("dt_s", 1e300)])
def test_a_sidecar_claiming_a_huge_window_is_refused_before_allocating(
    exports, tmp_path: Path, key: str, value: float
) -> None:
    model = exports["none"][1]
    copy = tmp_path / "m.onnx"
    copy.write_bytes(model.read_bytes())
    sidecar = json.loads(sidecar_path(model).read_text())
    sidecar["control"][key] = value
    sidecar_path(copy).write_text(json.dumps(sidecar))
    with pytest.raises(ExportError, match=f"damaged sidecar: {key} = "):
        Controller.load(copy)
