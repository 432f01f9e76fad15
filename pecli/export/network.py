"""A network trained elsewhere (RLlib, TorchRL, BenchMARL, your own code) as a pecli player.

A player trained on pecli's PettingZoo env (:func:`pecli.game.pettingzoo_env.parallel_env`) sees the
same normalised observation each step as pecli's own players. Hand its deterministic actor, a torch
module from observations ``(B, obs_dim)`` float32 to actions ``(B, 2)`` in [-1, 1], to :func:`export_network`:
it writes the same ONNX graph and sidecar as ``pecli export onnx``, so the player joins tournaments,
``pecli play`` and ``pecli exploit`` by its path, and runs on a robot like any export.

    >>> export_network(actor, "pursuer", load_scenario("paper"), "peers/rllib-pursuer.onnx", algo="rllib-ppo")

:class:`NetworkPolicy` plays the module itself in the batched game (no ONNX needed).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch as th
from torch import nn

from pecli import __version__
from pecli.errors import ExportError
from pecli.export.check import check_parity
from pecli.export.exporter import ExportResult, checked_onnx, write_export
from pecli.export.graph import DEFAULT_OPSET, MIN_OPSET, PolicyGraph, max_opset
from pecli.export.sidecar import build_sidecar
from pecli.game.si import SILayout
from pecli.policies.exported import ExportedPolicy
from pecli.roles import Role
from pecli.runtime import ExportedModel
from pecli.scenario import Scenario
from pecli.zoo import CheckpointMeta


class NetworkPolicy:
    """Plays ``network`` (observations ``(n, obs_dim)`` → actions ``(n, 2)``) deterministically, without memory."""

    def __init__(self, network: nn.Module, role: Role) -> None:
        self.network = network.eval()
        self.role = role

    def reset(self, n: int, mask: np.ndarray | None = None, seed: int | None = None) -> None:
        """Nothing to restart: the network sees one observation at a time."""

    def act(self, obs: np.ndarray) -> np.ndarray:
        with th.no_grad():
            action = self.network(th.as_tensor(np.asarray(obs, dtype=np.float32)))
        return np.clip(action.numpy().astype(np.float32), -1.0, 1.0)


def network_meta(
    role: Role, scenario: Scenario, algo: str, run: str, seed: int, steps: int, episodes: int, opponent: str
) -> CheckpointMeta:
    """What the sidecar says of a network trained elsewhere: one frame a decision, every step, no belief."""
    return CheckpointMeta(
        role=role,
        steps=steps,
        episodes=episodes,
        algo=algo,
        belief="none",
        scenario=scenario.name,
        scenario_hash=scenario.fingerprint(),
        opponent=opponent,
        frame_skip=1,
        frame_stack=1,
        history_length=1,
        history_stride=1,
        run=run,
        seed=seed,
    )


def _check_network(network: nn.Module, layout: SILayout) -> None:
    """:class:`ExportError` unless ``network`` maps ``(B, dim)`` observations to finite ``(B, 2)`` actions."""
    broken = [name for name, p in network.named_parameters() if not th.isfinite(p).all()]
    if broken:
        raise ExportError(f"{len(broken)} weight tensors of the network are NaN or infinite (e.g. {broken[0]})")
    try:
        with th.no_grad():
            out = network(th.zeros((3, layout.dim), dtype=th.float32))
    except Exception as exc:  # a network of another input size
        raise ExportError(f"the network does not take observations (B, {layout.dim}): {exc}") from None
    if not isinstance(out, th.Tensor) or tuple(out.shape) != (3, 2):
        shape = tuple(out.shape) if isinstance(out, th.Tensor) else type(out).__name__
        raise ExportError(f"the network must return actions (B, 2), not {shape}")


def export_network(
    network: nn.Module,
    role: Role,
    scenario: Scenario,
    out: str | Path,
    *,
    algo: str,
    run: str = "",
    seed: int = 0,
    steps: int = 0,
    episodes: int = 0,
    opponent: str = "self-play",
    opset: int = DEFAULT_OPSET,
    episodes_checked: int = 8,
) -> ExportResult:
    """Export ``network`` as ``role``'s player of ``scenario`` to ``out`` (``.onnx``) and its sidecar.

    Args:
        network: observations ``(B, obs_dim)`` float32 → actions ``(B, 2)`` in [-1, 1]; on the CPU,
            deterministic, traceable by ``torch.onnx.export``.
        algo, run, seed, steps, episodes, opponent: provenance written to the sidecar (e.g. ``"rllib-ppo"``).
        episodes_checked: games against the role's default opponent replayed through the export (parity).
    """
    out = Path(out)
    if out.suffix.lower() != ".onnx":
        raise ExportError(f"the export must end in .onnx, got '{out.name}'")
    if not MIN_OPSET <= opset <= max_opset():
        raise ExportError(f"the opset must be between {MIN_OPSET} and {max_opset()}, got {opset}")
    layout = SILayout(scenario, role)
    network = network.eval()
    _check_network(network, layout)
    graph = PolicyGraph.of_network(network, layout)
    example = {"obs": th.zeros((2, 1, layout.dim), dtype=th.float64)}
    data = checked_onnx(graph, example, opset, f"a {role} trained elsewhere ({algo}, pecli {__version__})")
    meta = network_meta(role, scenario, algo, run, seed, steps, episodes, opponent)
    sidecar = build_sidecar(graph, scenario, meta, None, opset, draws=0)
    exported = ExportedPolicy(ExportedModel.from_bytes(data, sidecar, source=str(out)), scenario)
    report = check_parity(exported, NetworkPolicy(network, role), scenario, episodes_checked, seed)
    if not report.passed:
        raise ExportError(f"parity check failed against the network: {report.failure()}; nothing written")
    return write_export(out, data, sidecar, report)
