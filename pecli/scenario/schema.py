"""The game a scenario describes: the two agents, their sensors, the arena and the reward (paper §III)."""

from __future__ import annotations

import json
import math
from typing import Annotated, Any, Literal

from pydantic import Field, field_validator, model_validator

from pecli.io import text_digest
from pecli.scenario.training import Training
from pecli.scenario.values import MAX_DT, MAX_HORIZON, MAX_METRES, MAX_RATE, TWO_PI, Angle, Count, Real, _Model, dotted


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

    def with_sensor_range(self, range_m: float, roles: tuple[str, ...] = ("pursuer", "evader")) -> Scenario:
        """This scenario with the sensors of ``roles`` reaching ``range_m`` metres (fields of view kept).

        A range beyond the arena's diagonal makes the opponent seen everywhere: full observation.
        """
        if not 0.0 < range_m <= MAX_METRES:
            raise ValueError(f"a sensor range must be in (0, {MAX_METRES:g}] m, got {range_m!r}")
        update = {}
        for role in roles:
            agent = self.agent(role)
            update[role] = agent.model_copy(update={"sensor": agent.sensor.model_copy(update={"range": range_m})})
        return self.model_copy(update=update)

    def fingerprint(self) -> str:
        """A short hash of everything that changes the game (not the name, description or training)."""
        payload = self.model_dump(exclude={"name", "description", "training"}, mode="json")
        text = json.dumps(payload, sort_keys=True, separators=(",", ":"))
        return text_digest(text)

    def differences(self, other: Scenario) -> list[tuple[str, Any, Any]]:
        """What makes ``other`` another game (what :meth:`fingerprint` covers): ``[(key, ours, theirs)]``,
        e.g. ``[("horizon", 150, 200)]``."""

        exclude = {"name", "description", "training"}
        ours, theirs = (dotted(s.model_dump(exclude=exclude, mode="json")) for s in (self, other))
        return [
            (key, ours.get(key), theirs.get(key))
            for key in sorted(ours.keys() | theirs.keys())
            if ours.get(key) != theirs.get(key)
        ]
