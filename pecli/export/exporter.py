"""``pecli export onnx``: a checkpoint to one ONNX graph and its sidecar, checked before it is written.

Steps: load the checkpoint as a :class:`LearnedPolicy`; build its :class:`PolicyGraph` and trace it
to ONNX; validate with ``onnx.checker`` (full check, shapes included); load the graph in ONNX
Runtime and replay recorded games through it and the checkpoint (:mod:`pecli.export.check`); only
if the largest action difference is within tolerance write ``MODEL.onnx`` and ``MODEL.onnx.json``,
each atomically (the model first; the sidecar holds the model's hash, so a mismatched pair is refused).
"""

from __future__ import annotations

import hashlib
import importlib.util
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import torch as th

from pecli import __version__
from pecli.errors import ExportError
from pecli.export.check import ParityReport, check_parity
from pecli.export.graph import DEFAULT_OPSET, MIN_OPSET, PolicyGraph, max_opset, to_onnx
from pecli.export.sidecar import build_sidecar, sidecar_differences
from pecli.game.si import SILayout
from pecli.io import atomic_path, atomic_write_json
from pecli.policies.exported import ExportedPolicy, exported_scenario
from pecli.policies.learned import LearnedPolicy
from pecli.runtime import ExportedModel, file_sha256, sidecar_path
from pecli.scenario import Scenario
from pecli.zoo import CONFIG_FILE, read_metadata, run_of


@dataclass(frozen=True)
class ExportResult:
    """What an export wrote and how it checked."""

    model: Path
    sidecar: Path
    size: int  # bytes of the .onnx file
    parity: ParityReport


def checkpoint_scenario(checkpoint: Path) -> Scenario:
    """The scenario a zoo checkpoint was trained on: its run's ``config.yaml`` (``<run>/<role>/<name>.zip``)."""
    run = run_of(checkpoint.resolve())
    if run is None:
        folder = checkpoint.resolve().parent.parent
        raise ExportError(f"{checkpoint} is not inside a zoo run (no {folder / CONFIG_FILE}): pass --config")
    return run.scenario()


