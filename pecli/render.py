"""Drawings of recorded episodes: trajectories, field-of-view wedges, beliefs and capture points (matplotlib).

A learned player with a belief has it drawn as dotted 1-sigma and 2-sigma ellipses per mixture
component (in its own colour, stronger for heavier components), next to the opponent's true position.

``draw_episodes`` writes a PNG with a panel per episode (at most :data:`MAX_PANELS`); ``animate_episode``
writes a GIF of one. Each drawing has axes in metres, a title per episode with its outcome and one legend,
outside the arena, naming every kind of mark it holds. matplotlib is imported lazily with the Agg backend.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from pecli.io import atomic_path

if TYPE_CHECKING:
    from matplotlib.artist import Artist
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

    from pecli.match import Recording

COLOURS = {"pursuer": "tab:blue", "evader": "tab:red"}
ROLES = ("pursuer", "evader")
OPPONENT = {"pursuer": "evader", "evader": "pursuer"}
MAX_PANELS = 16  # episodes one PNG draws, as a grid of up to 4 x 4 panels
PANEL_INCHES = 4.2  # a panel's side in a grid (a single episode: 5 in)


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _heading(state: np.ndarray) -> float | None:
    """Yaw of a car state (rad), ``None`` for a point mass."""
    return float(state[4]) if state.shape[-1] == 5 else None


def _is_car(recording: Recording, role: str) -> bool:
    """Whether ``role`` is recorded with a heading (a car), not as a point mass."""
    states = recording.pursuer if role == "pursuer" else recording.evader
    return states.shape[-1] == 5


def _sensor_is_wedge(recording: Recording, role: str) -> bool:
    """Whether ``role``'s sensor is drawn as a wedge (a car that sees less than all around) or as a dashed circle."""
    return _is_car(recording, role) and recording.scenario.agent(role).sensor.fov < 2 * math.pi - 1e-9


def _draw_arena(ax: Axes, recording: Recording) -> None:
    from matplotlib.patches import Rectangle

    hx, hy = recording.scenario.arena.half
    ax.add_patch(Rectangle((-hx, -hy), 2 * hx, 2 * hy, fill=False, lw=1.5, color="0.3"))
    margin = 0.05 * max(hx, hy)
    ax.set_xlim(-hx - margin, hx + margin)
    ax.set_ylim(-hy - margin, hy + margin)
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)", fontsize=8)
    ax.set_ylabel("y (m)", fontsize=8)
    ax.tick_params(labelsize=7)


def _sensor_patch(state: np.ndarray, role: str, recording: Recording, alpha: float):
    """The sensor footprint of a player in ``state``: a wedge for a car, a dashed circle (its range) otherwise."""
    from matplotlib.patches import Circle, Wedge

    sensor = recording.scenario.agent(role).sensor
    x, y = float(state[0]), float(state[1])
    heading = _heading(state)
    if heading is None or sensor.fov >= 2 * math.pi - 1e-9:  # a disk: outline only, it would cover the arena
        return Circle((x, y), sensor.range, fill=False, ls="--", lw=0.8, color=COLOURS[role], alpha=min(1.0, 6 * alpha))
    half = math.degrees(0.5 * sensor.fov)
    start, stop = math.degrees(heading) - half, math.degrees(heading) + half
    return Wedge((x, y), sensor.range, start, stop, color=COLOURS[role], alpha=alpha, lw=0)


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
    """How ``episode`` ended, with the time in s: ``captured at t = 4.2 s`` or ``timed out at t = 15.0 s``."""
    seconds = int(recording.steps[episode]) * recording.scenario.dt
    return f"{'captured' if recording.captured[episode] else 'timed out'} at t = {seconds:.1f} s"


