"""One pursuit-evasion game in plain Python floats: the scalar mirror of :class:`~pecli.game.game.Game`.

:class:`Game` steps ``n`` games as NumPy arrays. At ``n = 1`` the cost of a step is almost all
per-call NumPy overhead (dozens of ufunc calls on length-1 arrays, about 95 us a step), which
makes a PettingZoo environment over a single game slower than it needs to be. :class:`SingleGame`
plays exactly one game with Python floats and the :mod:`math` module in the hot path, and only
builds NumPy arrays for the observations it hands out.

    >>> game = SingleGame(load_scenario("paper"), seed=0)
    >>> obs = game.reset()                                   # {"pursuer": (11,), "evader": (11,)} float32
    >>> result = game.step([0.5, 1.0], [-1.0, 0.2])          # actions in [-1, 1]

Its semantics are those of ``Game(scenario, n=1, seed=seed, auto_reset=False)``: the same start
states (the same counter-based random numbers), dynamics (CommonRoad KS car with its input
constraints, point mass, explicit Euler, walls), sensors, observations in both frames, rewards,
capture / timeout rules, and the same freeze after an episode ends. ``tests/test_single_game.py``
keeps the two equal; a change to either must keep that test passing. The only differences are
rounding: ``math.cos``/``sin``/``tan`` may differ from NumPy's by an ulp, and the own-frame
observation block is scaled in float64 here but in float32 in :class:`ObservationCodec`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from pecli.game.game import START_CANDIDATES
from pecli.game.seeding import counter_uniform, fresh_seed
from pecli.roles import ROLES, Role
from pecli.scenario import CarAgent, PointMassAgent, Scenario

_PI = math.pi
_TWO_PI = 2.0 * math.pi
_INV_PI = 1.0 / math.pi


def _clip(x: float, lo: float, hi: float) -> float:
    """``np.clip`` for one float."""
    return lo if x < lo else hi if x > hi else x


def _wrap_near(angle: float) -> float:
    """Wrap an angle in [-3 pi, 3 pi) to [-pi, pi), rad (``dynamics.wrap_near`` for one float)."""
    if angle >= _PI:
        angle -= _TWO_PI
    if angle < -_PI:
        angle += _TWO_PI
    return angle


class _Car:
    """CommonRoad KS car of one game: ``x, y`` (m), ``delta`` (rad), ``v`` (m/s), ``psi`` (rad).

    ``cos_psi`` and ``sin_psi`` cache the trigonometry of the heading, as :class:`CarDynamics` does.
    """

    __slots__ = (
        "a_max", "cos_psi", "delta", "has_heading", "psi", "scale", "sin_psi", "speed_max", "state_dim",
        "steer_max", "steer_min", "steer_rate_max", "v", "v_max", "v_min", "v_switch", "wheelbase", "x", "y",
        "_inverse_scale",
    )  # fmt: skip

    def __init__(self, params: CarAgent, half_x: float, half_y: float) -> None:
        self.has_heading = True
        self.state_dim = 5
        self.steer_min, self.steer_max = params.steer_min, params.steer_max
        self.steer_rate_max, self.a_max = params.steer_rate_max, params.a_max
        self.v_min, self.v_max, self.v_switch = params.v_min, params.v_max, params.v_switch
        self.wheelbase = params.wheelbase
        self.speed_max = params.speed_max
        # normalisation constants of (x, y, delta, v, psi), as CarDynamics.scale
        self.scale = (half_x, half_y, params.steer_abs_max, params.speed_max, math.pi)
        self._inverse_scale = tuple(1.0 / s for s in self.scale)
        self.set_state((0.0, 0.0, 0.0, 0.0, 0.0))

    def set_state(self, state: Sequence[float]) -> None:
        """Set the SI state ``(x, y, delta, v, psi)`` and refresh the heading cache."""
        self.x, self.y, self.delta, self.v, self.psi = (float(s) for s in state)
        self.cos_psi, self.sin_psi = math.cos(self.psi), math.sin(self.psi)

    def state(self) -> list[float]:
        """The SI state ``[x, y, delta, v, psi]``."""
        return [self.x, self.y, self.delta, self.v, self.psi]

    def normalised(self) -> list[float]:
        """The state times the inverse normalisation constants (ObservationCodec's own block)."""
        ix, iy, idelta, iv, ipsi = self._inverse_scale
        return [self.x * ix, self.y * iy, self.delta * idelta, self.v * iv, self.psi * ipsi]

    def step(self, steer_action: float, accel_action: float, dt: float, speed_scale: float) -> None:
        """One Euler step of ``dt`` s with normalised actions; CommonRoad's input constraints apply."""
        delta, v, psi = self.delta, self.v, self.psi
        v_lo, v_hi = self.v_min * speed_scale, self.v_max * speed_scale
        steer_rate = _clip(steer_action, -1.0, 1.0) * self.steer_rate_max  # rad/s
        if (delta <= self.steer_min and steer_rate <= 0.0) or (delta >= self.steer_max and steer_rate >= 0.0):
            steer_rate = 0.0
        accel = _clip(accel_action, -1.0, 1.0) * self.a_max  # m/s^2
        if self.v_switch is not None and v > self.v_switch:
            accel = min(accel, self.a_max * self.v_switch / v)
        if (v <= v_lo and accel <= 0.0) or (v >= v_hi and accel >= 0.0):
            accel = 0.0
        v_dt = v * dt
        self.x = v_dt * self.cos_psi + self.x
        self.y = v_dt * self.sin_psi + self.y
        self.delta = _clip(delta + steer_rate * dt, self.steer_min, self.steer_max)
        self.v = _clip(v + accel * dt, v_lo, v_hi)
        psi = _wrap_near(psi + v_dt * math.tan(delta) / self.wheelbase)
        self.psi, self.cos_psi, self.sin_psi = psi, math.cos(psi), math.sin(psi)

    def walls(self, half_x: float, half_y: float) -> None:
        """Clip the position to the arena (m); a car that touched a wall stops (v = 0)."""
        if abs(self.x) > half_x or abs(self.y) > half_y:
            self.x = _clip(self.x, -half_x, half_x)
            self.y = _clip(self.y, -half_y, half_y)
            self.v = 0.0

    def velocity(self) -> tuple[float, float]:
        """World-frame velocity ``(v_x, v_y)``, m/s."""
        return self.v * self.cos_psi, self.v * self.sin_psi

    def sees(self, dx: float, dy: float, distance: float, fov: float, sensing_range: float) -> bool:
        """The wedge test of ``sensors.in_view``: target offset ``dx, dy`` (m) within range and ``fov`` (rad)."""
        if not distance <= sensing_range:
            return False
        return fov >= _TWO_PI or self.cos_psi * dx + self.sin_psi * dy >= math.cos(0.5 * fov) * distance


class _PointMass:
    """CommonRoad PM of one game: ``x, y`` (m), ``vx, vy`` (m/s); limits per axis."""

    __slots__ = ("a_max", "has_heading", "scale", "speed_max", "state_dim", "v_max", "vx", "vy", "x", "y",
                 "_inverse_scale")  # fmt: skip

    def __init__(self, params: PointMassAgent, half_x: float, half_y: float) -> None:
        self.has_heading = False
        self.state_dim = 4
        self.v_max, self.a_max = params.v_max, params.a_max
        self.speed_max = params.speed_max
        # normalisation constants of (x, y, vx, vy), as PointMassDynamics.scale
        self.scale = (half_x, half_y, params.v_max, params.v_max)
        self._inverse_scale = tuple(1.0 / s for s in self.scale)
        self.set_state((0.0, 0.0, 0.0, 0.0))

    def set_state(self, state: Sequence[float]) -> None:
        """Set the SI state ``(x, y, vx, vy)``."""
        self.x, self.y, self.vx, self.vy = (float(s) for s in state)

    def state(self) -> list[float]:
        """The SI state ``[x, y, vx, vy]``."""
        return [self.x, self.y, self.vx, self.vy]

    def normalised(self) -> list[float]:
        """The state times the inverse normalisation constants (ObservationCodec's own block)."""
        ix, iy, ivx, ivy = self._inverse_scale
        return [self.x * ix, self.y * iy, self.vx * ivx, self.vy * ivy]

    def step(self, ax_action: float, ay_action: float, dt: float, speed_scale: float) -> None:
        """One Euler step of ``dt`` s; an acceleration pushing past the speed limit is zeroed."""
        v_lim = self.v_max * speed_scale  # m/s, per axis
        vx, vy = self.vx, self.vy
        ax = _clip(ax_action, -1.0, 1.0) * self.a_max  # m/s^2
        ay = _clip(ay_action, -1.0, 1.0) * self.a_max
        if (vx <= -v_lim and ax <= 0.0) or (vx >= v_lim and ax >= 0.0):
            ax = 0.0
        if (vy <= -v_lim and ay <= 0.0) or (vy >= v_lim and ay >= 0.0):
            ay = 0.0
        self.x = self.x + vx * dt
        self.y = self.y + vy * dt
        self.vx = _clip(vx + ax * dt, -v_lim, v_lim)
        self.vy = _clip(vy + ay * dt, -v_lim, v_lim)

    def walls(self, half_x: float, half_y: float) -> None:
        """Clip the position to the arena (m) and drop the velocity component into the wall."""
        if abs(self.x) > half_x:
            self.x = _clip(self.x, -half_x, half_x)
            if self.vx * self.x > 0.0:
                self.vx = 0.0
        if abs(self.y) > half_y:
            self.y = _clip(self.y, -half_y, half_y)
            if self.vy * self.y > 0.0:
                self.vy = 0.0

    def velocity(self) -> tuple[float, float]:
        """World-frame velocity ``(v_x, v_y)``, m/s."""
        return self.vx, self.vy

    def sees(self, dx: float, dy: float, distance: float, fov: float, sensing_range: float) -> bool:
        """A point mass has no heading: its sensor is a disk, whatever ``fov`` says."""
        return distance <= sensing_range


_Player = _Car | _PointMass


def _make_player(params: CarAgent | PointMassAgent, half_x: float, half_y: float) -> _Player:
    return _Car(params, half_x, half_y) if isinstance(params, CarAgent) else _PointMass(params, half_x, half_y)


Action = Sequence[float] | np.ndarray  # two numbers in [-1, 1]


def _action(action: Action, role: Role) -> tuple[float, float]:
    """Two Python floats from a length-2 action (clipping happens in the dynamics)."""
    try:
        a, b = action.tolist() if isinstance(action, np.ndarray) else action
        return float(a), float(b)
    except (TypeError, ValueError):
        raise ValueError(f"{role} action must be two numbers, got {action!r}") from None


@dataclass(slots=True)
class SingleStep:
    """What one step of a :class:`SingleGame` returns (``StepResult`` of one game, as scalars)."""

    obs: dict[Role, np.ndarray]  # (obs_dim,) float32 per role
    rewards: dict[Role, float]  # unscaled, zero-sum
    captured: bool  # this step ended the episode with a capture
    timed_out: bool  # this step reached the horizon without a capture
    done: bool  # captured or timed_out
    steps: int  # steps played in the episode
    distance: float  # distance between the players after the step, m
    seen: dict[Role, bool]  # whether each role sees its opponent after the step


class SingleGame:
    """One game of ``scenario``, equal to ``Game(scenario, n=1, seed=seed, auto_reset=False)``.

    Args:
        scenario: the game to play.
        seed: seed of the start states; ``None`` draws one from the OS.
    """

    def __init__(self, scenario: Scenario, seed: int | None = None) -> None:
        self.scenario = scenario
        self.seed = fresh_seed() if seed is None else int(seed)
        half_x, half_y = scenario.arena.half
        self._half_x, self._half_y = half_x, half_y
        self._pursuer = _make_player(scenario.pursuer, half_x, half_y)
        self._evader = _make_player(scenario.evader, half_x, half_y)
        k_p, k_e = self._pursuer.state_dim, self._evader.state_dim
        self.obs_dim: dict[Role, int] = {"pursuer": k_p + k_e + 2, "evader": k_e + k_p + 2}
        self.state_dim = k_p + k_e
        # knobs a curriculum may turn while training, read at every step (as Game's)
        self.fov: dict[Role, float] = {role: scenario.agent(role).sensor.fov for role in ROLES}
        self.speed_scale: dict[Role, float] = {role: 1.0 for role in ROLES}
        self.t = 0
        self.episode = 0
        self.finished = False
        # constants of the hot path
        self._dt = scenario.dt
        self._horizon = scenario.horizon
        self._capture_distance = scenario.capture_distance
        self._reward_capture = scenario.reward.capture
        self._reward_time = scenario.reward.time
        self._reward_distance = scenario.reward.distance
        self._world_frame = scenario.observation_frame == "world"
        self._range = {role: scenario.agent(role).sensor.range for role in ROLES}
        self._inverse_range = {role: 1.0 / r for role, r in self._range.items()}
        self._inverse_velocity_scale = 1.0 / (self._pursuer.speed_max + self._evader.speed_max)
        self._unseen = {"pursuer": [0.0] * k_e, "evader": [0.0] * k_p}  # the zeroed opponent block
        self.reset(seed=self.seed)

    # ------------------------------------------------------------------ state
    def state(self) -> np.ndarray:
        """The privileged full state in SI units, ``(state_dim,)`` float64: pursuer then evader."""
        return np.array(self._pursuer.state() + self._evader.state())

    def normalised_state(self) -> np.ndarray:
        """The full state scaled to [-1, 1], plus ``t/T``: ``(state_dim + 1,)`` float32, for critics."""
        p, e = self._pursuer, self._evader
        values = [x / s for x, s in zip(p.state(), p.scale)] + [x / s for x, s in zip(e.state(), e.scale)]
        return np.array(values + [self.t / self._horizon], dtype=np.float32)

    def set_state(self, state: np.ndarray | Sequence[float], t: int = 0) -> dict[Role, np.ndarray]:
        """Put the game in the SI ``state`` ``(state_dim,)`` at step ``t``; returns the observations."""
        values = np.asarray(state, dtype=np.float64)
        if values.shape not in ((self.state_dim,), (1, self.state_dim)):
            raise ValueError(f"state must have shape {(self.state_dim,)}, got {values.shape}")
        row = values.reshape(-1).tolist()
        k = self._pursuer.state_dim
        self._pursuer.set_state(row[:k])
        self._evader.set_state(row[k:])
        self.t = int(t)
        self.finished = False
        return self.observe()

    # ------------------------------------------------------------------ reset
    def reset(self, seed: int | None = None) -> dict[Role, np.ndarray]:
        """Start a new episode; a new ``seed`` restarts the episode counter. Returns the observations."""
        if seed is not None:
            self.seed = int(seed)
            self.episode = 0
        self._start()
        return self.observe()

    def _start(self) -> None:
        """Sample the start state as ``Game._start`` does for game slot 0 (positions at least 2c apart)."""
        k = START_CANDIDATES
        u = counter_uniform(self.seed, np.array([0]), np.array([self.episode]), 4 * k + 2)[:, 0].tolist()
        self.episode += 1
        hx, hy = self._half_x, self._half_y
        px = [(2 * a - 1) * hx for a in u[0:k]]
        py = [(2 * a - 1) * hy for a in u[k : 2 * k]]
        ex = [(2 * a - 1) * hx for a in u[2 * k : 3 * k]]
        ey = [(2 * a - 1) * hy for a in u[3 * k : 4 * k]]
        dist = [math.sqrt((ex[i] - px[i]) * (ex[i] - px[i]) + (ey[i] - py[i]) * (ey[i] - py[i])) for i in range(k)]
        valid = [i for i in range(k) if dist[i] > self._capture_distance]
        choice = valid[0] if valid else dist.index(max(dist))
        for player, x, y, yaw in ((self._pursuer, px, py, u[-2]), (self._evader, ex, ey, u[-1])):
            start = [0.0] * player.state_dim
            start[0], start[1] = x[choice], y[choice]
            if player.has_heading:  # a car: random yaw in [-pi, pi), standing still, wheels straight
                start[4] = (2 * yaw - 1) * math.pi
            player.set_state(start)
        self.t = 0
        self.finished = False

    # ------------------------------------------------------------------ step
    def step(self, pursuer_action: Action, evader_action: Action) -> SingleStep:
        """Advance the game by one ``dt``; actions are two numbers in [-1, 1] (values outside are clipped).

        A finished game stays frozen (state and ``t`` unchanged, reward 0, no flags) until :meth:`reset`.
        """
        pa, pb = _action(pursuer_action, "pursuer")
        ea, eb = _action(evader_action, "evader")
        p, e = self._pursuer, self._evader
        frozen = self.finished
        if not frozen:
            dt, speed_scale = self._dt, self.speed_scale
            p.step(pa, pb, dt, speed_scale["pursuer"])
            e.step(ea, eb, dt, speed_scale["evader"])
            p.walls(self._half_x, self._half_y)
            e.walls(self._half_x, self._half_y)
            self.t += 1

        dx, dy = e.x - p.x, e.y - p.y
        distance = math.sqrt(dx * dx + dy * dy)
        if frozen:
            captured = timed_out = False
            reward = 0.0
        else:
            captured = distance <= self._capture_distance
            timed_out = not captured and self.t >= self._horizon
            if captured:
                reward = self._reward_capture
            elif timed_out:
                reward = -self._reward_capture
            else:
                reward = -(self._reward_time + self._reward_distance * distance)
        done = captured or timed_out
        obs, seen = self._observe(dx, dy, distance)
        if done:
            self.finished = True
        return SingleStep(
            obs=obs,
            rewards={"pursuer": reward, "evader": -reward},
            captured=captured,
            timed_out=timed_out,
            done=done,
            steps=self.t,
            distance=distance,
            seen=seen,
        )

    # ------------------------------------------------------------------ observe
    def observe(self) -> dict[Role, np.ndarray]:
        """Both players' current observations, ``(obs_dim,)`` float32 each."""
        p, e = self._pursuer, self._evader
        dx, dy = e.x - p.x, e.y - p.y
        return self._observe(dx, dy, math.sqrt(dx * dx + dy * dy))[0]

    def _observe(self, dx: float, dy: float, distance: float) -> tuple[dict[Role, np.ndarray], dict[Role, bool]]:
        """Observations and sensor verdicts; ``dx, dy`` is the evader minus the pursuer position, m.

        Layout as ``ObservationCodec.encode``: own state | opponent block (zeros when unseen) | seen +-1 | t/T.
        """
        p, e = self._pursuer, self._evader
        fov, sensing_range = self.fov, self._range
        seen_p = p.sees(dx, dy, distance, fov["pursuer"], sensing_range["pursuer"])
        seen_e = e.sees(-dx, -dy, distance, fov["evader"], sensing_range["evader"])
        time_fraction = self.t / self._horizon
        p_norm, e_norm = p.normalised(), e.normalised()
        if self._world_frame:
            p_block = e_norm if seen_p else self._unseen["pursuer"]
            e_block = p_norm if seen_e else self._unseen["evader"]
        else:
            p_block = self._relative(p, e, dx, dy, "pursuer") if seen_p else self._unseen["pursuer"]
            e_block = self._relative(e, p, -dx, -dy, "evader") if seen_e else self._unseen["evader"]
        obs: dict[Role, np.ndarray] = {
            "pursuer": np.array(p_norm + p_block + [1.0 if seen_p else -1.0, time_fraction], dtype=np.float32),
            "evader": np.array(e_norm + e_block + [1.0 if seen_e else -1.0, time_fraction], dtype=np.float32),
        }
        return obs, {"pursuer": seen_p, "evader": seen_e}

    def _relative(self, own: _Player, opp: _Player, dx: float, dy: float, role: Role) -> list[float]:
        """The own-frame opponent block of ``ObservationCodec._relative``, clipped to [-1, 1].

        Relative position (m) / sensing range and relative velocity (m/s) / both speed limits, rotated into a
        car observer's body frame; a car opponent adds its heading relative to the observer's, / pi.
        """
        own_vx, own_vy = own.velocity()
        opp_vx, opp_vy = opp.velocity()
        dvx, dvy = opp_vx - own_vx, opp_vy - own_vy
        if isinstance(own, _Car):
            c, s = own.cos_psi, own.sin_psi
            dx, dy, dvx, dvy = c * dx + s * dy, c * dy - s * dx, c * dvx + s * dvy, c * dvy - s * dvx
        inverse_range, inverse_velocity = self._inverse_range[role], self._inverse_velocity_scale
        block = [dx * inverse_range, dy * inverse_range, dvx * inverse_velocity, dvy * inverse_velocity]
        if isinstance(opp, _Car):
            relative = _wrap_near(opp.psi - own.psi) if isinstance(own, _Car) else opp.psi
            block.append(relative * _INV_PI)
        return [-1.0 if b < -1.0 else 1.0 if b > 1.0 else b for b in block]
