"""The sidecar JSON beside an exported model: what the graph is, and how a robot must feed it.

``final.onnx`` comes with ``final.onnx.json``. :func:`build_sidecar` writes every field that
:class:`pecli.runtime.ExportedModel` reads, plus the provenance (checkpoint hash, versions) and
the full scenario. ``docs/export.md`` describes each field.
"""

from __future__ import annotations

import math
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from pecli import __version__
from pecli.export.graph import PolicyGraph, command_limits
from pecli.game.si import SILayout
from pecli.runtime import FORMAT, file_sha256
from pecli.scenario import Scenario
from pecli.zoo import CheckpointMeta

COMMAND_FIELDS = {
    True: [("steering_velocity", "rad/s"), ("acceleration", "m/s^2")],  # a car
    False: [("a_x", "m/s^2"), ("a_y", "m/s^2")],  # a point mass, world frame
}


def _fields(pairs: list[tuple[str, str]]) -> list[dict[str, str]]:
    return [{"name": name, "unit": unit} for name, unit in pairs]


def io_layout(
    graph: PolicyGraph, layout: SILayout, meta: CheckpointMeta, draws: int
) -> dict[str, list[dict[str, Any]]]:
    """The graph's inputs and outputs: name, dtype, shape (``"batch"`` first) and meaning."""
    window = -(-meta.history_length // meta.history_stride)
    inputs = {
        "obs": {
            "dtype": "float64",
            "shape": ["batch", meta.frame_stack, layout.dim],
            "meaning": "SI rows of the last frame_stack decision ticks, oldest first (see 'row')",
        },
        "history": {
            "dtype": "float64",
            "shape": ["batch", window, layout.dim],
            "meaning": f"every {meta.history_stride}th SI row of the last {meta.history_length} ticks, "
            "oldest first, newest = this tick; zero rows before the game's start",
        },
        "uniform": {
            "dtype": "float32",
            "shape": ["batch", draws],
            "meaning": "uniform [0, 1) numbers that pick the mixture components of the belief's draws",
        },
        "normal": {
            "dtype": "float32",
            "shape": ["batch", draws, 2],
            "meaning": "standard normal numbers of the belief's draws",
        },
    }
    own_car = layout.own.has_heading
    outputs = {
        "command": {
            "dtype": "float64",
            "shape": ["batch", 2],
            "fields": _fields(COMMAND_FIELDS[own_car]),
            "meaning": "the command in physical units (the action times command_limits)",
        },
        "action": {
            "dtype": "float32",
            "shape": ["batch", 2],
            "meaning": "the actor's output in [-1, 1], as the simulator takes it",
        },
        "belief_weights": {"dtype": "float32", "shape": ["batch", "K"], "meaning": "mixture weights"},
        "belief_means": {
            "dtype": "float64",
            "shape": ["batch", "K", 2],
            "unit": "m",
            "meaning": "component means of the opponent's position, world frame",
        },
        "belief_stds": {
            "dtype": "float64",
            "shape": ["batch", "K", 2],
            "unit": "m",
            "meaning": "component standard deviations along x and y",
        },
    }
    return {
        "inputs": [{"name": name, **inputs[name]} for name in graph.input_names],
        "outputs": [{"name": name, **outputs[name]} for name in graph.output_names],
    }


def build_sidecar(
    graph: PolicyGraph,
    scenario: Scenario,
    meta: CheckpointMeta,
    checkpoint: Path | None,
    opset: int,
    draws: int,
) -> dict[str, Any]:
    """Everything but ``model_sha256`` and ``parity``, which the export adds once it has them
    (``checkpoint`` is None for a network trained elsewhere: its file and hash are then null)."""
    layout = SILayout(scenario, meta.role)
    controls = robot_fields(scenario, meta, draws)
    return {
        "format": FORMAT,
        "pecli_version": __version__,
        "created": datetime.now(UTC).isoformat(timespec="seconds"),
        "opset": opset,
        "role": meta.role,
        "belief": meta.belief,
        "checkpoint": {
            "file": checkpoint.name if checkpoint is not None else None,
            "sha256": file_sha256(checkpoint) if checkpoint is not None else None,
            **{key: getattr(meta, key) for key in ("run", "steps", "episodes", "algo", "seed", "pecli_version")},
        },
        "scenario": {
            "name": scenario.name,
            "fingerprint": scenario.fingerprint(),
            "config": scenario.model_dump(mode="json"),
        },
        **controls,
        **io_layout(graph, layout, meta, draws),
    }


def robot_fields(scenario: Scenario, meta: CheckpointMeta, draws: int) -> dict[str, Any]:
    """The sidecar's sections a robot acts on (``control``, ``sensor``, ``layout``, ``command_limits``):
    what follows from the scenario and the checkpoint, so that :func:`sidecar_differences` can check them."""
    layout = SILayout(scenario, meta.role)
    sensor = scenario.agent(meta.role).sensor
    return {
        "control": {
            "dt_s": scenario.dt,
            "rate_hz": 1.0 / scenario.dt,
            "frame_skip": meta.frame_skip,
            "frame_stack": meta.frame_stack,
            "history_length": meta.history_length,
            "history_stride": meta.history_stride,
            "horizon_s": layout.horizon_s,
        },
        "sensor": {"range_m": sensor.range, "fov_rad": sensor.fov, "fov_deg": math.degrees(sensor.fov)},
        "layout": {
            "dim": layout.dim,
            "own_dim": layout.k,
            "opponent_dim": layout.m,
            "own_heading": layout.own.has_heading,
            "draws": draws,
            "row": [field.to_dict() for field in layout.fields()],
        },
        "command_limits": list(command_limits(layout)),
    }


def sidecar_differences(sidecar: dict[str, Any], scenario: Scenario, meta: CheckpointMeta, draws: int) -> list[str]:
    """Where ``sidecar`` disagrees with what ``scenario`` and the checkpoint's ``meta`` say, e.g.
    ``"sensor.fov_rad is 1.0, not 2.0944"``: a sidecar edited by hand, or put beside another model."""
    expected = {
        "role": meta.role,
        "belief": meta.belief,
        "scenario": {"fingerprint": scenario.fingerprint()},
        **robot_fields(scenario, meta, draws),
    }
    return _differences(sidecar, expected, "")


def _differences(found: Any, expected: Any, where: str) -> list[str]:
    if isinstance(expected, dict):
        if not isinstance(found, dict):
            return [f"{where} is {found!r}, not a section"]
        return [
            d
            for key, value in expected.items()
            for d in _differences(found.get(key), value, f"{where}.{key}".lstrip("."))
        ]
    if isinstance(expected, list) and isinstance(found, list) and len(found) == len(expected):
        return [d for i, (f, e) in enumerate(zip(found, expected)) for d in _differences(f, e, f"{where}[{i}]")]
    same = found == expected
    if isinstance(expected, float) and isinstance(found, int | float) and not isinstance(found, bool):
        same = math.isclose(found, expected, rel_tol=1e-12, abs_tol=1e-12)
    return [] if same else [f"{where} is {found!r}, not {expected!r}"]
