"""Drawings of recorded episodes: trajectories, field-of-view wedges, beliefs and capture points (matplotlib).

A learned player with a belief has it drawn as dotted 1-sigma and 2-sigma ellipses per mixture
component (in its own colour, stronger for heavier components), next to the opponent's true position.

``draw_episodes`` writes a PNG with a panel per episode; ``animate_episode`` writes a GIF of one.
matplotlib is imported lazily with the non-interactive Agg backend.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from pecli.io import atomic_path

if TYPE_CHECKING:
    from matplotlib.axes import Axes

    from pecli.match import Recording

COLOURS = {"pursuer": "tab:blue", "evader": "tab:red"}


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _heading(state: np.ndarray) -> float | None:
    """Yaw of a car state (rad), ``None`` for a point mass."""
    return float(state[4]) if state.shape[-1] == 5 else None


def _draw_arena(ax: Axes, recording: Recording) -> None:
    from matplotlib.patches import Rectangle

    hx, hy = recording.scenario.arena.half
    ax.add_patch(Rectangle((-hx, -hy), 2 * hx, 2 * hy, fill=False, lw=1.5, color="0.3"))
    margin = 0.05 * max(hx, hy)
    ax.set_xlim(-hx - margin, hx + margin)
    ax.set_ylim(-hy - margin, hy + margin)
    ax.set_aspect("equal")
    ax.tick_params(labelsize=7)


def _sensor_patch(state: np.ndarray, role: str, recording: Recording, alpha: float):
    """The sensor footprint of a player in ``state``: a wedge for a car, a disk for a point mass."""
    from matplotlib.patches import Circle, Wedge

    sensor = recording.scenario.agent(role).sensor
    x, y = float(state[0]), float(state[1])
    heading = _heading(state)
    style = {"color": COLOURS[role], "alpha": alpha, "lw": 0}
    if heading is None or sensor.fov >= 2 * math.pi - 1e-9:  # a disk: outline only, it would cover the arena
        return Circle((x, y), sensor.range, fill=False, ls="--", lw=0.8, color=COLOURS[role], alpha=min(1.0, 6 * alpha))
    half = math.degrees(0.5 * sensor.fov)
    return Wedge((x, y), sensor.range, math.degrees(heading) - half, math.degrees(heading) + half, **style)


def _body_patch(state: np.ndarray, role: str):
    """A triangle pointing along the heading for a car, a dot for a point mass."""
    from matplotlib.patches import Circle, Polygon

    x, y = float(state[0]), float(state[1])
    heading = _heading(state)
    if heading is None:
        return Circle((x, y), 0.2, color=COLOURS[role], zorder=5)
    c, s = math.cos(heading), math.sin(heading)
    points = [
        (x + 0.45 * c, y + 0.45 * s),
        (x - 0.25 * c - 0.2 * s, y - 0.25 * s + 0.2 * c),
        (x - 0.25 * c + 0.2 * s, y - 0.25 * s - 0.2 * c),
    ]
    return Polygon(points, closed=True, color=COLOURS[role], zorder=5)


def _draw_belief(ax: Axes, recording: Recording, role: str, episode: int, t: int) -> None:
    """A player's belief at frame ``t``: each mixture component as 1-sigma and 2-sigma ellipses, shaded by weight."""
    from matplotlib.patches import Ellipse

    if role not in recording.beliefs:
        return
    weights, means, stds = (part[t, episode] for part in recording.beliefs[role])
    hx, hy = recording.scenario.arena.half
    colour = COLOURS[role]
    for w, mu, sd in zip(weights, means, stds):
        centre = (mu[0] * hx, mu[1] * hy)
        for k, alpha in ((1, 0.35), (2, 0.15)):
            ax.add_patch(
                Ellipse(
                    centre,
                    2 * k * sd[0] * hx,
                    2 * k * sd[1] * hy,
                    fill=False,
                    ls=":",
                    lw=1.0,
                    color=colour,
                    alpha=max(0.1, alpha * (0.3 + 0.7 * float(w))),
                    zorder=4,
                )
            )
        ax.plot(*centre, "+", color=colour, ms=5 + 6 * float(w), zorder=4)


