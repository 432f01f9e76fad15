"""The robot runtime: an exported policy on a robot, with NumPy and ONNX Runtime only.

Nothing here imports torch, Stable-Baselines3 or the simulator, so a robot needs only ``numpy``
and ``onnxruntime`` besides this package (its wheel installed with ``--no-deps``; docs/export.md)::

    >>> from pecli.runtime import Controller
    >>> controller = Controller.load("final.onnx", seed=0)   # reads final.onnx.json beside it
    >>> controller.reset()                                   # at the start of a game
    >>> command = controller.step(own_state, opponent_state) # once per control tick (10 Hz)
    >>> steering_velocity, acceleration = command            # rad/s and m/s^2 for a car

:class:`MixedController` plays several exports as one (``mix:`` in simulation): each game one of them, drawn
uniformly at ``reset()``.

:class:`ExportedModel` is the graph with its sidecar, batched and stateless. :class:`Controller` is
one player on one robot: it keeps the frame stack and the history window, decides every
``frame_skip`` ticks and holds its command in between, exactly as :mod:`pecli.game.memory` and
``pecli.policies.windowed`` do in simulation. See ``docs/export.md`` for the layout and units.
"""

from __future__ import annotations

import hashlib
import json
import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from pecli.errors import ExportError
from pecli.onnx_guard import MAX_MODEL_BYTES, check_graph

FORMAT = "pecli-onnx/1"
SIDECAR_SUFFIX = ".json"  # final.onnx -> final.onnx.json


MAX_SIDECAR_BYTES = 1 << 20
MAX_ARENA_BYTES = 2 << 30  # what the exported graphs of one process may hold at once
RUN_CHUNK = 2048  # games a graph runs at once: a batch of any size runs in chunks, well within the arena
_arena: list[bool] = []  # one capped arena per process, made by the first model loaded


def sidecar_path(model: str | Path) -> Path:
    """The sidecar of an exported model: ``final.onnx`` → ``final.onnx.json``."""
    model = Path(model)
    return model.with_name(model.name + SIDECAR_SUFFIX)


