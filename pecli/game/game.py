"""The batched pursuit-evasion game: N independent games as NumPy arrays.

    >>> game = Game(load_scenario("paper"), n=1024, seed=0)
    >>> obs = game.reset()                                   # {"pursuer": (1024, 11), "evader": (1024, 11)}
    >>> result = game.step(pursuer_actions, evader_actions)  # actions (1024, 2) in [-1, 1]

Both players move simultaneously every step. After the step the game checks capture
(``d <= 2c``) and the horizon (``t >= T``, the evader wins; a capture on the last step still
counts as a capture), computes the zero-sum reward and both observations.

Without ``auto_reset`` a finished game freezes: later steps leave its state alone and give
it zero reward, so a whole batch can be stepped until every game has ended. With
``auto_reset`` a finished game restarts at once; its last observation and state are in
``StepResult.final_obs`` / ``final_state``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from pecli.game.dynamics import make_dynamics
from pecli.game.observation import ObservationCodec
from pecli.game.seeding import counter_uniform, fresh_seed
from pecli.game.sensors import in_view
from pecli.roles import ROLES, Role
from pecli.scenario import Scenario

START_CANDIDATES = 8  # start positions drawn per game; the first pair farther apart than 2c is used


@dataclass
class StepResult:
    """What one step of ``n`` games returns. Arrays are ``(n,)`` unless noted."""

    obs: dict[Role, np.ndarray]  # (n, obs_dim) per role; for restarted games, the new episode's first one
    rewards: dict[Role, np.ndarray]  # unscaled, zero-sum: rewards["evader"] == -rewards["pursuer"]
    captured: np.ndarray  # this step ended the episode with a capture
    timed_out: np.ndarray  # this step reached the horizon without a capture
    done: np.ndarray  # captured | timed_out
    steps: np.ndarray  # steps played in the episode, counted at its end for games that finished
    distance: np.ndarray  # distance between the players after the step, m
    seen: dict[Role, np.ndarray]  # whether each role sees its opponent after the step
    final_obs: dict[Role, np.ndarray] | None = None  # with auto_reset: observations before the restart
    final_state: np.ndarray | None = None  # with auto_reset: (n, state_dim) SI state before the restart


class Game:
    """``n`` independent games of one scenario, stepped together.

    Args:
        scenario: the game to play.
        n: number of games in the batch.
        seed: seed of the start states; ``None`` draws one from the OS.
        auto_reset: restart finished games inside :meth:`step`.
    """

    def __init__(self, scenario: Scenario, n: int = 1, seed: int | None = None, auto_reset: bool = False) -> None:
        if n < 1:
            raise ValueError(f"a batch needs at least one game, got n={n}")
        self.scenario = scenario
        self.n = n
        self.auto_reset = auto_reset
        self.seed = fresh_seed() if seed is None else int(seed)
        self.dynamics = {role: make_dynamics(scenario.agent(role)) for role in ROLES}
        self.codecs = {role: ObservationCodec(scenario, role) for role in ROLES}
        self.obs_dim: dict[Role, int] = {role: self.codecs[role].dim for role in ROLES}
        self.state_dim = sum(d.state_dim for d in self.dynamics.values())
        # knobs a curriculum may turn while training (paper §V-A)
        self.fov: dict[Role, float] = {role: scenario.agent(role).sensor.fov for role in ROLES}
        self.speed_scale: dict[Role, float] = {role: 1.0 for role in ROLES}
        self._half = scenario.arena.half
        # normalisation of the privileged state, per row (pursuer's rows then evader's)
        self._state_inverse_scale = {role: (1.0 / self.dynamics[role].scale(*self._half))[:, None] for role in ROLES}
        # row-wise internal states (rows, n): the SI state, then any cached rows (a car's cos/sin psi)
        self.pursuer = np.zeros((self.dynamics["pursuer"].rows, n))
        self.evader = np.zeros((self.dynamics["evader"].rows, n))
        self.t = np.zeros(n, dtype=np.int64)
        self.episode = np.zeros(n, dtype=np.int64)
        self.finished = np.zeros(n, dtype=bool)
        self.reset(seed=self.seed)

    # ------------------------------------------------------------------ state
    def state(self) -> np.ndarray:
        """The privileged full state in SI units: ``(n, k_p + k_e)``, pursuer then evader."""
        kp, ke = self.dynamics["pursuer"].state_dim, self.dynamics["evader"].state_dim
        return np.concatenate([self.pursuer[:kp], self.evader[:ke]]).T.copy()

    def normalised_state(self) -> np.ndarray:
        """The full state scaled to [-1, 1], plus ``t/T``: ``(n, state_dim + 1)`` float32, for critics."""
        kp, ke = self.dynamics["pursuer"].state_dim, self.dynamics["evader"].state_dim
        out = np.empty((kp + ke + 1, self.n), dtype=np.float32)
        np.multiply(self.pursuer[:kp], self._state_inverse_scale["pursuer"], out=out[:kp])
        np.multiply(self.evader[:ke], self._state_inverse_scale["evader"], out=out[kp : kp + ke])
        out[-1] = self.t / self.scenario.horizon
        return out.T

    def set_state(self, state: np.ndarray, t: np.ndarray | int = 0) -> dict[Role, np.ndarray]:
        """Put every game in the SI ``state`` ``(n, state_dim)`` at step ``t``; returns the observations."""
        state = np.asarray(state, dtype=np.float64)
        if state.shape != (self.n, self.state_dim):
            raise ValueError(f"state must have shape {(self.n, self.state_dim)}, got {state.shape}")
        k = self.dynamics["pursuer"].state_dim
        self.pursuer = self.dynamics["pursuer"].from_state(state[:, :k].T)
        self.evader = self.dynamics["evader"].from_state(state[:, k:].T)
        self.t = np.broadcast_to(np.asarray(t, dtype=np.int64), (self.n,)).copy()
        self.finished[:] = False
        return self.observe()

    # ------------------------------------------------------------------ reset
    def reset(self, seed: int | None = None, mask: np.ndarray | None = None) -> dict[Role, np.ndarray]:
        """Start new episodes, in every game or where ``mask`` is true; returns all observations.

        A new ``seed`` without a mask restarts the episode counters, so the same seed gives the same
        start states; with a mask the restarted games continue their counters under the new seed.
        """
        if seed is not None:
            self.seed = int(seed)
            if mask is None:
                self.episode[:] = 0
        idx = np.arange(self.n) if mask is None else np.flatnonzero(mask)
        if idx.size:
            self._start(idx)
        return self.observe()

    def _start(self, idx: np.ndarray) -> None:
        """Sample start states for the games ``idx``: uniform positions at least 2c apart, still, random yaw."""
        hx, hy = self._half
        k = START_CANDIDATES
        u = counter_uniform(self.seed, idx, self.episode[idx], 4 * k + 2)
        self.episode[idx] += 1
        px, py = (2 * u[0:k] - 1) * hx, (2 * u[k : 2 * k] - 1) * hy
        ex, ey = (2 * u[2 * k : 3 * k] - 1) * hx, (2 * u[3 * k : 4 * k] - 1) * hy
        dist = np.sqrt((ex - px) ** 2 + (ey - py) ** 2)
        valid = dist > self.scenario.capture_distance
        choice = np.where(valid.any(axis=0), valid.argmax(axis=0), dist.argmax(axis=0))
        cols = np.arange(idx.size)
        placements: tuple[tuple[Role, tuple[np.ndarray, np.ndarray], np.ndarray], ...] = (
            ("pursuer", (px, py), u[-2]),
            ("evader", (ex, ey), u[-1]),
        )
        for role, (x, y), yaw in placements:
            rows, dynamics = getattr(self, role), self.dynamics[role]
            start = np.zeros((dynamics.state_dim, idx.size))
            start[0], start[1] = x[choice, cols], y[choice, cols]
            if dynamics.has_heading:  # a car: random yaw in [-pi, pi), standing still, wheels straight
                start[4] = (2 * yaw - 1) * math.pi
            rows[:, idx] = dynamics.from_state(start)
        self.t[idx] = 0
        self.finished[idx] = False

    # ------------------------------------------------------------------ step
    def step(self, pursuer_action: np.ndarray, evader_action: np.ndarray) -> StepResult:
        """Advance every game by one ``dt``; actions ``(n, 2)`` in [-1, 1] (values outside are clipped)."""
        pursuer_action = self._check_action(pursuer_action, "pursuer")
        evader_action = self._check_action(evader_action, "evader")
        sc = self.scenario
        dt = sc.dt
        hx, hy = self._half
        new_p = self.dynamics["pursuer"].step(self.pursuer, pursuer_action, dt, self.speed_scale["pursuer"])
        new_e = self.dynamics["evader"].step(self.evader, evader_action, dt, self.speed_scale["evader"])
        self.dynamics["pursuer"].stop_at_walls(new_p, hx, hy)
        self.dynamics["evader"].stop_at_walls(new_e, hx, hy)
        frozen = self.finished if not self.auto_reset and self.finished.any() else None
        if frozen is not None:
            new_p[:, frozen] = self.pursuer[:, frozen]
            new_e[:, frozen] = self.evader[:, frozen]
            self.t += ~frozen
        else:
            self.t += 1
        self.pursuer, self.evader = new_p, new_e

        dx, dy = new_e[0] - new_p[0], new_e[1] - new_p[1]
        distance = np.sqrt(dx * dx + dy * dy)
        captured = distance <= sc.capture_distance
        timed_out = (self.t >= sc.horizon) & ~captured
        reward = -(sc.reward.time + sc.reward.distance * distance)
        reward[captured] = sc.reward.capture
        reward[timed_out] = -sc.reward.capture
        if frozen is not None:
            captured &= ~frozen
            timed_out &= ~frozen
            reward[frozen] = 0.0
        done = captured | timed_out
        steps = self.t.copy()
        obs, seen = self._observe(self.pursuer, self.evader, self.t, dx, dy, distance)

        final_obs = final_state = None
        if self.auto_reset:
            if done.any():
                final_obs, final_state = obs, self.state()
                restarted = np.flatnonzero(done)
                self._start(restarted)
                fresh = self._observe(self.pursuer[:, restarted], self.evader[:, restarted], self.t[restarted])[0]
                obs = {role: obs[role].copy() for role in ROLES}
                for role in ROLES:
                    obs[role][restarted] = fresh[role]
        else:
            self.finished |= done
        return StepResult(
            obs=obs,
            rewards={"pursuer": reward, "evader": -reward},
            captured=captured,
            timed_out=timed_out,
            done=done,
            steps=steps,
            distance=distance,
            seen=seen,
            final_obs=final_obs,
            final_state=final_state,
        )

    def _check_action(self, action: np.ndarray, role: Role) -> np.ndarray:
        action = np.asarray(action, dtype=np.float64)
        if action.shape != (self.n, 2):
            raise ValueError(f"{role} actions must have shape ({self.n}, 2), got {action.shape}")
        return action

    # ------------------------------------------------------------------ observe
    def observe(self) -> dict[Role, np.ndarray]:
        """Both players' current observations, ``(n, obs_dim)`` float32 each."""
        return self._observe(self.pursuer, self.evader, self.t)[0]

    def seen(self) -> dict[Role, np.ndarray]:
        """Whether each player currently sees its opponent, ``(n,)`` bool each."""
        return self._observe(self.pursuer, self.evader, self.t)[1]

    def _observe(
        self,
        pursuer: np.ndarray,
        evader: np.ndarray,
        t: np.ndarray,
        dx: np.ndarray | None = None,
        dy: np.ndarray | None = None,
        distance: np.ndarray | None = None,
    ) -> tuple[dict[Role, np.ndarray], dict[Role, np.ndarray]]:
        """Observations and sensor verdicts for the given internal rows (all games or a subset)."""
        if dx is None or dy is None or distance is None:
            dx, dy = evader[0] - pursuer[0], evader[1] - pursuer[1]
            distance = np.sqrt(dx * dx + dy * dy)
        time_fraction = t / self.scenario.horizon
        p_dyn, e_dyn = self.dynamics["pursuer"], self.dynamics["evader"]
        p_sensor, e_sensor = self.scenario.pursuer.sensor, self.scenario.evader.sensor
        seen_p = in_view(dx, dy, distance, p_dyn.heading_cos_sin(pursuer), self.fov["pursuer"], p_sensor.range)
        seen_e = in_view(-dx, -dy, distance, e_dyn.heading_cos_sin(evader), self.fov["evader"], e_sensor.range)
        obs: dict[Role, np.ndarray] = {
            "pursuer": self.codecs["pursuer"].encode(pursuer, evader, dx, dy, seen_p, time_fraction),
            "evader": self.codecs["evader"].encode(evader, pursuer, -dx, -dy, seen_e, time_fraction),
        }
        return obs, {"pursuer": seen_p, "evader": seen_e}