def example_inputs(layout: SILayout, learned: LearnedPolicy, batch: int = 2) -> dict[str, th.Tensor]:
    """Inputs to trace the graph with (values do not matter: the graph has no data-dependent branches)."""
    window = -(-learned.history_length // learned.history_stride) if learned.history_length else 0
    return {
        "obs": th.zeros((batch, learned.frame_stack, layout.dim), dtype=th.float64),
        "history": th.zeros((batch, window, layout.dim), dtype=th.float64),
        "uniform": th.full((batch, learned.draws), 0.5),
        "normal": th.zeros((batch, learned.draws, 2)),
    }


NEEDS_ONNX = "pecli export needs onnx and onnxruntime: pip install onnx onnxruntime (pecli's export extra)"


def export_available() -> bool:
    """Whether ``onnx`` and ``onnxruntime``, which exporting and its parity check need, are installed."""
    return all(importlib.util.find_spec(name) is not None for name in ("onnx", "onnxruntime"))


def require_finite(learned: LearnedPolicy, checkpoint: Path) -> None:
    """:class:`ExportError` when the actor (belief included) holds a NaN or an infinity: it would command NaN."""
    broken = [name for name, p in learned.actor.named_parameters() if not th.isfinite(p).all()]
    if broken:
        raise ExportError(
            f"{checkpoint}: {len(broken)} weight tensors of the network are NaN or infinite "
            f"(e.g. {broken[0]}): a broken policy is not exported (its training diverged)"
        )


def checked_onnx(graph: PolicyGraph, example: dict[str, th.Tensor], opset: int, description: str) -> bytes:
    """``graph`` traced to ONNX, validated by ``onnx.checker`` and labelled with ``description``."""
    try:
        import onnx
    except ImportError:
        raise ExportError(NEEDS_ONNX) from None

    try:
        data = to_onnx(graph, example, opset)
    except Exception as exc:  # an opset the exporter does not support, an operator it cannot write
        raise ExportError(f"cannot export to ONNX opset {opset}: {type(exc).__name__}: {exc}") from None
    model = onnx.load_from_string(data)
    try:
        onnx.checker.check_model(model, full_check=True)
    except (onnx.checker.ValidationError, onnx.shape_inference.InferenceError) as exc:
        raise ExportError(f"the exported graph fails onnx.checker: {exc}") from None
    model.producer_name, model.producer_version = "pecli", __version__
    model.doc_string = f"{description}: SI state estimates in, SI command out; see the sidecar .onnx.json"
    return model.SerializeToString()


def onnx_bytes(learned: LearnedPolicy, layout: SILayout, opset: int) -> tuple[PolicyGraph, bytes]:
    """The checkpoint's graph traced to ONNX, validated by ``onnx.checker`` and labelled."""
    graph = PolicyGraph(learned.actor, layout)
    description = f"pecli {learned.role} ({learned.meta.belief} belief)"
    return graph, checked_onnx(graph, example_inputs(layout, learned), opset, description)


def write_export(out: Path, data: bytes, sidecar: dict[str, Any], parity: ParityReport) -> ExportResult:
    """Write the model, then its sidecar with the model's hash and the parity report, each atomically."""
    out.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(out) as tmp:
        tmp.write_bytes(data)
    sidecar.update(model_sha256=hashlib.sha256(data).hexdigest(), parity=parity.to_dict())
    atomic_write_json(sidecar_path(out), sidecar)
    return ExportResult(model=out, sidecar=sidecar_path(out), size=len(data), parity=parity)


def export_checkpoint(
    checkpoint: str | Path,
    out: str | Path | None = None,
    scenario: Scenario | None = None,
    opset: int = DEFAULT_OPSET,
    episodes: int = 8,
    seed: int = 0,
) -> ExportResult:
    """Export ``checkpoint`` to ``out`` (default: beside it, ``.onnx``) after checking parity.

    Args:
        checkpoint: a zoo checkpoint (``.zip`` with its metadata).
        out: the model file; its sidecar is ``out`` + ``.json``.
        scenario: the scenario it was trained on (default: its run's ``config.yaml``).
        opset: the ONNX opset.
        episodes, seed: the recorded games of the parity check.
    """
    checkpoint = Path(checkpoint)
    if not checkpoint.is_file():
        raise ExportError(f"no checkpoint at {checkpoint}")
    if not MIN_OPSET <= opset <= max_opset():
        raise ExportError(f"--opset must be between {MIN_OPSET} and {max_opset()}, got {opset}")
    out = Path(out) if out is not None else checkpoint.with_suffix(".onnx")
    if out.suffix.lower() != ".onnx":
        raise ExportError(f"--out must end in .onnx, got '{out.name}'")
    meta = read_metadata(checkpoint)
    scenario = scenario or checkpoint_scenario(checkpoint)
    learned = LearnedPolicy.load(checkpoint, meta.role, scenario)
    require_finite(learned, checkpoint)
    layout = SILayout(scenario, meta.role)
    graph, data = onnx_bytes(learned, layout, opset)
    sidecar = build_sidecar(graph, scenario, meta, checkpoint, opset, learned.draws)
    exported = ExportedPolicy(ExportedModel.from_bytes(data, sidecar, source=str(out)), scenario)
    report = check_parity(exported, learned, scenario, episodes, seed)
    if not report.passed:
        raise ExportError(f"parity check failed against the checkpoint: {report.failure()}; nothing written")
    return write_export(out, data, sidecar, report)


def check_export(
    model: str | Path, checkpoint: str | Path, episodes: int = 8, seed: int = 0, opponent: str | None = None
) -> ParityReport:
    """``pecli export check``: replay recorded games through ``model`` and ``checkpoint``; the scenario is
    the one in the model's sidecar."""
    model, checkpoint = Path(model), Path(checkpoint)
    exported_model = ExportedModel.load(model)  # refuses a missing or damaged model with one line
    if not checkpoint.is_file():
        raise ExportError(f"no checkpoint at {checkpoint}")
    sidecar: dict[str, Any] = exported_model.sidecar
    if sidecar.get("checkpoint", {}).get("sha256") != file_sha256(checkpoint):
        raise ExportError(f"{model} was exported from another checkpoint than {checkpoint} (SHA-256 differs)")
    scenario = exported_scenario(sidecar, source=str(sidecar_path(model)))
    meta = read_metadata(checkpoint)
    if meta.scenario_hash != scenario.fingerprint():
        raise ExportError(
            f"{sidecar_path(model)}: its scenario ({scenario.fingerprint()}) is not the one "
            f"{checkpoint.name} was trained on ({meta.scenario_hash}): the sidecar was edited; "
            "export again"
        )
    learned = LearnedPolicy.load(checkpoint, exported_model.role, scenario)  # type: ignore[arg-type]
    require_finite(learned, checkpoint)
    if differences := sidecar_differences(sidecar, scenario, learned.meta, learned.draws):
        more = f" (and {len(differences) - 1} more)" if len(differences) > 1 else ""
        raise ExportError(
            f"{sidecar_path(model)} does not match its scenario and checkpoint: {differences[0]}{more}; "
            "a robot would act on the wrong numbers: export again"
        )
    return check_parity(ExportedPolicy(exported_model, scenario), learned, scenario, episodes, seed, opponent)