def _outcome(recording: Recording, episode: int) -> str:
    steps = int(recording.steps[episode])
    if recording.captured[episode]:
        return f"captured at step {steps} ({steps * recording.scenario.dt:.1f} s)"
    return f"timeout after {steps} steps"


def draw_episodes(recording: Recording, path: str | Path, episodes: int = 4) -> Path:
    """Draw up to ``episodes`` recorded episodes side by side into a PNG; returns the path."""
    plt = _pyplot()
    count = max(1, min(episodes, recording.steps.shape[0]))
    cols = min(count, 2)
    rows = math.ceil(count / cols)
    fig, axes = plt.subplots(rows, cols, figsize=(5 * cols, 5 * rows), squeeze=False)
    for i, ax in enumerate(axes.flat):
        if i >= count:
            ax.axis("off")
            continue
        _draw_arena(ax, recording)
        end = int(recording.steps[i])
        for role, states in (("pursuer", recording.pursuer[: end + 1, i]), ("evader", recording.evader[: end + 1, i])):
            ax.plot(states[:, 0], states[:, 1], color=COLOURS[role], lw=1.2, label=role)
            ax.plot(states[0, 0], states[0, 1], "o", mfc="white", color=COLOURS[role], ms=6)
            moments = np.linspace(0, end, 4).astype(int) if role == "pursuer" else [end]
            for t in moments:
                ax.add_patch(_sensor_patch(states[t], role, recording, alpha=0.08))
            ax.add_patch(_body_patch(states[-1], role))
        for role in recording.beliefs:  # where each learned player believed its opponent was, at the end
            _draw_belief(ax, recording, role, i, end)
        if recording.captured[i]:
            ax.plot(*recording.evader[end, i, :2], "kx", ms=10, mew=2, zorder=6)
        ax.set_title(f"episode {i}: {_outcome(recording, i)}", fontsize=9)
        if i == 0:
            ax.legend(loc="upper right", fontsize=7)
    fig.suptitle(recording.scenario.name, fontsize=11)
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=110, format="png")
    plt.close(fig)
    return Path(path)


def animate_episode(recording: Recording, path: str | Path, episode: int = 0, fps: int = 10) -> Path:
    """Animate one recorded episode into a GIF, with trails and sensor footprints; returns the path."""
    plt = _pyplot()
    from matplotlib.animation import FuncAnimation, PillowWriter

    end = int(recording.steps[episode])
    stride = max(1, math.ceil((end + 1) / 200))  # at most ~200 frames
    frames = list(range(0, end + 1, stride))
    if frames[-1] != end:
        frames.append(end)
    fig, ax = plt.subplots(figsize=(5, 5))
    pursuer, evader = recording.pursuer[:, episode], recording.evader[:, episode]

    def draw(t: int) -> None:
        ax.clear()
        _draw_arena(ax, recording)
        for role, states, seen in (
            ("pursuer", pursuer, recording.seen_by_pursuer[:, episode]),
            ("evader", evader, recording.seen_by_evader[:, episode]),
        ):
            ax.plot(states[: t + 1, 0], states[: t + 1, 1], color=COLOURS[role], lw=1.0)
            ax.add_patch(_sensor_patch(states[t], role, recording, alpha=0.18 if seen[t] else 0.07))
            ax.add_patch(_body_patch(states[t], role))
        for role in recording.beliefs:
            _draw_belief(ax, recording, role, episode, t)
        if t == end and recording.captured[episode]:
            ax.plot(*evader[t, :2], "kx", ms=12, mew=2, zorder=6)
        ax.set_title(
            f"{recording.scenario.name}  t = {t * recording.scenario.dt:.1f} s   {_outcome(recording, episode)}"
            if t == end
            else f"{recording.scenario.name}  t = {t * recording.scenario.dt:.1f} s",
            fontsize=9,
        )

    animation = FuncAnimation(fig, draw, frames=frames)
    with atomic_path(path) as tmp:
        animation.save(tmp, writer=PillowWriter(fps=fps))
    plt.close(fig)
    return Path(path)
