"""Networks trained elsewhere exported as pecli players (pecli.export.network)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch as th
from torch import nn

from pecli.errors import ExportError, PecliError
from pecli.export.network import NetworkPolicy, export_network
from pecli.game.pettingzoo_env import parallel_env
from pecli.match import play_match
from pecli.policies.registry import resolve_policy
from pecli.runtime import read_sidecar
from pecli.scenario import Scenario
from pecli.tournament import pairing_results, player_spec

pytest.importorskip("onnxruntime")


def actor(dim: int, seed: int) -> nn.Module:
    th.manual_seed(seed)
    return nn.Sequential(nn.Linear(dim, 32), nn.Tanh(), nn.Linear(32, 2), nn.Tanh())


@pytest.mark.parametrize("role", ["pursuer", "evader"])
def test_an_exported_network_plays_as_the_network_does(quick: Scenario, tmp_path: Path, role: str) -> None:
    network = actor(parallel_env(quick).observation_space(role).shape[0], seed=1)
    result = export_network(network, role, quick, tmp_path / f"{role}.onnx", algo="mlp", steps=7, run="elsewhere")
    assert result.parity.passed and result.parity.decisions > 0
    sidecar = read_sidecar(result.model)
    assert (sidecar["role"], sidecar["belief"], sidecar["checkpoint"]["algo"]) == (role, "none", "mlp")
    assert sidecar["checkpoint"]["sha256"] is None and sidecar["control"]["frame_stack"] == 1

    # the export by its path, in a match, gives the network's own results
    other = "greedy" if role == "pursuer" else "pure-pursuit"
    players = {role: resolve_policy(str(result.model), role, quick)}
    direct = {role: NetworkPolicy(network, role)}
    for table in (players, direct):
        opponent_role = "evader" if role == "pursuer" else "pursuer"
        table[opponent_role] = resolve_policy(other, opponent_role, quick)
    exported, _ = play_match(quick, players["pursuer"], players["evader"], episodes=16, seed=3)
    own, _ = play_match(quick, direct["pursuer"], direct["evader"], episodes=16, seed=3)
    assert exported.capture_rate == own.capture_rate


def test_the_pettingzoo_observation_is_the_one_the_export_is_fed(quick: Scenario, tmp_path: Path) -> None:
    network = actor(parallel_env(quick).observation_space("pursuer").shape[0], seed=2)
    model = export_network(network, "pursuer", quick, tmp_path / "p.onnx", algo="mlp").model
    exported = resolve_policy(str(model), "pursuer", quick)
    env = parallel_env(quick)
    obs, _ = env.reset(seed=5)
    exported.reset(1)
    for _ in range(20):
        action = exported.act(obs["pursuer"][None])[0]
        with th.no_grad():
            expected = network(th.as_tensor(obs["pursuer"][None])).numpy()[0]
        np.testing.assert_allclose(action, expected, atol=1e-5)
        obs, *_ = env.step({"pursuer": action, "evader": np.zeros(2, dtype=np.float32)})
        if not env.agents:
            break


@pytest.mark.parametrize(
    ("network", "expected"),
    [
        (nn.Linear(5, 2), "does not take observations"),
        (nn.Linear(11, 3), "must return actions (B, 2)"),
    ],
)
def test_a_network_of_the_wrong_shape_is_refused(quick: Scenario, tmp_path: Path, network, expected: str) -> None:
    with pytest.raises(ExportError, match=expected.replace("(", r"\(").replace(")", r"\)")):
        export_network(network, "pursuer", quick, tmp_path / "x.onnx", algo="mlp")
    assert not (tmp_path / "x.onnx").exists()


def test_a_network_with_nan_weights_is_refused(quick: Scenario, tmp_path: Path) -> None:
    network = actor(11, seed=3)
    with th.no_grad():
        network[0].weight[0, 0] = float("nan")
    with pytest.raises(ExportError, match="NaN or infinite"):
        export_network(network, "pursuer", quick, tmp_path / "x.onnx", algo="mlp")


def test_an_exported_network_joins_pairing_results_by_its_path(quick: Scenario, tmp_path: Path, monkeypatch) -> None:
    network = actor(parallel_env(quick).observation_space("pursuer").shape[0], seed=4)
    export_network(network, "pursuer", quick, tmp_path / "peer" / "pursuer.onnx", algo="mlp")
    monkeypatch.chdir(tmp_path)
    results = pairing_results(quick, ["peer/pursuer.onnx"], ["greedy"], 4, [0], tmp_path / "t")
    assert set(results) == {(player_spec("peer/pursuer.onnx"), "greedy")}
    with pytest.raises(PecliError, match="peer/pursuer.onnx cannot play evader in quick"):
        pairing_results(quick, ["pure-pursuit"], ["peer/pursuer.onnx"], 4, [0], tmp_path / "t")  # no evader
