"""Scenarios: the typed, validated description of one pursuit-evasion game.

A scenario is read from YAML with ``yaml.safe_load`` and validated by pydantic.
Every quantity is in SI units (metres, seconds, radians). Angles (a sensor's ``fov``, a car's
steering limits) may be written as numbers or as expressions such as ``2pi/3``, ``pi``, ``-20deg``.

    >>> scenario = load_scenario("configs/paper.yaml")   # or a built-in name: "paper"
    >>> scenario.pursuer.kind, scenario.capture_distance
    ('car', 0.5)
"""

from __future__ import annotations

import hashlib
import json
import math
import re
import sys
from pathlib import Path
from typing import Annotated, Any, Literal

import yaml
from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator, model_validator
from pydantic.functional_validators import BeforeValidator

from pecli.errors import ConfigError

TWO_PI = 2.0 * math.pi
_ANGLE = re.compile(r"^\s*(?:(?P<k>[0-9]*\.?[0-9]+)\s*\*?\s*)?pi\s*(?:/\s*(?P<d>[0-9]*\.?[0-9]+))?\s*$")
_DEGREES = re.compile(r"^\s*(?P<v>-?[0-9]*\.?[0-9]+)\s*deg\s*$")


def parse_angle(value: Any) -> Any:
    """Turn ``"2pi/3"``, ``"pi"``, ``"1.5*pi"`` or ``"120deg"`` into radians; pass numbers through."""
    if isinstance(value, str):
        if m := _ANGLE.match(value):
            k = float(m["k"]) if m["k"] else 1.0
            d = float(m["d"]) if m["d"] else 1.0
            return k * math.pi / d
        if m := _DEGREES.match(value):
            return math.radians(float(m["v"]))
        raise ValueError(f"cannot read {value!r} as an angle (write radians, 'k*pi/m' or 'Ndeg')")
    return value


Angle = Annotated[float, BeforeValidator(parse_angle)]