def _legend_handles(recording: Recording, episodes: Sequence[int], animated: bool) -> list[Artist]:
    """One legend entry per kind of mark a drawing of ``episodes`` holds (a GIF when ``animated``), none for the
    kinds it lacks (no capture mark where every episode timed out, a belief only for a player that has one)."""
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    scenario = recording.scenario
    handles: list[Artist] = [
        Line2D([], [], color=COLOURS[role], lw=1.2, label=f"{role}'s {'trail' if animated else 'path'}")
        for role in ROLES
    ]
    if not animated:
        handles.append(Line2D([], [], ls="", marker="o", mfc="white", mec="0.3", ms=6, label="start"))
    for role in ROLES:
        car = _is_car(recording, role)
        shape = "car, nose along its heading" if car else "point mass"
        handles.append(
            Line2D(
                [],
                [],
                ls="",
                marker="^" if car else "o",
                color=COLOURS[role],
                ms=7,
                label=f"{role} {'now' if animated else 'at the end'} ({shape})",
            )
        )
    for role in ROLES:
        sensor = scenario.agent(role).sensor
        if _sensor_is_wedge(recording, role):
            fov = f"{math.degrees(sensor.fov):.0f}°, {sensor.range:g} m"
            handles.append(Patch(color=COLOURS[role], alpha=0.3, lw=0, label=f"{role}'s field of view ({fov})"))
        else:
            handles.append(
                Line2D(
                    [], [], ls="--", lw=0.8, color=COLOURS[role], label=f"{role}'s sensing range ({sensor.range:g} m)"
                )
            )
    if animated:
        handles.append(Patch(color="0.45", alpha=0.5, lw=0, label="darker: it sees its opponent"))
    if any(bool(recording.captured[i]) for i in episodes):
        handles.append(
            Line2D(
                [],
                [],
                ls="",
                marker="x",
                color="k",
                ms=8,
                mew=2,
                label=f"capture (within {scenario.capture_distance:g} m)",
            )
        )
    for role in ROLES:
        if role in recording.beliefs:
            colour, opponent = COLOURS[role], OPPONENT[role]
            handles.append(
                Line2D(
                    [], [], ls=":", lw=1.0, color=colour, label=f"{role}'s belief of where the {opponent} is (1σ, 2σ)"
                )
            )
            handles.append(
                Line2D([], [], ls="", marker="+", color=colour, ms=7, label="its components' means (larger: likelier)")
            )
    return handles


def _grid(count: int) -> tuple[int, int]:
    """Rows and columns of a grid of ``count`` panels: at most 4 a row, rows as even as they go (8: 2 x 4)."""
    rows = math.ceil(count / 4)
    return rows, math.ceil(count / rows)


def episodes_figure(recording: Recording, episodes: int = MAX_PANELS, title: str | None = None) -> Figure:
    """A figure of the first ``episodes`` recorded episodes (at most :data:`MAX_PANELS`), a panel each, with one
    legend below the panels; ``title`` (default: the scenario's name) heads it."""
    plt = _pyplot()
    count = max(1, min(episodes, recording.steps.shape[0], MAX_PANELS))
    rows, cols = _grid(count)
    side = 5.0 if count == 1 else PANEL_INCHES
    fig, axes = plt.subplots(rows, cols, figsize=(side * cols, side * rows), squeeze=False, layout="constrained")
    for i, ax in enumerate(axes.flat):
        if i >= count:
            ax.axis("off")
            continue
        _draw_arena(ax, recording)
        end = int(recording.steps[i])
        for role, states in (("pursuer", recording.pursuer[: end + 1, i]), ("evader", recording.evader[: end + 1, i])):
            ax.plot(states[:, 0], states[:, 1], color=COLOURS[role], lw=1.2)
            ax.plot(states[0, 0], states[0, 1], "o", mfc="white", color=COLOURS[role], ms=6)
            moments = np.linspace(0, end, 4).astype(int) if role == "pursuer" else [end]
            for t in moments:
                ax.add_patch(_sensor_patch(states[t], role, recording, alpha=0.08))
            ax.add_patch(_body_patch(states[-1], role))
        for role in recording.beliefs:  # where each learned player believed its opponent was, at the end
            _draw_belief(ax, recording, role, i, end)
        if recording.captured[i]:
            ax.plot(*recording.evader[end, i, :2], "kx", ms=10, mew=2, zorder=6)
        ax.set_title(f"episode {i + 1}: {_outcome(recording, i)}", fontsize=9)
    fig.suptitle(title or recording.scenario.name, fontsize=11 if cols < 3 else 13)
    handles = _legend_handles(recording, range(count), animated=False)
    fig.legend(
        handles=handles,
        loc="outside lower center",  # below the panels, off the arenas
        ncol=min(len(handles), max(2, cols)),
        fontsize=8 if cols < 3 else 10,
        frameon=False,
    )
    return fig


def draw_episodes(recording: Recording, path: str | Path, episodes: int = MAX_PANELS, title: str | None = None) -> Path:
    """Draw the first ``episodes`` recorded episodes (at most :data:`MAX_PANELS`) into a PNG; returns the path."""
    plt = _pyplot()
    fig = episodes_figure(recording, episodes, title)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=110, format="png", bbox_inches="tight")
    plt.close(fig)
    return Path(path)


