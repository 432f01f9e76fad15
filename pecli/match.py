"""Play a pursuer against an evader: all episodes as one batch, and the paper's metrics.

    >>> result, _ = play_match(scenario, pursuer, evader, episodes=500, seed=0)
    >>> result.capture_rate, result.time_to_capture_mean, result.time_to_capture_std

Episode ``i`` under seed ``s`` always starts from the same state, whoever plays it
(see :mod:`pecli.game.seeding`), so matches with the same seed are paired comparisons.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numpy as np

from pecli.errors import PolicyError
from pecli.game import Game
from pecli.policies.base import Policy
from pecli.scenario import Scenario

MAX_EPISODES = 1_000_000  # episodes played at once: one batched game, about 1.5 KiB each


@dataclass(frozen=True)
class MatchResult:
    """Outcomes of ``episodes`` games; arrays are ``(episodes,)``."""

    captured: np.ndarray  # bool: the pursuer won
    steps: np.ndarray  # steps played until capture or timeout
    horizon: int  # T of the scenario

    @property
    def episodes(self) -> int:
        return int(self.captured.shape[0])

    @property
    def time_to_capture(self) -> np.ndarray:
        """Normalised time-to-capture per episode: ``steps / T``, a timeout counts 1.0."""
        return np.where(self.captured, self.steps / self.horizon, 1.0)

    @property
    def capture_rate(self) -> float:
        return float(self.captured.mean())

    @property
    def time_to_capture_mean(self) -> float:
        return float(self.time_to_capture.mean())

    @property
    def time_to_capture_std(self) -> float:
        """Population standard deviation (ddof = 0) of the normalised time-to-capture."""
        return float(self.time_to_capture.std())

    def summary(self) -> dict[str, float | int]:
        """The metrics as a JSON-ready dict."""
        return {
            "capture_rate": self.capture_rate,
            "time_to_capture_mean": self.time_to_capture_mean,
            "time_to_capture_std": self.time_to_capture_std,
            "episodes": self.episodes,
        }


@dataclass(frozen=True)
class Recording:
    """Trajectories of the first ``r`` episodes, for drawing; ``T1`` = steps played + 1 (the start)."""

    scenario: Scenario
    pursuer: np.ndarray  # (T1, r, k_p) SI states
    evader: np.ndarray  # (T1, r, k_e) SI states
    seen_by_pursuer: np.ndarray  # (T1, r) bool
    seen_by_evader: np.ndarray  # (T1, r) bool
    steps: np.ndarray  # (r,) steps each episode lasted
    captured: np.ndarray  # (r,) bool
    # per role with a belief: weights (T1, r, K), means (T1, r, K, 2), stds (T1, r, K, 2), normalised world frame
    beliefs: dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]] = field(default_factory=dict)

    def games(self, index: np.ndarray | list[int]) -> Recording:
        """The recording of the games ``index`` only (e.g. those the evader escaped, to draw them)."""
        index = np.asarray(index, dtype=int)
        return replace(
            self,
            pursuer=self.pursuer[:, index],
            evader=self.evader[:, index],
            seen_by_pursuer=self.seen_by_pursuer[:, index],
            seen_by_evader=self.seen_by_evader[:, index],
            steps=self.steps[index],
            captured=self.captured[index],
            beliefs={
                role: (weights[:, index], means[:, index], stds[:, index])
                for role, (weights, means, stds) in self.beliefs.items()
            },
        )


@dataclass(frozen=True)
class Behaviour:
    """How the evader of a recording played, averaged over the steps its games lasted: to tell a lost search (the
    pursuer rarely sees it) from a lost chase (seen, yet it gets away). Speeds in m per step, distances in m."""

    caught: float  # share of games the pursuer won
    seen: float  # share of steps the pursuer saw the evader
    sees: float  # share of steps the evader saw the pursuer
    speed_unseen: float  # how fast the evader moved while it did not see the pursuer
    speed_seeing: float  # and while it saw it
    distance: float  # between the two
    wall: float  # from the evader to the nearest wall

    @classmethod
    def of(cls, recording: Recording) -> Behaviour:
        evader, pursuer = recording.evader[..., :2], recording.pursuer[..., :2]
        alive = np.arange(len(evader))[:, None] < recording.steps[None, :]  # (T1, r): the steps each game ran
        moved = alive[:-1]  # the move from frame t to t + 1 happened if the game ran step t
        speed = np.linalg.norm(np.diff(evader, axis=0), axis=2)
        sees = recording.seen_by_evader[:-1]  # what the evader saw when it chose that move
        wall = np.min(np.asarray(recording.scenario.arena.half) - np.abs(evader), axis=2)

        def mean(values: np.ndarray) -> float:
            return float(values.mean()) if values.size else float("nan")

        return cls(
            caught=mean(recording.captured),
            seen=mean(recording.seen_by_pursuer[alive]),
            sees=mean(recording.seen_by_evader[alive]),
            speed_unseen=mean(speed[moved & ~sees]),
            speed_seeing=mean(speed[moved & sees]),
            distance=mean(np.linalg.norm(evader - pursuer, axis=2)[alive]),
            wall=mean(wall[alive]),
        )


def policy_seeds(seed: int) -> tuple[int, int]:
    """Independent seeds for the pursuer's and the evader's own randomness, derived from a match seed."""
    a, b = np.random.SeedSequence(seed).generate_state(2, dtype=np.uint64)
    return int(a), int(b)


def play_match(
    scenario: Scenario,
    pursuer: Policy,
    evader: Policy,
    episodes: int,
    seed: int = 0,
    record: int = 0,
    on_step: Callable[[int, int], None] | None = None,
) -> tuple[MatchResult, Recording | None]:
    """Play ``episodes`` games at once until each ends; record the first ``record`` of them.

    ``on_step(step, games_still_running)`` is called after every step (for progress displays).
    """
    if pursuer.role != "pursuer" or evader.role != "evader":
        raise ValueError(f"need a pursuer and an evader, got {pursuer.role} and {evader.role}")
    if episodes < 1:
        raise ValueError("episodes must be at least 1")
    game = Game(scenario, n=episodes, seed=seed)
    obs = game.reset(seed=seed)
    pursuer_seed, evader_seed = policy_seeds(seed)
    pursuer.reset(episodes, seed=pursuer_seed)
    evader.reset(episodes, seed=evader_seed)
    captured = np.zeros(episodes, dtype=bool)
    record = min(record, episodes)
    frames: list[tuple[np.ndarray, dict]] = []
    beliefs: dict[str, list] = {}
    if record:
        frames.append((game.state()[:record], {k: v[:record] for k, v in game.seen().items()}))
    for step in range(1, scenario.horizon + 1):
        pursuer_action, evader_action = pursuer.act(obs["pursuer"]), evader.act(obs["evader"])
        for role, action in (("pursuer", pursuer_action), ("evader", evader_action)):
            if not np.isfinite(action).all():  # a damaged network would drive the game to NaN states silently
                raise PolicyError(f"the {role} played a NaN or infinite action at step {step}: it cannot be played")
        if record:  # each player's belief given its window at the current frame
            _record_beliefs(beliefs, pursuer, evader, record)
        result = game.step(pursuer_action, evader_action)
        captured |= result.captured
        if record:
            frames.append((game.state()[:record], {k: v[:record] for k, v in result.seen.items()}))
        running = int((~game.finished).sum())
        for player in (pursuer, evader):  # a learned player need not decide for finished games
            end = getattr(player, "end", None)
            if end is not None and running < episodes:
                end(game.finished)
        if on_step is not None:
            on_step(step, running)
        if running == 0:
            break
        obs = result.obs
    match = MatchResult(captured=captured, steps=game.t.copy(), horizon=scenario.horizon)
    if not record:
        return match, None
    states = np.stack([f[0] for f in frames])
    kp = game.dynamics["pursuer"].state_dim
    recording = Recording(
        scenario=scenario,
        pursuer=states[:, :, :kp],
        evader=states[:, :, kp:],
        seen_by_pursuer=np.stack([f[1]["pursuer"] for f in frames]),
        seen_by_evader=np.stack([f[1]["evader"] for f in frames]),
        steps=match.steps[:record].copy(),
        captured=captured[:record].copy(),
        beliefs={role: _stack_beliefs(items, len(frames)) for role, items in beliefs.items()},
    )
    return match, recording


def _record_beliefs(beliefs: dict[str, list], pursuer: Policy, evader: Policy, record: int) -> None:
    """Append the current beliefs of the players that have one (their ``current_belief()``)."""
    for role, policy in (("pursuer", pursuer), ("evader", evader)):
        current = getattr(policy, "current_belief", None)
        belief = current(record) if current is not None else None
        if belief is not None:
            beliefs.setdefault(role, []).append(belief)


def _stack_beliefs(items: list, frames: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(weights, means, stds)`` per frame; the last frame (after the last step) repeats the last belief."""
    items = items[:frames] + [items[-1]] * (frames - len(items))
    return tuple(np.stack([item[i] for item in items]) for i in range(3))  # type: ignore[return-value]