def file_sha256(path: str | Path) -> str:
    """The SHA-256 of a file's bytes, hex."""
    digest = hashlib.sha256()
    with Path(path).open("rb") as handle:
        for block in iter(lambda: handle.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def read_sidecar(model: str | Path) -> dict[str, Any]:
    """The sidecar of ``model``; :class:`ExportError` if it is missing, damaged or of another format."""
    path = sidecar_path(model)
    if not path.is_file():
        raise ExportError(f"{model}: no sidecar {path.name} beside it (export writes both; copy them together)")
    try:  # read as data, bounded: this module stands alone on a robot (NumPy and onnxruntime only)
        if path.stat().st_size > MAX_SIDECAR_BYTES:
            raise ValueError(f"{path.stat().st_size:,} bytes, more than a sidecar can be")
        data = json.loads(path.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError, OSError, ValueError) as exc:
        raise ExportError(f"{path}: damaged sidecar ({exc})") from None
    except RecursionError:
        raise ExportError(f"{path}: damaged sidecar (nested too deep)") from None
    if not isinstance(data, dict):
        raise ExportError(f"{path}: not a pecli sidecar (not a JSON object)")
    if data.get("format") != FORMAT:
        found = f"format {data['format']!r}" if "format" in data else "no 'format'"
        raise ExportError(f"{path}: not a pecli sidecar of format {FORMAT} ({found})")
    return data


def _shown(value: object) -> str:
    """``value`` as a message quotes it, cut short (the robot runtime copies no other pecli module for this)."""
    text = str(value)
    return text if len(text) <= 40 else f"{text[:37]}..."


def _check_sidecar_values(model: ExportedModel) -> None:
    """:class:`ExportError` unless the sidecar's names are strings, its sensor finite and its limits two
    finite positive numbers (what an export writes)."""
    names = {"role": model.role, "belief": model.belief, "scenario.name": model.scenario_name}
    names["scenario.fingerprint"] = model.scenario_fingerprint
    for key, value in names.items():
        if not isinstance(value, str):
            raise ExportError(f"damaged sidecar: {key} = {_shown(value)}, not a string")
    for key, number in (("sensor.range_m", model.sensor_range), ("sensor.fov_rad", model.sensor_fov)):
        if not (math.isfinite(number) and number > 0):
            raise ExportError(f"damaged sidecar: {key} = {_shown(number)}, not a positive number")
    if not isinstance(model.sidecar["layout"]["own_heading"], bool):
        raise ExportError("damaged sidecar: layout.own_heading is not true or false")
    if model.limits.shape != (2,) or not (np.isfinite(model.limits).all() and (model.limits > 0).all()):
        raise ExportError(
            f"damaged sidecar: command_limits = {_shown(model.limits.tolist())}, not two positive numbers"
        )


def _check_outputs(session: Any) -> None:
    """:class:`ExportError` unless the graph answers ``command`` and ``action``, each ``(batch, 2)`` floats."""
    outputs = {node.name: node for node in session.get_outputs()}
    for name in ("command", "action"):
        node = outputs.get(name)
        if node is None:
            raise ExportError(f"the graph has no output '{name}' (its outputs: {_shown(sorted(outputs))})")
        if node.type not in ("tensor(float)", "tensor(double)") or len(node.shape) != 2 or node.shape[1] != 2:
            raise ExportError(
                f"the graph's output '{name}' is a {node.type} of shape {node.shape}, not floats of shape (batch, 2)"
            )


class ExportedModel:
    """An exported graph and its sidecar: SI state estimates in, SI commands out, batched.

    Args:
        session: an ``onnxruntime.InferenceSession`` of the graph.
        sidecar: the sidecar's content (the layout, the control settings, the sensor).
    """

    def __init__(self, session: Any, sidecar: dict[str, Any]) -> None:
        self.session = session
        self.sidecar = sidecar
        try:
            control, layout = sidecar["control"], sidecar["layout"]
            self.role: str = sidecar["role"]
            self.belief: str = sidecar["belief"]
            self.scenario_name: str = sidecar["scenario"]["name"]
            self.scenario_fingerprint: str = sidecar["scenario"]["fingerprint"]
            self.dt = float(control["dt_s"])
            self.frame_skip, self.frame_stack = int(control["frame_skip"]), int(control["frame_stack"])
            self.history_length, self.history_stride = int(control["history_length"]), int(control["history_stride"])
            self.dim, self.own_dim, self.opponent_dim = (
                int(layout["dim"]),
                int(layout["own_dim"]),
                int(layout["opponent_dim"]),
            )
            self.own_heading = bool(layout["own_heading"])
            self.draws = int(layout["draws"])
            self.sensor_range, self.sensor_fov = (
                float(sidecar["sensor"]["range_m"]),
                float(sidecar["sensor"]["fov_rad"]),
            )
            self.limits = np.asarray(sidecar["command_limits"], dtype=np.float64)
        except KeyError as exc:
            raise ExportError(f"incomplete sidecar (no '{exc.args[0]}')") from None
        except (TypeError, ValueError) as exc:
            raise ExportError(f"incomplete sidecar ({type(exc).__name__}: {exc})") from None
        _check_sidecar_values(self)
        bounded = {
            "dt_s": (self.dt, 10.0),
            "frame_skip": (self.frame_skip, 1000),
            "frame_stack": (self.frame_stack, 1000),
            "history_length": (self.history_length, 10_000),
            "history_stride": (self.history_stride, 10_000),
            "dim": (self.dim, 10_000),
        }  # a scenario's own bounds: nothing an export can have is larger
        bad = [f"{key} = {_shown(value)}" for key, (value, most) in bounded.items() if not 0 < value <= most]
        if not 0 <= self.draws <= 65_536:
            bad.append(f"draws = {self.draws}")
        if bad:
            raise ExportError(f"damaged sidecar: {', '.join(bad)}")
        self.window = -(-self.history_length // self.history_stride)
        self.has_history = self.belief != "none"
        expected = {"obs": [self.frame_stack, self.dim]}
        if self.has_history:
            expected["history"] = [self.window, self.dim]
        if self.draws:
            expected.update(uniform=[self.draws], normal=[self.draws, 2])
        found = {node.name: list(node.shape[1:]) for node in session.get_inputs()}
        if found != expected:
            raise ExportError(
                f"the graph's inputs {found} do not match its sidecar's {expected} (shapes after the batch)"
            )
        self.outputs = [node.name for node in session.get_outputs()]
        _check_outputs(session)

    @classmethod
    def load(cls, path: str | Path, threads: int = 1) -> ExportedModel:
        """Load ``path`` and its sidecar; refuses a model that is missing, damaged or not its sidecar's."""
        path = Path(path)
        if not path.is_file():
            raise ExportError(f"no exported model at {path}")
        if path.stat().st_size > MAX_MODEL_BYTES:
            raise ExportError(f"{path}: {path.stat().st_size:,} bytes, more than an export ever is")
        sidecar = read_sidecar(path)
        if sidecar.get("model_sha256") != file_sha256(path):
            raise ExportError(
                f"{path} does not match its sidecar {sidecar_path(path).name} (SHA-256 differs): "
                "the model was changed or damaged; export it again"
            )
        return cls.from_bytes(path.read_bytes(), sidecar, threads, source=str(path))

    @classmethod
    def from_bytes(
        cls, model: bytes, sidecar: dict[str, Any], threads: int = 1, source: str = "model"
    ) -> ExportedModel:
        """A model from the graph's bytes (serialised ONNX) and its sidecar."""
        try:
            import onnxruntime as ort
        except ImportError:
            raise ExportError("exported models need onnxruntime: pip install onnxruntime") from None

        check_graph(model, source)  # only an export's operators and sizes (with the onnx package)
        options = ort.SessionOptions()
        options.intra_op_num_threads = threads
        options.inter_op_num_threads = 1
        options.execution_mode = ort.ExecutionMode.ORT_SEQUENTIAL
        options.log_severity_level = 4  # its failures reach the user as ExportError, not as log lines
        _cap_memory(ort, options)
        try:
            session = ort.InferenceSession(model, options, providers=["CPUExecutionProvider"])
        except Exception as exc:  # onnxruntime raises its own exception types for damaged graphs
            raise ExportError(f"{source}: cannot load the ONNX graph ({type(exc).__name__}: {exc})") from None
        try:
            return cls(session, sidecar)
        except ExportError as exc:
            raise ExportError(f"{source}: {exc}") from None

    def run(
        self,
        obs: np.ndarray,
        history: np.ndarray | None = None,
        uniform: np.ndarray | None = None,
        normal: np.ndarray | None = None,
    ) -> dict[str, np.ndarray]:
        """Run the graph on a batch of ``B``.

        Args:
            obs: the last ``frame_stack`` SI rows at decision ticks, oldest first, ``(B, frame_stack, dim)``.
            history: the window, every ``history_stride``-th SI row, oldest first, zero rows before the
                start, ``(B, window, dim)``; for a model with a belief.
            uniform, normal: a mixed belief's random numbers, ``(B, draws)`` in [0, 1) and ``(B, draws, 2)``
                standard normal.

        Returns:
            ``command (B, 2)`` SI, ``action (B, 2)`` in [-1, 1], and with a belief ``belief_weights (B, K)``,
            ``belief_means (B, K, 2)`` and ``belief_stds (B, K, 2)`` in metres, world frame.
        """
        feed = {"obs": np.asarray(obs, dtype=np.float64)}
        if self.has_history:
            if history is None:
                raise ValueError("this model has a belief: pass the history window")
            feed["history"] = np.asarray(history, dtype=np.float64)
        if self.draws:
            if uniform is None or normal is None:
                raise ValueError("this model has a mixed belief: pass its uniform and normal draws")
            feed["uniform"] = np.asarray(uniform, dtype=np.float32)
            feed["normal"] = np.asarray(normal, dtype=np.float32)
        games = len(feed["obs"])
        parts = [
            self._run({name: value[start : start + RUN_CHUNK] for name, value in feed.items()})
            for start in range(0, games, RUN_CHUNK)
        ] or [self._run(feed)]  # no games: the graph's empty answers
        return {name: np.concatenate([part[i] for part in parts]) for i, name in enumerate(self.outputs)}

    def _run(self, feed: dict[str, np.ndarray]) -> list[np.ndarray]:
        try:
            return self.session.run(self.outputs, feed)
        except Exception as exc:  # onnxruntime's own types: a graph that fails, or asks past the arena's cap
            raise ExportError(f"the exported graph failed to run: {_run_failure(str(exc))}") from None

    def sees(self, own: np.ndarray, opponent: np.ndarray) -> bool:
        """Whether this player's sensor sees ``opponent`` from ``own`` (SI states; the game's wedge test)."""
        dx, dy = float(opponent[0] - own[0]), float(opponent[1] - own[1])
        distance = math.sqrt(dx * dx + dy * dy)
        seen = distance <= self.sensor_range
        if seen and self.own_heading and self.sensor_fov < 2.0 * math.pi:
            seen = math.cos(own[4]) * dx + math.sin(own[4]) * dy >= math.cos(0.5 * self.sensor_fov) * distance
        return bool(seen)


class Controller:
    """One exported player on one robot, fed one state estimate per control tick.

    Args:
        model: the exported model.
        seed: seed of a mixed belief's random numbers: the seed an ``ExportedPolicy`` is reset with draws the
            same numbers (a match seeds each player with ``pecli.match.policy_seeds(seed)``).
    """

    def __init__(self, model: ExportedModel, seed: int | None = None) -> None:
        self.model = model
        self.rng = np.random.default_rng(seed)
        # positions back from the newest row, oldest first: (window - 1) * stride, ..., stride, 0
        self._back = np.arange(model.window - 1, -1, -1) * model.history_stride
        self.reset()

    @classmethod
    def load(cls, path: str | Path, seed: int | None = None, threads: int = 1) -> Controller:
        """A controller for the exported model at ``path`` (its sidecar beside it)."""
        return cls(ExportedModel.load(path, threads), seed)

    def reset(self, seed: int | None = None) -> None:
        """Start a new game: forget the past, restart the clock (and the draws, given a seed)."""
        m = self.model
        if seed is not None:
            self.rng = np.random.default_rng(seed)
        self.ticks = 0
        self.stack = np.zeros((m.frame_stack, m.dim))
        self.buffer = np.zeros((m.history_length, m.dim))  # a ring of the last history_length rows
        self.cursor = 0
        self.command = np.zeros(2)
        self.outputs: dict[str, np.ndarray] = {}

    def row(
        self, own: np.ndarray, opponent: np.ndarray | None = None, seen: bool | None = None, time: float | None = None
    ) -> np.ndarray:
        """The SI row of this tick: own state, opponent state (zeros unless seen), seen flag, time (s).

        ``seen=None`` applies the player's sensor (range and field of view from the sidecar) to
        ``opponent``; ``time=None`` counts ticks since :meth:`reset` times ``dt``.
        """
        m = self.model
        own = _vector(own, m.own_dim, "own state")
        if opponent is not None:
            opponent = _vector(opponent, m.opponent_dim, "opponent state")
        if seen is None:
            seen = opponent is not None and m.sees(own, opponent)
        if seen and opponent is None:
            raise ValueError("seen=True needs the opponent's state")
        out = np.zeros(m.dim)
        out[: m.own_dim] = own
        if seen:
            out[m.own_dim : m.own_dim + m.opponent_dim] = opponent
        out[-2] = 1.0 if seen else -1.0
        if time is not None and not math.isfinite(float(time)):
            raise ValueError(f"time must be a finite number of seconds, got {time}")
        out[-1] = self.ticks * m.dt if time is None else float(time)
        return out

    def step(
        self, own: np.ndarray, opponent: np.ndarray | None = None, seen: bool | None = None, time: float | None = None
    ) -> np.ndarray:
        """The command ``(2,)`` in SI units for this tick (see :meth:`row` for the arguments).

        A car's command is (steering velocity rad/s, acceleration m/s^2); a point mass's
        (a_x, a_y) m/s^2 in the world frame. Between decisions (every ``frame_skip`` ticks) the
        last command is held, as in training. A model that returns NaN or infinity raises
        :class:`~pecli.errors.ExportError` instead: a robot must stop rather than send it.
        """
        m = self.model
        row = self.row(own, opponent, seen, time)
        self.buffer[self.cursor] = row  # the window holds zeros before a game's first row (reset)
        self.cursor = (self.cursor + 1) % m.history_length
        if self.ticks == 0:  # a game's first tick fills the frame stack with its row
            self.stack[:] = row
        if self.ticks % m.frame_skip == 0:
            self.stack = np.concatenate([self.stack[1:], row[None]])
            self.outputs = self._run()
            command = self.outputs["command"][0]
            if not np.isfinite(command).all():
                raise ExportError(
                    f"the model returned the command {command.tolist()} at tick {self.ticks}: "
                    "a NaN or infinite command is never sent to the motors (is the model damaged? "
                    "`pecli export check` tells)"
                )
            self.command = command.copy()
        self.ticks += 1
        return self.command.copy()

    def window(self) -> np.ndarray:
        """The history window ``(window, dim)``: every ``history_stride``-th row, oldest first."""
        index = (self.cursor - 1 - self._back) % self.model.history_length
        return self.buffer[index]

    def belief(self) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
        """The belief at the last decision: weights ``(K,)``, means ``(K, 2)`` m and stds ``(K, 2)`` m, world frame."""
        if "belief_means" not in self.outputs:
            return None
        return self.outputs["belief_weights"][0], self.outputs["belief_means"][0], self.outputs["belief_stds"][0]

    def _run(self) -> dict[str, np.ndarray]:
        m = self.model
        uniform = normal = None
        if m.draws:  # the same calls, in the same order, as pecli.policies.windowed
            uniform = self.rng.random((1, m.draws), dtype=np.float32)
            normal = self.rng.standard_normal((1, m.draws, 2), dtype=np.float32)
        history = self.window()[None] if m.has_history else None
        return m.run(self.stack[None], history, uniform, normal)


class MixedController:
    """Several exported players as one on a robot: each game draws one member at :meth:`reset`, uniformly or by
    ``weights``, and that member plays the whole game (the runtime form of the policy string ``mix:``).

    Args:
        controllers: the members, every one playing the same role of the same game.
        seed: seed of the draws (each member keeps its own random numbers for a mixed belief).
        weights: one non-negative weight per member (normalised here; ``mix:A@2,B`` is ``[2, 1]``); default uniform.
    """

    def __init__(
        self, controllers: Sequence[Controller], seed: int | None = None, weights: Sequence[float] | None = None
    ) -> None:
        if not controllers:
            raise ExportError("a mixture needs at least one exported player")
        self.weights: np.ndarray | None = None
        if weights is not None:
            # pecli.metagame.mixture_weights written out: the runtime imports only the modules a robot copies
            w = np.asarray(weights, dtype=np.float64)
            if w.shape != (len(controllers),) or not np.all(np.isfinite(w)) or np.any(w < 0) or w.sum() <= 0:
                raise ExportError(
                    f"weights must be {len(controllers)} non-negative numbers with a positive sum, got {list(weights)}"
                )
            self.weights = w / w.sum()
        first = controllers[0].model
        for controller in controllers[1:]:
            other = controller.model
            if (other.role, other.scenario_fingerprint) != (first.role, first.scenario_fingerprint):
                raise ExportError(
                    f"every member must play one role of one game: {first.role} of '{first.scenario_name}' and "
                    f"{other.role} of '{other.scenario_name}'"
                )
        self.controllers = list(controllers)
        self.rng = np.random.default_rng(seed)
        self.member = 0
        self.reset()

    @classmethod
    def load(
        cls,
        paths: Sequence[str | Path],
        seed: int | None = None,
        threads: int = 1,
        weights: Sequence[float] | None = None,
    ) -> MixedController:
        """A mixture of the exported models at ``paths`` (each with its sidecar beside it), drawn by ``weights``."""
        members = np.random.default_rng(seed).integers(0, 2**31, size=len(paths)).tolist()
        return cls([Controller.load(path, int(s), threads) for path, s in zip(paths, members)], seed, weights)

    def reset(self, seed: int | None = None) -> None:
        """Start a new game: draw the member that plays it, and reset that member."""
        if seed is not None:
            self.rng = np.random.default_rng(seed)
        if self.weights is None:
            self.member = int(self.rng.integers(len(self.controllers)))
        else:
            self.member = int(self.rng.choice(len(self.controllers), p=self.weights))
        self.controllers[self.member].reset()

    @property
    def playing(self) -> Controller:
        """The member playing this game."""
        return self.controllers[self.member]

    def step(
        self, own: np.ndarray, opponent: np.ndarray | None = None, seen: bool | None = None, time: float | None = None
    ) -> np.ndarray:
        """The playing member's command for this tick (:meth:`Controller.step`)."""
        return self.playing.step(own, opponent, seen, time)


def _vector(values: Any, size: int, what: str) -> np.ndarray:
    out = np.asarray(values, dtype=np.float64).reshape(-1)
    if out.shape != (size,):
        raise ValueError(f"{what} must have {size} numbers, got {out.size}")
    if not np.isfinite(out).all():
        raise ValueError(f"{what} must be finite, got {out.tolist()}")
    return out


def _cap_memory(ort: Any, options: Any) -> None:
    """Make ``options``' session allocate from one CPU arena per process of at most :data:`MAX_ARENA_BYTES`.

    A graph's shapes may be computed at run time from its inputs, past what :func:`check_graph` can bound (a
    ``ConstantOfShape`` of the input's shape joined to large constants): with the cap such a graph fails its
    allocation, one line, instead of taking the machine's memory.
    """
    if not hasattr(ort, "create_and_register_allocator"):  # an onnxruntime older than 1.9: no cap to set
        return
    if not _arena:
        info = ort.OrtMemoryInfo("Cpu", ort.OrtAllocatorType.ORT_ARENA_ALLOCATOR, 0, ort.OrtMemType.DEFAULT)
        ort.create_and_register_allocator(
            info, ort.OrtArenaCfg({"max_mem": MAX_ARENA_BYTES, "arena_extend_strategy": 1})
        )
        ort.set_default_logger_severity(4)
        _arena.append(True)
    options.add_session_config_entry("session.use_env_allocators", "1")


def _run_failure(message: str) -> str:
    """onnxruntime's report of a failed run, in one line: the bytes asked for, where the arena's cap refused them."""
    import re

    asked = re.search(r"requested bytes of (\d+)", message)
    if asked is not None:
        return f"it asked for {int(asked.group(1)):,} bytes, more than exported graphs may hold ({MAX_ARENA_BYTES:,})"
    return " ".join(message.split())[:300]