class _Model(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


class Sensor(_Model):
    """A noise-free wedge sensor: the opponent is seen iff within ``range`` and ``fov``/2 of the heading."""

    range: float = Field(gt=0, description="sensing range V_r in m")
    fov: Angle = Field(default=TWO_PI, description="field-of-view angle V_alpha in rad, in (0, 2pi]")

    @field_validator("fov")
    @classmethod
    def _fov_in_range(cls, fov: float) -> float:
        if not 0.0 < fov <= TWO_PI + 1e-9:
            raise ValueError("FOV must be in (0, 2pi] rad")
        return min(fov, TWO_PI)


class CarAgent(_Model):
    """A kinematic single-track car (CommonRoad KS model); state (s_x, s_y, delta, v, psi)."""

    kind: Literal["car"] = "car"
    lf: float = Field(gt=0, description="centre of gravity to front axle, m")
    lr: float = Field(gt=0, description="centre of gravity to rear axle, m")
    steer_min: Angle = Field(description="lowest steering angle delta, rad")
    steer_max: Angle = Field(description="highest steering angle delta, rad")
    steer_rate_max: float = Field(gt=0, description="steering velocity limit |v_delta|, rad/s")
    v_min: float = Field(description="lowest longitudinal velocity, m/s (negative: reverse)")
    v_max: float = Field(gt=0, description="highest longitudinal velocity, m/s")
    a_max: float = Field(gt=0, description="acceleration limit |a|, m/s^2")
    v_switch: float | None = Field(default=None, gt=0, description="above this speed a_max falls as 1/v; none: never")
    sensor: Sensor

    @model_validator(mode="after")
    def _limits_ordered(self) -> CarAgent:
        if self.steer_min >= self.steer_max:
            raise ValueError(f"steer_min ({self.steer_min:g}) must be below steer_max ({self.steer_max:g})")
        if self.v_min > 0:
            raise ValueError(f"v_min ({self.v_min:g}) must be <= 0 so that a car can stand still")
        if not self.steer_min <= 0 <= self.steer_max:
            raise ValueError("the steering range must contain 0")
        return self

    @property
    def wheelbase(self) -> float:
        return self.lf + self.lr

    @property
    def speed_max(self) -> float:
        """Largest speed in either direction, m/s (the normalisation constant for v)."""
        return max(abs(self.v_min), self.v_max)

    @property
    def steer_abs_max(self) -> float:
        return max(abs(self.steer_min), abs(self.steer_max))


class PointMassAgent(_Model):
    """A point mass (CommonRoad PM model); state (s_x, s_y, v_x, v_y), input (a_x, a_y)."""

    kind: Literal["point_mass"] = "point_mass"
    v_max: float = Field(gt=0, description="velocity limit per axis, m/s")
    a_max: float = Field(gt=0, description="acceleration limit per axis, m/s^2")
    sensor: Sensor

    @field_validator("sensor")
    @classmethod
    def _disk(cls, sensor: Sensor) -> Sensor:
        if sensor.fov < TWO_PI - 1e-9:
            raise ValueError("a point mass has no heading, so its sensor is a disk: leave fov out (2pi)")
        return sensor

    @property
    def speed_max(self) -> float:
        """Largest speed, m/s (both axes at their limit)."""
        return self.v_max * math.sqrt(2.0)


Agent = Annotated[CarAgent | PointMassAgent, Field(discriminator="kind")]


class Arena(_Model):
    """An obstacle-free rectangle centred at the origin."""

    width: float = Field(gt=0, description="extent along x, m")
    height: float = Field(gt=0, description="extent along y, m")

    @property
    def half(self) -> tuple[float, float]:
        return 0.5 * self.width, 0.5 * self.height


class Reward(_Model):
    """Zero-sum reward coefficients (paper section IV-D); the pursuer's reward, the evader gets its negative."""

    capture: float = Field(default=1000.0, ge=0, description="lambda_capture: +on capture, -on timeout")
    time: float = Field(default=1.0, ge=0, description="lambda_t: cost per step")
    distance: float = Field(default=1.0, ge=0, description="lambda_d: cost per metre of distance per step")


class Curriculum(_Model):
    """Paper section V-A: over the first ``fraction`` of training the pursuer's FOV shrinks from 2pi
    to its configured value and the evader's speed limit grows from 0 to its configured value."""

    enabled: bool = True
    fraction: float = Field(default=0.3, gt=0, le=1, description="share of the training budget it spans")


class BeliefSettings(_Model):
    """The belief network and how it is fitted (paper section V-A)."""

    hidden: int = Field(default=128, ge=1, description="BiMDN LSTM units per direction")
    fc: int = Field(default=32, ge=1, description="width of the shared layer and of each head")
    components: int = Field(default=3, ge=1, description="Gaussians in the mixture")
    samples: int = Field(default=16, ge=1, description="draws the 'bimdn-mixed' actor reads")
    buffer_size: int = Field(default=25_000, ge=1, description="(window, true position) pairs kept")
    warmup: int = Field(default=10_000, ge=0, description="pairs collected before fitting starts")
    update_every: int = Field(default=10, ge=1, description="vector-env steps between belief updates")
    batch_size: int = Field(default=256, ge=1)
    learning_rate: float = Field(default=0.002, gt=0)
    max_grad_norm: float = Field(default=1.0, gt=0, description="(ours) gradient clipping of the belief's updates")


class SelfPlay(_Model):
    """Alternating self-play (``pecli selfplay``): each round trains the pursuer, then the evader,
    against opponents drawn from the other side's pool."""

    rounds: int = Field(default=10, ge=1, description="rounds; a round trains each side once")
    steps_per_round: int = Field(default=50_000, ge=1, description="learner transitions per side per round")
    opponents: Literal["latest", "uniform", "pfsp"] = Field(
        default="pfsp",
        description="latest: the newest opponents; uniform: the whole pool; pfsp: weighted by how often they win",
    )
    pfsp_power: float = Field(default=2.0, gt=0, description="(ours) PFSP weight = P(opponent wins)^power")
    pfsp_prior_episodes: float = Field(
        default=10.0, gt=0, description="(ours) pseudo-episodes of the prior (a tournament's prediction, else 0.5)"
    )
    pfsp_decay: float = Field(
        default=0.5, ge=0, le=1, description="(ours) share of an opponent's record kept when the learner moves on a round"
    )


class Training(_Model):
    """How a learner is trained (Stable-Baselines3 TD3/DDPG on a frozen-opponent view)."""

    algo: Literal["td3", "ddpg"] = "td3"
    belief: Literal["none", "bimdn", "bimdn-mixed", "ukf", "image"] = Field(
        default="none", description="what the actor adds to its observation about the unseen opponent"
    )
    steps: int = Field(default=1_000_000, ge=1, description="budget in learner transitions (all envs together)")
    n_envs: int = Field(default=8, ge=1, description="games stepped together in one process")
    frame_skip: int = Field(default=2, ge=1, description="game steps each action is held for")
    frame_stack: int = Field(default=2, ge=1, description="observations stacked into the actor's input")
    history_length: int = Field(default=200, ge=1, description="game steps the belief window looks back")
    history_stride: int = Field(default=10, ge=1, description="keep every k-th step of the window (10: 1 Hz)")
    reward_scale: float = Field(default=0.001, gt=0, description="rewards are multiplied by this for learning")
    learning_rate: float = Field(default=5e-4, gt=0)
    buffer_size: int = Field(default=100_000, ge=1)
    batch_size: int = Field(default=512, ge=1)
    gamma: float = Field(default=0.99, gt=0, le=1)
    tau: float = Field(default=0.005, gt=0, le=1)
    action_noise: float = Field(default=0.1, ge=0, description="std of the Gaussian exploration noise")
    net_arch: list[int] = Field(default=[128, 128], min_length=1)
    learning_starts: int = Field(default=5_000, ge=0, description="transitions collected before learning")
    train_freq: int = Field(default=1, ge=1, description="vector-env steps between updates")
    gradient_steps: int = Field(default=2, ge=1, description="gradient steps per update")
    checkpoint_every: int = Field(default=250, ge=1, description="episodes between zoo checkpoints")
    eval_every: int = Field(default=0, ge=0, description="transitions between evaluations; 0: none")
    eval_episodes: int = Field(default=200, ge=1)
    torch_threads: int = Field(default=1, ge=1, description="torch threads per process (1 is fastest on a shared CPU)")
    curriculum: Curriculum = Curriculum()
    belief_settings: BeliefSettings = BeliefSettings()
    selfplay: SelfPlay = SelfPlay()

    @model_validator(mode="after")
    def _window_fits(self) -> Training:
        if self.history_stride > self.history_length:
            raise ValueError(
                f"history_stride ({self.history_stride}) must not exceed history_length ({self.history_length})"
            )
        return self


class Scenario(_Model):
    """One game: the arena, the clock, both players and what they observe; and how to train on it."""

    name: str = "custom"
    description: str = ""
    arena: Arena
    dt: float = Field(default=0.1, gt=0, description="time step, s")
    horizon: int = Field(default=400, ge=1, description="steps before a timeout (evader wins)")
    capture_radius: float = Field(default=0.25, gt=0, description="agent radius c; capture when d <= 2c")
    observation_frame: Literal["own", "world"] = Field(
        default="own",
        description="'own': the opponent relative to the observer, rotated into its body frame; 'world': the paper's",
    )
    reward: Reward = Reward()
    pursuer: Agent
    evader: Agent
    training: Training = Training()

    @model_validator(mode="after")
    def _arena_fits_capture(self) -> Scenario:
        if min(self.arena.width, self.arena.height) <= 2 * self.capture_distance:
            raise ValueError(
                f"the arena ({self.arena.width:g} x {self.arena.height:g} m) must be larger than "
                f"twice the capture distance ({self.capture_distance:g} m)"
            )
        return self

    @property
    def capture_distance(self) -> float:
        """Capture happens when the players are at most this far apart (2c), m."""
        return 2.0 * self.capture_radius

    def agent(self, role: str) -> CarAgent | PointMassAgent:
        """The parameters of ``role`` ('pursuer' or 'evader')."""
        if role == "pursuer":
            return self.pursuer
        if role == "evader":
            return self.evader
        raise ValueError(f"role must be 'pursuer' or 'evader', not {role!r}")

    def fingerprint(self) -> str:
        """A short hash of everything that changes the game (not the name, description or training)."""
        payload = self.model_dump(exclude={"name", "description", "training"}, mode="json")
        text = json.dumps(payload, sort_keys=True, separators=(",", ":"))
        return hashlib.sha256(text.encode()).hexdigest()[:16]

    def differences(self, other: Scenario) -> list[tuple[str, Any, Any]]:
        """What makes ``other`` another game (what :meth:`fingerprint` covers): ``[(key, ours, theirs)]``,
        e.g. ``[("horizon", 150, 200)]``."""

        def flat(data: Any, prefix: str = "") -> dict[str, Any]:
            if not isinstance(data, dict):
                return {prefix.rstrip("."): data}
            return {k: v for key, value in data.items() for k, v in flat(value, f"{prefix}{key}.").items()}

        exclude = {"name", "description", "training"}
        ours, theirs = (flat(s.model_dump(exclude=exclude, mode="json")) for s in (self, other))
        return [(key, ours.get(key), theirs.get(key)) for key in sorted(ours.keys() | theirs.keys())
                if ours.get(key) != theirs.get(key)]


def builtin_config_dir() -> Path:
    """The folder holding the built-in ``configs/*.yaml`` (source checkout or installed data files)."""
    for candidate in (Path(__file__).resolve().parents[1] / "configs", Path(sys.prefix) / "share" / "pecli" / "configs"):
        if candidate.is_dir():
            return candidate
    return Path("configs")


def builtin_names() -> list[str]:
    """Names of the built-in scenarios (``paper``, ``quick``, ...)."""
    return sorted(p.stem for p in builtin_config_dir().glob("*.yaml"))


def resolve_config_path(path_or_name: str | Path) -> Path:
    """A path as given, or the built-in config of that name."""
    path = Path(path_or_name)
    if path.exists() or path.suffix in (".yaml", ".yml") or len(path.parts) > 1:
        return path
    return builtin_config_dir() / f"{path_or_name}.yaml"


def _describe(error: dict[str, Any]) -> str:
    """One readable phrase for one pydantic error."""
    kind, msg = error["type"], error["msg"]
    if kind == "extra_forbidden":
        return "unknown key"
    if kind == "missing":
        return "missing required key"
    msg = msg.removeprefix("Value error, ")
    if "input" in error and kind not in ("model_type", "union_tag_invalid"):
        shown = error["input"]
        if not isinstance(shown, dict | list):
            return f"{msg} (got {shown!r})"
    return msg


def _location(error: dict[str, Any]) -> str:
    # drop the discriminator tags pydantic adds to the path of a tagged union (e.g. 'car')
    parts = [str(p) for p in error["loc"] if p not in ("car", "point_mass")]
    return ".".join(parts)


def scenario_from_dict(data: Any, source: str = "<dict>") -> Scenario:
    """Validate ``data`` into a :class:`Scenario`; errors become one-line :class:`ConfigError`."""
    if not isinstance(data, dict):
        raise ConfigError(f"{source}: a scenario must be a mapping of keys to values, not {type(data).__name__}")
    try:
        return Scenario.model_validate(data)
    except ValidationError as exc:
        errors = exc.errors()
        first = errors[0]
        where = _location(first)
        more = f" (and {len(errors) - 1} more problem{'s' if len(errors) > 2 else ''})" if len(errors) > 1 else ""
        raise ConfigError(f"{source}: {where or 'top level'}: {_describe(first)}{more}") from None


def load_scenario(path_or_name: str | Path) -> Scenario:
    """Read and validate a scenario from a YAML file or a built-in name (see :func:`builtin_names`)."""
    path = resolve_config_path(path_or_name)
    if not path.is_file():
        known = ", ".join(builtin_names())
        raise ConfigError(f"config not found: {path_or_name} (give a YAML file or one of: {known})")
    try:
        data = yaml.safe_load(path.read_text())
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f" line {mark.line + 1}" if mark is not None else ""
        problem = getattr(exc, "problem", None) or "not valid YAML"
        raise ConfigError(f"{path}:{where}: {problem}") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise ConfigError(f"{path}: cannot read: {exc}") from None
    return scenario_from_dict(data, source=str(path))
