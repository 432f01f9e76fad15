"""What a Hamilton–Jacobi solution depends on: the game's numbers, the model, the grid, the order, the horizon.

    >>> problem = Problem.for_scenario(load_scenario("point_mass"))      # abs8d, default grid, maxmin, T
    >>> problem.grid.describe(), problem.key()
    ('5x5x15x15x5x5x15x15', '...')

Two problems with the same :meth:`Problem.key` have the same solution, so the key names the
cache file. The scenario's name, sensors, rewards and training settings do not enter it: they
do not change the value.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass
from functools import cached_property
from typing import Literal

from pecli.errors import ConfigError
from pecli.hj.grid import DEFAULT_MODEL, DEFAULT_SIZES, MODELS, Grid, Model, make_grid
from pecli.io import text_digest
from pecli.scenario import PointMassAgent, Scenario
from pecli.text import article

Order = Literal["maxmin", "minmax"]
ORDERS: tuple[Order, ...] = ("maxmin", "minmax")
DEFAULT_ORDER: Order = "maxmin"
Backend = Literal["numpy", "hj-reachability"]
BACKENDS: tuple[Backend, ...] = ("numpy", "hj-reachability")
SOLVER_VERSION = 2  # part of every key: bump it when the solver's results change


@dataclass(frozen=True)
class PointMassGame:
    """The numbers of a point mass vs point mass game that the value depends on (SI units)."""

    width: float  # arena, m
    height: float
    dt: float  # s
    capture_distance: float  # 2c, m
    pursuer_v_max: float  # per axis, m/s
    evader_v_max: float
    pursuer_a_max: float  # per axis, m/s^2
    evader_a_max: float

    @classmethod
    def of(cls, scenario: Scenario) -> PointMassGame:
        """The game of ``scenario``; :class:`ConfigError` unless both players are point masses."""
        p, e = scenario.pursuer, scenario.evader
        if not (isinstance(p, PointMassAgent) and isinstance(e, PointMassAgent)):
            raise ConfigError(
                f"the Hamilton-Jacobi baseline is for point mass vs point mass; scenario '{scenario.name}' "
                f"has {article(p.kind)} pursuer and {article(e.kind)} evader (try --config point_mass)"
            )
        return cls(
            width=scenario.arena.width,
            height=scenario.arena.height,
            dt=scenario.dt,
            capture_distance=scenario.capture_distance,
            pursuer_v_max=p.v_max,
            evader_v_max=e.v_max,
            pursuer_a_max=p.a_max,
            evader_a_max=e.a_max,
        )


@dataclass(frozen=True)
class Problem:
    """One value function to compute.

    Attributes:
        game: the game's numbers.
        model: ``abs8d`` (both players' positions and velocities: the walls), ``rel4d`` (relative position
            and velocity) or ``rel6d`` (relative position, both velocities); see :mod:`pecli.hj.grid`.
        sizes: nodes per position axis and per velocity axis as asked for (``rel4d`` snaps its
            velocity axis, see :mod:`pecli.hj.grid`).
        order: ``maxmin`` (the evader commits first and the pursuer answers) or ``minmax`` (the other way).
        steps: the horizon in game steps.
        backend: ``numpy`` (:mod:`pecli.hj.solver`, the game's discrete time) or ``hj-reachability``
            (:mod:`pecli.hj.reachability`, continuous time, ``rel4d`` only).
    """

    game: PointMassGame
    model: Model = DEFAULT_MODEL
    sizes: tuple[int, int] = DEFAULT_SIZES[DEFAULT_MODEL]
    order: Order = DEFAULT_ORDER
    steps: int = 100
    backend: Backend = "numpy"

    def __post_init__(self) -> None:
        if self.model not in MODELS:
            raise ConfigError(f"unknown HJ model '{self.model}' (known: {', '.join(MODELS)})")
        if self.order not in ORDERS:
            raise ConfigError(f"unknown order '{self.order}' (known: {', '.join(ORDERS)})")
        if self.steps < 1:
            raise ConfigError(f"the horizon must be at least 1 step, got {self.steps}")
        if self.backend not in BACKENDS:
            raise ConfigError(f"unknown HJ backend '{self.backend}' (known: {', '.join(BACKENDS)})")
        if self.backend == "hj-reachability" and self.model != "rel4d":
            raise ConfigError(f"the hj-reachability backend solves rel4d only, not {self.model}")
        object.__setattr__(self, "sizes", tuple(int(n) for n in self.sizes))
        self.grid  # noqa: B018 - validates the sizes now, not at the first use

    @classmethod
    def for_scenario(
        cls,
        scenario: Scenario,
        model: Model = DEFAULT_MODEL,
        sizes: tuple[int, int] | None = None,
        order: Order = DEFAULT_ORDER,
        steps: int | None = None,
        backend: Backend = "numpy",
    ) -> Problem:
        """The problem of ``scenario``'s game; the grid defaults to the model's, the horizon to T."""
        if model not in MODELS:
            raise ConfigError(f"unknown HJ model '{model}' (known: {', '.join(MODELS)})")
        return cls(
            game=PointMassGame.of(scenario),
            model=model,
            sizes=sizes or DEFAULT_SIZES[model],
            order=order,
            steps=scenario.horizon if steps is None else steps,
            backend=backend,
        )

    @cached_property
    def grid(self) -> Grid:
        g = self.game
        return make_grid(
            self.model,
            self.sizes,
            extents=(g.width, g.height),
            speed_limits=(g.pursuer_v_max, g.evader_v_max),
            evader_step=g.evader_a_max * g.dt,
        )

    @property
    def dt(self) -> float:
        return self.game.dt

    def to_dict(self) -> dict:
        return {
            "game": asdict(self.game),
            "model": self.model,
            "sizes": list(self.sizes),
            "order": self.order,
            "steps": self.steps,
            "backend": self.backend,
        }

    @classmethod
    def from_dict(cls, data: dict) -> Problem:
        return cls(
            game=PointMassGame(**data["game"]),
            model=data["model"],
            sizes=tuple(data["sizes"]),
            order=data["order"],
            steps=int(data["steps"]),
            backend=data["backend"],
        )

    def key(self) -> str:
        """A hash of every parameter and of the solver's version: equal keys, equal solutions."""
        return _digest(self.to_dict())

    def cache_key(self) -> str:
        """Like :meth:`key`, but with the grid as the axes actually solved on, so that requested sizes
        ``rel4d`` snaps to one grid share one cached solution."""
        payload = {key: value for key, value in self.to_dict().items() if key != "sizes"}
        payload["axes"] = [[axis.name, axis.low, axis.high, axis.n] for axis in (*self.grid.x_axes, *self.grid.y_axes)]
        return _digest(payload)

    def describe(self) -> str:
        """``rel4d 23x81x23x81 maxmin T=100`` style."""
        backend = "" if self.backend == "numpy" else f" ({self.backend})"
        return f"{self.model} {self.grid.describe()} {self.order} T={self.steps}{backend}"


def _digest(payload: dict) -> str:
    """16 hex digits of the SHA-256 of ``payload`` and the solver's version, as canonical JSON."""
    text = json.dumps({"solver": SOLVER_VERSION, **payload}, sort_keys=True)
    return text_digest(text)
