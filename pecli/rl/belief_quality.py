"""How well a belief locates the unseen opponent: windows from played games, a belief fitted on them offline, and
its location error where the opponent is out of sight.

The paper's beliefs are judged by what they add to capture (its Table I); this measures the belief itself, as a
researcher comparing beliefs wants to:

1. :func:`collect_windows` plays batched games of one observer (pursuer or evader) against several opponents and
   keeps, every ``every`` steps, each live game's history window, the opponent's true position (normalised) and
   whether the observer saw it then;
2. :func:`fit_belief` fits a learned belief on such windows by negative log-likelihood (the paper's batch and
   learning rate, Adam, gradient clipping) and keeps the state with the best validation NLL;
3. :func:`location_error` is the distance in metres between a belief's mean and the true position;
   :func:`last_sighting` is the baseline a belief must beat: the last sighting in the window (the arena's
   centre when there is none).

``benchmarks/bench_belief.py quality`` drives it on the paper's scenario.
"""

from __future__ import annotations

import copy
import time
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import torch as th

from pecli.belief.model import BeliefModel
from pecli.belief.window import WindowDecoder
from pecli.roles import Role, opponent_of
from pecli.scenario import BeliefSettings, Scenario

BATCH = 2048  # windows per forward pass when scoring


@dataclass
class Windows:
    """History windows ``(N, samples * dim)``, the opponent's true positions ``(N, 2)`` (normalised by the arena's
    half-extents) and whether the observer did not see it at that moment ``(N,)``."""

    history: np.ndarray
    target: np.ndarray
    unseen: np.ndarray

    def __len__(self) -> int:
        return len(self.history)


def collect_windows(
    scenario: Scenario,
    observer: str,
    opponents: Sequence[str],
    games: int,
    seed: int,
    role: Role = "pursuer",
    every: int = 10,
) -> Windows:
    """Windows of ``observer`` (a policy string playing ``role``) against each of ``opponents``, ``games`` batched
    games each (seeded ``seed + k`` for the k-th opponent), at every ``every``-th step of each live game."""
    from pecli.game import Game
    from pecli.game.memory import HistoryWindow
    from pecli.policies import resolve_policy

    other = opponent_of(role)
    t = scenario.training
    histories, targets, unseen = [], [], []
    for k, name in enumerate(opponents):
        game = Game(scenario, n=games, seed=seed + k)
        obs = game.reset(seed=seed + k)
        players = {
            role: resolve_policy(observer, role, scenario, seed=seed + k),
            other: resolve_policy(name, other, scenario, seed=seed + 100 + k),
        }
        for player in players.values():
            player.reset(games)
        window = HistoryWindow(games, game.obs_dim[role], t.history_length, t.history_stride)
        window.reset(obs[role])
        seen_index = game.codecs[role].seen_index
        first = game.dynamics["pursuer"].state_dim if role == "pursuer" else 0
        position = slice(first, first + 2)  # the opponent's (x, y) in the normalised state
        for step in range(1, scenario.horizon + 1):
            obs = game.step(players["pursuer"].act(obs["pursuer"]), players["evader"].act(obs["evader"])).obs
            window.push(obs[role])
            if step % every == 0:
                live = ~game.finished
                histories.append(window.get()[live])
                targets.append(game.normalised_state()[live, position])
                unseen.append(obs[role][live, seen_index] < 0)
    return Windows(np.concatenate(histories), np.concatenate(targets), np.concatenate(unseen))


def last_sighting(decoder: WindowDecoder, history: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The last sighting of the opponent in each window (normalised; the arena's centre if none) and whether
    the window holds one."""
    window = decoder(history)
    out = np.zeros((history.shape[0], 2))
    for t in range(window.seen.shape[1]):  # later sightings overwrite earlier ones
        seen = window.seen[:, t] & window.valid[:, t]
        out[seen] = window.opp_pos[seen, t]
    return out, (window.seen & window.valid).any(axis=1)


@th.no_grad()
def belief_means(model: BeliefModel, history: np.ndarray) -> np.ndarray:
    """The mean of ``model``'s mixture for each window, ``(N, 2)`` normalised."""
    parts = [model.mixture(th.as_tensor(history[i : i + BATCH])).mean().numpy() for i in range(0, len(history), BATCH)]
    return np.concatenate(parts)


@th.no_grad()
def mean_nll(model: BeliefModel, windows: Windows) -> float:
    """The mean negative log-likelihood of the true positions under ``model``'s mixtures."""
    total = 0.0
    for i in range(0, len(windows), BATCH):
        mixture = model.mixture(th.as_tensor(windows.history[i : i + BATCH]))
        total -= mixture.log_prob(th.as_tensor(windows.target[i : i + BATCH])).sum().item()
    return total / len(windows)


@dataclass
class Fit:
    """What :func:`fit_belief` did: the update whose state it kept, that state's validation NLL, the seconds."""

    kept_update: int
    validation_nll: float
    seconds: float


def fit_belief(
    model: BeliefModel,
    data: Windows,
    validation: Windows,
    settings: BeliefSettings,
    updates: int,
    check_every: int,
    seed: int = 0,
) -> Fit:
    """Fit a learned ``model`` on ``data`` by NLL for ``updates`` batches (``settings``: batch size, learning rate,
    gradient clipping, as training fits it), checking ``validation`` every ``check_every`` updates; ``model`` ends
    with the state of the best check (the initial one included)."""
    if not model.learned:
        raise ValueError(f"a {model.kind} belief has nothing to fit")
    optimiser = th.optim.Adam(model.parameters(), lr=settings.learning_rate)
    rng = np.random.default_rng(seed)
    best = (mean_nll(model, validation), 0, copy.deepcopy(model.state_dict()))
    start = time.perf_counter()
    for update in range(1, updates + 1):
        index = rng.integers(0, len(data), settings.batch_size)
        loss = model.mixture(th.as_tensor(data.history[index])).nll(th.as_tensor(data.target[index]))
        optimiser.zero_grad()
        loss.backward()
        th.nn.utils.clip_grad_norm_(model.parameters(), settings.max_grad_norm)
        optimiser.step()
        if update % check_every == 0:
            score = mean_nll(model, validation)
            if score < best[0]:
                best = (score, update, copy.deepcopy(model.state_dict()))
    model.load_state_dict(best[2])
    return Fit(kept_update=best[1], validation_nll=best[0], seconds=time.perf_counter() - start)


def location_error(scenario: Scenario, estimate: np.ndarray, target: np.ndarray) -> np.ndarray:
    """The distance in metres between estimated and true positions, both ``(N, 2)`` normalised."""
    return np.linalg.norm((estimate - target) * np.array(scenario.arena.half), axis=1)