def episode_animation(
    recording: Recording, episode: int = 0, title: str | None = None
) -> tuple[Figure, Callable[[int], None], Callable[[int], np.ndarray], list[int]]:
    """The figure of an animation of ``episode``, the function drawing frame ``t`` (a step) into it, the function
    rendering frame ``t`` to pixels and the steps to draw (at most about 200); the arena, the legend right of it
    and the title stay as they are frame to frame."""
    plt = _pyplot()
    end = int(recording.steps[episode])
    stride = max(1, math.ceil((end + 1) / 200))  # at most ~200 frames
    frames = list(range(0, end + 1, stride))
    if frames[-1] != end:
        frames.append(end)
    fig, ax = plt.subplots(figsize=(8.4, 5))
    fig.subplots_adjust(left=0.08, right=0.58, bottom=0.1, top=0.86)
    handles = _legend_handles(recording, [episode], animated=True)
    fig.legend(handles=handles, loc="center left", bbox_to_anchor=(0.59, 0.5), fontsize=7.5, frameon=False)
    fig.suptitle(
        f"{title or recording.scenario.name}\nepisode {episode + 1}: {_outcome(recording, episode)}", fontsize=10
    )
    pursuer, evader = recording.pursuer[:, episode], recording.evader[:, episode]
    _draw_arena(ax, recording)  # drawn once: a frame changes only the marks below, which are animated
    trails = {role: ax.plot([], [], color=COLOURS[role], lw=1.0, animated=True)[0] for role in ROLES}
    ax.title.set_animated(True)
    marks: list[Artist] = []  # this frame's sensors, bodies, beliefs and capture mark

    def draw(t: int) -> None:
        for mark in marks:
            mark.remove()
        before = set(ax.get_children())
        for role, states, seen in (
            ("pursuer", pursuer, recording.seen_by_pursuer[:, episode]),
            ("evader", evader, recording.seen_by_evader[:, episode]),
        ):
            trails[role].set_data(states[: t + 1, 0], states[: t + 1, 1])
            ax.add_patch(_sensor_patch(states[t], role, recording, alpha=0.18 if seen[t] else 0.07))
            ax.add_patch(_body_patch(states[t], role))
        for role in recording.beliefs:
            _draw_belief(ax, recording, role, episode, t)
        if t == end and recording.captured[episode]:
            ax.plot(*evader[t, :2], "kx", ms=12, mew=2, zorder=6)
        marks[:] = [artist for artist in ax.get_children() if artist not in before]
        for mark in marks:
            mark.set_animated(True)
        ax.set_title(f"t = {t * recording.scenario.dt:.1f} s", fontsize=9)

    def frame(t: int) -> np.ndarray:
        """Frame ``t`` as RGBA pixels ``(height, width, 4)``: the still parts rendered once, the marks over them."""
        draw(t)
        if not background:
            fig.canvas.draw()  # everything not animated: arena, axes, legend, title
            background.append(fig.canvas.copy_from_bbox(fig.bbox))  # type: ignore[attr-defined]
        fig.canvas.restore_region(background[0])  # type: ignore[attr-defined]
        for artist in sorted([*trails.values(), *marks], key=lambda artist: artist.get_zorder()):
            ax.draw_artist(artist)
        ax.draw_artist(ax.title)
        return np.asarray(fig.canvas.buffer_rgba()).copy()  # type: ignore[attr-defined]

    background: list = []
    return fig, draw, frame, frames


def animate_episode(
    recording: Recording, path: str | Path, episode: int = 0, fps: int = 10, title: str | None = None
) -> Path:
    """Animate one recorded episode into a GIF, with trails and sensor footprints; returns the path."""
    from PIL import Image

    plt = _pyplot()
    fig, _, frame, frames = episode_animation(recording, episode, title)
    images = [Image.fromarray(frame(t)).convert("RGB") for t in frames]
    plt.close(fig)
    palette = images[-1].quantize(colors=256)  # the last frame has every mark's colour: one palette for all
    with atomic_path(path) as tmp:
        images[0].quantize(palette=palette).save(
            tmp,
            format="GIF",
            save_all=True,
            append_images=[image.quantize(palette=palette) for image in images[1:]],
            duration=round(1000 / fps),
            loop=0,
        )
    return Path(path)
