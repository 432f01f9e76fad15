"""Scenarios: the typed, validated description of one pursuit-evasion game.

A scenario is read from YAML with a safe loader that refuses duplicate keys, and validated by
pydantic strictly: every number finite, no boolean where a number belongs (nor a number where a
boolean belongs), and the sizes that decide a run's memory and time within plausible bounds, checked
before anything is allocated (:func:`memory_estimate`). Every quantity is in SI units (metres,
seconds, radians). Angles (a sensor's ``fov``, a car's steering limits) may be written as numbers or
as expressions such as ``2pi/3``, ``pi``, ``-20deg``.

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
from pydantic import (
    BaseModel,
    ConfigDict,
    Field,
    ValidationError,
    field_validator,
    model_validator,
)
from pydantic.functional_validators import BeforeValidator

from pecli.errors import ConfigError
from pecli.roles import Role

TWO_PI = 2.0 * math.pi
_ANGLE = re.compile(r"^\s*(?:(?P<k>[0-9]*\.?[0-9]+)\s*\*?\s*)?pi\s*(?:/\s*(?P<d>[0-9]*\.?[0-9]+))?\s*$")
_DEGREES = re.compile(r"^\s*(?P<v>-?[0-9]*\.?[0-9]+)\s*deg\s*$")


_NUMBER = re.compile(r"^\s*[-+]?(?:[0-9][0-9_]*\.?[0-9_]*|\.[0-9_]+)(?:[eE][-+]?[0-9]+)?\s*$")


def parse_number(value: Any) -> Any:
    """A string that spells a number, as YAML 1.1 leaves ``1e-4`` or ``1.0e6``, as that float; anything else
    unchanged (``nan``, ``inf`` and ``true`` stay what they are, and strict validation refuses them)."""
    if isinstance(value, str) and _NUMBER.match(value):
        return float(value.replace("_", ""))
    return value


def parse_angle(value: Any) -> Any:
    """Turn ``"2pi/3"``, ``"pi"``, ``"1.5*pi"`` or ``"120deg"`` into radians; pass numbers through."""
    value = parse_number(value)
    if isinstance(value, str):
        if m := _ANGLE.match(value):
            k = float(m["k"]) if m["k"] else 1.0
            d = float(m["d"]) if m["d"] else 1.0
            if d == 0.0:
                raise ValueError(f"cannot read {value!r} as an angle (it divides by zero)")
            return k * math.pi / d
        if m := _DEGREES.match(value):
            return math.radians(float(m["v"]))
        raise ValueError(f"cannot read {value!r} as an angle (write radians, 'k*pi/m' or 'Ndeg')")
    return value


Angle = Annotated[float, BeforeValidator(parse_angle)]
Real = Annotated[float, BeforeValidator(parse_number)]
"""A real setting: a finite number (``1e-4`` as YAML leaves it, a string, is read too); ``true`` is refused."""


def _whole(value: Any) -> Any:
    """A number that is whole (``1.0e6``, or YAML's string ``1e6``) as that integer; anything else unchanged."""
    value = parse_number(value)
    if isinstance(value, float) and value.is_integer():
        return int(value)
    return value


Count = Annotated[int, BeforeValidator(_whole)]
"""An integer setting; ``true`` is refused, a whole float such as ``1.0e6`` accepted."""

# Plausible bounds: beyond them a setting is a typo (an extra zero, a unit mix-up), refused before
# anything is allocated. What they allocate together is bounded by MEMORY_LIMIT (memory_estimate).
MAX_STEPS = 10**10  # learner transitions of one run (the paper: 10^6)
MAX_GAMES = 65_536  # training.n_envs: games stepped together in one process (the paper: 8)
MAX_HORIZON = 100_000  # game steps of one episode (the paper: 400)
MAX_HISTORY = 10_000  # game steps of the belief window (the paper: 200)
MAX_BUFFER = 10**8  # transitions or pairs kept (the paper: 10^5)
MAX_BATCH = 65_536
MAX_WIDTH = 65_536  # units of one hidden layer or LSTM
MAX_METRES = 1e6  # any length: arena, sensor range, car, capture radius (the paper's arena: 16 m)
MAX_RATE = 1e5  # any speed, acceleration or steering rate, SI (the paper's car: 2.5 m/s, 2 m/s^2)
MAX_DT = 10.0  # the game's time step, s (the paper: 0.1)
MAX_DEPTH = 32  # hidden layers
MAX_COUNT = 10**9  # any other count (episodes, intervals, threads, ...)
MEMORY_LIMIT = 64 * 2**30  # bytes one training process may plan to allocate (memory_estimate)


class _Model(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True, strict=True, allow_inf_nan=False)


class Sensor(_Model):
    """A noise-free wedge sensor: the opponent is seen iff within ``range`` and ``fov``/2 of the heading."""

    range: Real = Field(gt=0, le=MAX_METRES, description="sensing range V_r in m")
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
    lf: Real = Field(gt=0, le=MAX_METRES, description="centre of gravity to front axle, m")
    lr: Real = Field(gt=0, le=MAX_METRES, description="centre of gravity to rear axle, m")
    steer_min: Angle = Field(description="lowest steering angle delta, rad")
    steer_max: Angle = Field(description="highest steering angle delta, rad")
    steer_rate_max: Real = Field(gt=0, le=MAX_RATE, description="steering velocity limit |v_delta|, rad/s")
    v_min: Real = Field(ge=-MAX_RATE, description="lowest longitudinal velocity, m/s (negative: reverse)")
    v_max: Real = Field(gt=0, le=MAX_RATE, description="highest longitudinal velocity, m/s")
    a_max: Real = Field(gt=0, le=MAX_RATE, description="acceleration limit |a|, m/s^2")
    v_switch: Real | None = Field(default=None, gt=0, description="above this speed a_max falls as 1/v; none: never")
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
    v_max: Real = Field(gt=0, le=MAX_RATE, description="velocity limit per axis, m/s")
    a_max: Real = Field(gt=0, le=MAX_RATE, description="acceleration limit per axis, m/s^2")
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

    width: Real = Field(gt=0, le=MAX_METRES, description="extent along x, m")
    height: Real = Field(gt=0, le=MAX_METRES, description="extent along y, m")

    @property
    def half(self) -> tuple[float, float]:
        return 0.5 * self.width, 0.5 * self.height


class Reward(_Model):
    """Zero-sum reward coefficients (paper section IV-D); the pursuer's reward, the evader gets its negative."""

    capture: Real = Field(default=1000.0, ge=0, description="lambda_capture: +on capture, -on timeout")
    time: Real = Field(default=1.0, ge=0, description="lambda_t: cost per step")
    distance: Real = Field(default=1.0, ge=0, description="lambda_d: cost per metre of distance per step")


class Curriculum(_Model):
    """Paper section V-A: over the first ``fraction`` of training the pursuer's FOV shrinks from 2pi
    to its configured value and the evader's speed limit grows from 0 to its configured value."""

    enabled: bool = True
    fraction: Real = Field(default=0.3, gt=0, le=1, description="share of the training budget it spans")
    steps: Count | None = Field(default=None, ge=1, le=MAX_STEPS,
                                description="learner transitions it spans, instead of a fraction of the budget "
                                "(for runs a CPU budget stops, whose planned budget is only a ceiling)")

    def span(self, budget: int) -> float:
        """The learner transitions the curriculum spans in a run planned for ``budget`` of them."""
        return float(self.steps) if self.steps is not None else max(1.0, self.fraction * budget)


class BeliefSettings(_Model):
    """The belief network and how it is fitted (paper section V-A)."""

    hidden: Count = Field(default=128, ge=1, le=MAX_WIDTH, description="BiMDN LSTM units per direction")
    fc: Count = Field(default=32, ge=1, le=MAX_WIDTH, description="width of the shared layer and of each head")
    components: Count = Field(default=3, ge=1, le=1024, description="Gaussians in the mixture")
    samples: Count = Field(default=16, ge=1, le=MAX_BATCH, description="draws the 'bimdn-mixed' actor reads")
    buffer_size: Count = Field(default=25_000, ge=1, le=MAX_BUFFER, description="(window, true position) pairs kept")
    warmup: Count = Field(default=10_000, ge=0, le=MAX_STEPS, description="pairs collected before fitting starts")
    update_every: Count = Field(default=10, ge=1, le=MAX_COUNT, description="vector-env steps between belief updates")
    batch_size: Count = Field(default=256, ge=1, le=MAX_BATCH)
    learning_rate: Real = Field(default=0.002, gt=0)
    max_grad_norm: Real = Field(default=1.0, gt=0, description="(ours) gradient clipping of the belief's updates")


class SelfPlay(_Model):
    """Alternating self-play (``pecli selfplay``): each round trains the pursuer, then the evader,
    against opponents drawn from the other side's pool."""

    rounds: Count = Field(default=10, ge=1, le=100_000, description="rounds; a round trains each side once")
    steps_per_round: Count = Field(default=50_000, ge=1, le=MAX_STEPS,
                                  description="learner transitions per side per round")
    schedule: Literal["alternating", "simultaneous"] = Field(
        default="alternating",
        description="alternating: one side trains at a time against the other's pool; simultaneous: both "
        "learners in the same games, both learning every step (the paper's MADDPG)",
    )
    opponents: Literal["latest", "uniform", "pfsp", "league", "nash"] = Field(
        default="pfsp",
        description="latest: the newest opponents; uniform: the whole pool; pfsp: weighted by how often they win; "
        "league: pfsp with exploiters and the scripted players kept in the pool (AlphaStar's league); nash: the "
        "league with the Nash mixture of the pools' meta-game in place of pfsp (PSRO's meta-solver)",
    )
    nash_games: int = Field(
        default=100, ge=1, le=100_000,
        description="(ours) nash: games each new pairing of the two pools plays for the meta-game's capture matrix "
        "(its CPU counts in the run's budget)",
    )
    pfsp_power: Real = Field(default=2.0, gt=0, description="(ours) PFSP weight = P(opponent wins)^power")
    pfsp_prior_episodes: Real = Field(
        default=10.0, gt=0, description="(ours) pseudo-episodes of the prior (a tournament's prediction, else 0.5)"
    )
    pfsp_decay: Real = Field(
        default=0.5, ge=0, le=1, description="(ours) share of an opponent's record kept when the learner moves on a round"
    )
    league_floor: Real = Field(
        default=0.2, ge=0, le=1, description="(ours) league: the share of games the scripted players keep, together"
    )
    league_floor_split: Literal["uniform", "pfsp"] = Field(
        default="uniform",
        description="(ours) league: the floor split among the scripted players alike (uniform), or by their pfsp "
        "weights, most to those that still beat the learner (pfsp)",
    )
    league_exploiter_share: Real = Field(
        default=0.0, ge=0, le=1,
        description="(ours) league: the share of games the exploiters that joined the pool keep, together, split by "
        "their pfsp weights (AlphaStar's main agents spend games on the league's exploiters); 0: they are drawn by "
        "pfsp like any other checkpoint",
    )
    league_exploiter_every: int = Field(
        default=1, ge=0, le=100_000,
        description="(ours) league: the exploiters train in every k-th round (1: every round, as AlphaStar's; 0: "
        "never, the main agents' pools keep only the scripted players and their own checkpoints)",
    )
    league_exploiter_roles: list[Role] = Field(
        default=["pursuer", "evader"], min_length=1,
        description="(ours) league: the sides that have an exploiter (an evader exploiter finds the main pursuer's "
        "holes, a pursuer exploiter the main evader's)",
    )
    league_exploiter_after: Real = Field(
        default=0.0, ge=0, le=100_000,
        description="(ours) league: CPU-hours the run spends before its exploiters train (a run of hours can leave "
        "its first hours to the main agents and call the exploiters in once what is left to find are holes)",
    )
    exploiter_join: Real = Field(
        default=0.5, gt=0, le=1,
        description="(ours) league: an exploiter joins its side's pool when it wins this share of its turn's games "
        "(or of its join games, with exploiter_join_games)",
    )
    exploiter_join_games: int = Field(
        default=0, ge=0, le=100_000,
        description="(ours) league: N > 0: after its turn the exploiter's final network plays N games against the "
        "main agent it trained against, and these decide whether it joins (AlphaStar's exploiters join on their win "
        "rate against the main agents); 0: its record over the whole turn, learning included, decides",
    )
    league_exploiter_timeout: int = Field(
        default=0, ge=0, le=100_000,
        description="(ours) league: an exploiter joins its side's pool at the end of its k-th turn without joining, "
        "whatever it won (AlphaStar's timeout), and starts afresh; 0: it joins only by winning exploiter_join",
    )

    average_last: int = Field(
        default=10, ge=0, le=100_000,
        description="(ours) after every round each main learner's average.zip is the mean of the weights of its "
        "last k rounds played after the curriculum (fewer while the run is younger; the newest round alone while "
        "the curriculum runs), the player a run hands over; 0: none",
    )

    @model_validator(mode="after")
    def _league_alternates(self) -> SelfPlay:
        if self.opponents in ("league", "nash") and self.schedule != "alternating":
            raise ValueError(f"opponents '{self.opponents}' needs the alternating schedule (the simultaneous one has "
                             "no pools)")
        if self.league_floor + self.league_exploiter_share > 1:
            raise ValueError(f"league_floor ({self.league_floor}) and league_exploiter_share "
                             f"({self.league_exploiter_share}) together keep more than all the games")
        return self


ALGOS = ("td3", "ddpg", "sac", "tqc", "crossq")  # the algorithms of pecli.models.algorithms


class Training(_Model):
    """How a learner is trained (Stable-Baselines3 / sb3-contrib off-policy algorithms on a frozen-opponent view)."""

    algo: Literal[ALGOS] = Field(default="td3", description="td3, ddpg, sac, tqc or crossq")  # type: ignore[valid-type]
    belief: Literal["none", "bimdn", "bimdn-mixed", "ukf", "image"] = Field(
        default="none", description="what the actor adds to its observation about the unseen opponent"
    )
    steps: Count = Field(default=1_000_000, ge=1, le=MAX_STEPS,
                         description="budget in learner transitions (all envs together)")
    n_envs: Count = Field(default=8, ge=1, le=MAX_COUNT, description="games stepped together in one process")
    frame_skip: Count = Field(default=2, ge=1, le=1000, description="game steps each action is held for")
    frame_stack: Count = Field(default=2, ge=1, le=1000, description="observations stacked into the actor's input")
    history_length: Count = Field(default=200, ge=1, le=MAX_HISTORY,
                                  description="game steps the belief window looks back")
    history_stride: Count = Field(default=10, ge=1, le=MAX_HISTORY,
                                  description="keep every k-th step of the window (10: 1 Hz)")
    reward_scale: Real = Field(default=0.001, gt=0, description="rewards are multiplied by this for learning")
    learning_rate: Real = Field(default=5e-4, gt=0)
    buffer_size: Count = Field(default=100_000, ge=1, le=MAX_BUFFER)
    batch_size: Count = Field(default=512, ge=1, le=MAX_BATCH)
    gamma: Real = Field(default=0.99, gt=0, le=1)
    tau: Real = Field(default=0.005, gt=0, le=1)
    n_step: Count = Field(default=1, ge=1, le=1000,
                          description="n-step returns: rewards summed over n transitions before bootstrapping")
    action_noise: Real = Field(default=0.1, ge=0, description="std of the Gaussian exploration noise")
    net_arch: list[Annotated[Count, Field(ge=1, le=MAX_WIDTH)]] = Field(
        default=[128, 128], min_length=1, max_length=MAX_DEPTH, description="hidden layer widths of actor and critics"
    )
    learning_starts: Count = Field(default=5_000, ge=0, le=MAX_STEPS,
                                   description="transitions collected before learning")
    train_freq: Count = Field(default=1, ge=1, le=MAX_COUNT, description="vector-env steps between updates")
    gradient_steps: Count = Field(default=2, ge=1, le=10_000, description="gradient steps per update")
    checkpoint_every: Count = Field(default=250, ge=1, le=MAX_COUNT, description="episodes between zoo checkpoints")
    eval_every: Count = Field(default=0, ge=0, le=MAX_STEPS, description="transitions between evaluations; 0: none")
    eval_episodes: Count = Field(default=200, ge=1, le=MAX_GAMES)
    torch_threads: Count = Field(default=1, ge=1, le=1024,
                                 description="torch threads per process (1 is fastest on a shared CPU)")
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
    dt: Real = Field(default=0.1, gt=0, le=MAX_DT, description="time step, s")
    horizon: Count = Field(default=400, ge=1, le=MAX_HORIZON, description="steps before a timeout (evader wins)")
    capture_radius: Real = Field(default=0.25, gt=0, le=MAX_METRES, description="agent radius c; capture when d <= 2c")
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

        exclude = {"name", "description", "training"}
        ours, theirs = (dotted(s.model_dump(exclude=exclude, mode="json")) for s in (self, other))
        return [(key, ours.get(key), theirs.get(key)) for key in sorted(ours.keys() | theirs.keys())
                if ours.get(key) != theirs.get(key)]


def dotted(data: Any, prefix: str = "") -> dict[str, Any]:
    """A nested mapping as ``{"dotted.key": leaf}`` (an empty mapping, or anything else, is a leaf):
    ``{"arena": {"width": 8.0}}`` -> ``{"arena.width": 8.0}``."""
    if not isinstance(data, dict) or not data:
        return {prefix.rstrip("."): data}
    return {k: v for key, value in data.items() for k, v in dotted(value, f"{prefix}{key}.").items()}


def builtin_config_dir() -> Path:
    """The folder holding the built-in ``configs/*.yaml`` (source checkout or installed data files)."""
    for candidate in (Path(__file__).resolve().parents[1] / "configs", Path(sys.prefix) / "share" / "pecli" / "configs"):
        if candidate.is_dir():
            return candidate
    return Path("configs")


BUILTIN_SCENARIOS = ("car_vs_car", "league", "paper", "point_mass", "quick", "robots", "tuned")
BUILTIN_EXPERIMENTS = ("exploitability", "schedules", "smoke", "strength", "strength-exploiters", "strength-floor",
                       "strength-joingames", "strength-lite", "strength-share", "strength-small", "table1",
                       "table1-small", "table2")
"""pecli's own scenarios and experiments, by name: a file a user saves beside them never becomes a built-in."""


def builtin_names() -> list[str]:
    """Names of the built-in scenarios (``paper``, ``quick``, ...)."""
    return sorted(name for name in BUILTIN_SCENARIOS if (builtin_config_dir() / f"{name}.yaml").is_file())


def builtin_experiment_dir() -> Path:
    """The folder holding the built-in experiments (``configs/experiments``)."""
    return builtin_config_dir() / "experiments"


def builtin_experiments() -> list[str]:
    """Names of the built-in experiments (``table1``, ``strength``, ...)."""
    return sorted(name for name in BUILTIN_EXPERIMENTS if (builtin_experiment_dir() / f"{name}.yaml").is_file())


def resolve_config_path(path_or_name: str | Path) -> Path:
    """A path as given, or the built-in config of that name."""
    path = Path(path_or_name)
    if path.exists() or path.suffix in (".yaml", ".yml") or len(path.parts) > 1 or str(path) not in BUILTIN_SCENARIOS:
        return path
    return builtin_config_dir() / f"{path_or_name}.yaml"


def _describe(error: dict[str, Any]) -> str:
    """One readable phrase for one pydantic error."""
    kind, msg = error["type"], error["msg"]
    if kind == "extra_forbidden":
        return "unknown key"
    if kind == "missing":
        return "missing required key"
    shown = error.get("input")
    if kind in ("int_type", "float_type") and isinstance(shown, bool):
        return f"a number is expected here, not the boolean {str(shown).lower()}"
    if kind == "bool_type":
        return f"true or false is expected here (got {shown!r})"
    if kind == "finite_number":
        return f"must be a finite number (got {shown!r})"
    msg = msg.removeprefix("Value error, ")
    if "input" in error and kind not in ("model_type", "union_tag_invalid"):
        if not isinstance(shown, dict | list):
            return f"{msg} (got {shown!r})"
    return msg


def _location(error: dict[str, Any]) -> str:
    # drop the discriminator tags pydantic adds to the path of a tagged union (e.g. 'car'); quote odd keys
    parts = [str(p) if str(p).isprintable() else repr(p) for p in error["loc"] if p not in ("car", "point_mass")]
    return ".".join(parts)


def _size(size: int) -> str:
    """``~1,144 GiB``, ``~3.1 GiB``, ``~220 MiB``."""
    if size >= 10 * 2**30:
        return f"~{size / 2**30:,.0f} GiB"
    return f"~{size / 2**30:.2g} GiB" if size >= 2**30 else f"~{size / 2**20:.3g} MiB"


def _state_dim(agent: CarAgent | PointMassAgent) -> int:
    return 5 if agent.kind == "car" else 4  # (s_x, s_y, delta, v, psi) or (s_x, s_y, v_x, v_y)


def _mlp_parameters(sizes: list[int]) -> int:
    return sum(a * b + b for a, b in zip(sizes, sizes[1:]))


def memory_estimate(scenario: Scenario) -> dict[str, int]:
    """Roughly the bytes one learner of ``scenario`` allocates, by the setting that decides each part
    (``pecli selfplay`` holds two learners in one process: about twice this).

    ``training.n_envs``: the batched games with their frame stacks and history windows (about 1.5 KiB
    per game besides the windows, measured); ``training.buffer_size``: SB3's replay buffer (float32
    observations and next observations, actions, rewards, flags); ``training.belief_settings.buffer_size``:
    a learned belief's (window, position) pairs; ``training.net_arch``: actor and critics with their
    targets, gradients, Adam moments and one batch's activations; ``training.belief_settings.hidden``:
    the BiMDN's LSTM and one batch's activations.
    """
    t, b = scenario.training, scenario.training.belief_settings
    kp, ke = _state_dim(scenario.pursuer), _state_dim(scenario.evader)
    dim = kp + ke + 2  # one observation row: own state, opponent state, seen flag, time
    belief = t.belief != "none"
    window = -(-t.history_length // t.history_stride)
    features = (2 * b.samples if t.belief == "bimdn-mixed" else 2) if belief else 0
    obs = t.frame_stack * dim + (window * dim + features if belief else 0)
    transition = 2 * (obs + kp + ke + 1 + 2) + 2 + 3  # obs and next obs (+ state, opp_action), action, flags
    per_game = 1536 + 4 * dim * (2 * t.frame_stack + (t.history_length + 2 * window if belief else 0))
    critics = 2 if t.algo == "td3" else 1
    actor = _mlp_parameters([t.frame_stack * dim + features, *t.net_arch, 2])
    critic = _mlp_parameters([obs + kp + ke + 1 + 2 + 2, *t.net_arch, 1])
    activations = 2 * t.batch_size * sum(t.net_arch) * (1 + critics)  # forward and backward
    estimate = {
        "training.n_envs": t.n_envs * per_game,
        "training.buffer_size": 4 * t.buffer_size * transition,
        "training.net_arch": 4 * (5 * (actor + critics * critic) + activations),
    }
    if t.belief in ("bimdn", "bimdn-mixed", "image"):
        lstm = 2 * 4 * b.hidden * (dim + b.hidden + 2)  # two directions, four gates
        estimate["training.belief_settings.buffer_size"] = 4 * b.buffer_size * (window * dim + 3)
        estimate["training.belief_settings.hidden"] = 4 * (5 * lstm + 12 * b.batch_size * window * 2 * b.hidden)
    return estimate


_UNITS = {"training.n_envs": "games", "training.buffer_size": "transitions",
          "training.belief_settings.buffer_size": "pairs", "training.belief_settings.hidden": "LSTM units"}


def check_resources(scenario: Scenario, source: str = "<dict>") -> None:
    """:class:`ConfigError` when ``scenario`` would make a training process allocate implausibly much
    (more than :data:`MAX_GAMES` games, or more than :data:`MEMORY_LIMIT` by :func:`memory_estimate`)."""
    estimate = memory_estimate(scenario)
    n_envs = scenario.training.n_envs
    if n_envs > MAX_GAMES:
        raise ConfigError(f"{source}: training.n_envs: {n_envs} games need {_size(estimate['training.n_envs'])}; "
                          f"one process steps at most {MAX_GAMES} games")
    total = sum(estimate.values())
    if total > MEMORY_LIMIT:
        key = max(estimate, key=estimate.__getitem__)
        value: Any = scenario.training
        for part in key.split(".")[1:]:
            value = getattr(value, part)
        what = f"{value} {_UNITS[key]}" if key in _UNITS else str(value)
        raise ConfigError(f"{source}: {key}: {what} need {_size(estimate[key])} (a training process of this "
                          f"scenario needs {_size(total)} in all; the limit is {_size(MEMORY_LIMIT)})")


def scenario_from_dict(data: Any, source: str = "<dict>") -> Scenario:
    """Validate ``data`` into a :class:`Scenario`; errors become one-line :class:`ConfigError`."""
    if not isinstance(data, dict):
        raise ConfigError(f"{source}: a scenario must be a mapping of keys to values, not {type(data).__name__}")
    try:
        scenario = Scenario.model_validate(data)
    except ValidationError as exc:
        raise ConfigError(validation_message(exc, source)) from None
    check_resources(scenario, source)
    return scenario


def validation_message(exc: ValidationError, source: str) -> str:
    """One line for a pydantic error: ``<source>: <key.path>: <problem> (and N more problems)``."""
    errors = exc.errors()
    first = errors[0]
    where = _location(first)
    more = f" (and {len(errors) - 1} more problem{'s' if len(errors) > 2 else ''})" if len(errors) > 1 else ""
    return f"{source}: {where or 'top level'}: {_describe(first)}{more}"


class StrictLoader(yaml.SafeLoader):
    """``yaml.SafeLoader`` that refuses a key given twice in one mapping (YAML would keep the last silently)."""

    def construct_mapping(self, node: yaml.MappingNode, deep: bool = False) -> dict[Any, Any]:
        first_line: dict[Any, int] = {}
        for key_node, _ in node.value:
            if key_node.tag == "tag:yaml.org,2002:merge":  # '<<: *base' keys may be overridden on purpose
                continue
            key = self.construct_object(key_node, deep=True)
            try:
                seen = key in first_line
            except TypeError:  # an unhashable key: SafeLoader's own error says so
                continue
            if seen:
                raise yaml.constructor.ConstructorError(
                    "while constructing a mapping", node.start_mark,
                    f"duplicate key {key!r} (first given on line {first_line[key]})", key_node.start_mark)
            first_line[key] = key_node.start_mark.line + 1
        return super().construct_mapping(node, deep=deep)


MAX_FILE_BYTES = 1 << 20  # a scenario or experiment file is a page of YAML


def read_yaml(path: Path) -> Any:
    """The content of the YAML file ``path`` (safe, duplicate keys refused); :class:`ConfigError` in one
    line (with the line number) if it cannot be read."""
    try:
        if path.stat().st_size > MAX_FILE_BYTES:
            raise ConfigError(f"{path}: {path.stat().st_size:,} bytes is too large for a configuration file "
                              f"(at most {MAX_FILE_BYTES:,})")
        return yaml.load(path.read_text(), Loader=StrictLoader)  # noqa: S506 (a SafeLoader)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f" line {mark.line + 1}" if mark is not None else ""
        problem = " ".join(str(getattr(exc, "problem", None) or "not valid YAML").split())
        raise ConfigError(f"{path}:{where}: {problem}") from None
    except RecursionError:
        raise ConfigError(f"{path}: nested too deeply to be read") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise ConfigError(f"{path}: cannot read: {exc}") from None
    except ValueError as exc:  # an integer of more digits than Python converts (4300)
        raise ConfigError(f"{path}: {exc}") from None


def load_scenario(path_or_name: str | Path) -> Scenario:
    """Read and validate a scenario from a YAML file or a built-in name (see :func:`builtin_names`)."""
    path = resolve_config_path(path_or_name)
    if not path.is_file():
        known = ", ".join(builtin_names())
        raise ConfigError(f"config not found: {path_or_name} (give a YAML file or one of: {known})")
    return scenario_from_dict(read_yaml(path), source=str(path))
