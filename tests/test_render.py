"""Drawings of recorded episodes: a panel per episode, axes in metres, outcomes in the titles, one legend naming
the marks drawn and only those, off the arena."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from pecli.match import Recording, play_match
from pecli.policies import resolve_policy
from pecli.render import MAX_PANELS, _grid, episode_animation, episodes_figure
from pecli.scenario import Scenario

plt = pytest.importorskip("matplotlib.pyplot")


@pytest.fixture(scope="module")
def recording(quick: Scenario) -> Recording:
    """20 games of pure pursuit against the rash evader: some captured, some timed out."""
    pursuer, evader = resolve_policy("pure-pursuit", "pursuer", quick), resolve_policy("rash", "evader", quick)
    _, recorded = play_match(quick, pursuer, evader, episodes=20, seed=0, record=20)
    assert recorded is not None and recorded.captured.any() and not recorded.captured.all()
    return recorded


def with_belief(recording: Recording, role: str = "pursuer") -> Recording:
    """``recording`` as if ``role`` had a belief of two components."""
    frames, games = recording.pursuer.shape[:2]
    weights = np.full((frames, games, 2), 0.5)
    means, stds = np.zeros((frames, games, 2, 2)), np.full((frames, games, 2, 2), 0.1)
    return replace(recording, beliefs={role: (weights, means, stds)})


def labels(fig) -> list[str]:
    (legend,) = fig.legends  # one legend for the whole figure
    return [text.get_text() for text in legend.get_texts()]


def outside_every_arena(fig) -> bool:
    fig.canvas.draw()
    box = fig.legends[0].get_window_extent()
    return not any(box.overlaps(ax.get_window_extent()) for ax in fig.axes if ax.axison)


def test_every_requested_episode_gets_a_panel_up_to_the_cap(recording: Recording) -> None:
    for requested, drawn in ((1, 1), (8, 8), (20, MAX_PANELS)):
        fig = episodes_figure(recording, requested)
        panels = [ax for ax in fig.axes if ax.axison]
        assert len(panels) == drawn
        for i, ax in enumerate(panels):
            seconds = recording.steps[i] * recording.scenario.dt
            outcome = "captured" if recording.captured[i] else "timed out"
            assert ax.get_title() == f"episode {i + 1}: {outcome} at t = {seconds:.1f} s"
            assert (ax.get_xlabel(), ax.get_ylabel()) == ("x (m)", "y (m)")
            assert ax.get_legend() is None  # the figure's legend only
        plt.close(fig)
    assert [_grid(n) for n in (1, 3, 4, 5, 8, 9, 16)] == [(1, 1), (1, 3), (1, 4), (2, 3), (2, 4), (3, 3), (4, 4)]


def test_the_legend_names_the_marks_drawn_and_no_others(recording: Recording) -> None:
    escaped = recording.games(np.flatnonzero(~recording.captured)[:2])
    fig = episodes_figure(escaped, 2, title="pure-pursuit vs rash")
    assert fig.get_suptitle() == "pure-pursuit vs rash"
    assert labels(fig) == [
        "pursuer's path",
        "evader's path",
        "start",
        "pursuer at the end (car, nose along its heading)",
        "evader at the end (point mass)",
        "pursuer's field of view (120°, 6 m)",  # the wedges
        "evader's sensing range (6 m)",  # the dashed circle: a point mass sees all around
    ]
    assert outside_every_arena(fig)
    plt.close(fig)

    caught = recording.games(np.flatnonzero(recording.captured)[:2])
    fig = episodes_figure(with_belief(caught), 2)
    shown = labels(fig)
    assert "capture (within 0.5 m)" in shown  # the capture distance: twice the capture radius
    assert "pursuer's belief of where the evader is (1σ, 2σ)" in shown
    assert not any(label.startswith("evader's belief") for label in shown)
    plt.close(fig)


def test_an_animation_has_one_legend_beside_the_arena_and_its_outcome(recording: Recording) -> None:
    episode = int(np.flatnonzero(recording.captured)[0])
    fig, draw, frame, frames = episode_animation(with_belief(recording, "evader"), episode, title="a game")
    assert frames[0] == 0 and frames[-1] == recording.steps[episode] and len(frames) <= 201
    for t in (frames[0], frames[len(frames) // 2], frames[-1]):
        draw(t)  # a frame clears the arena, not the legend or the title
        (ax,) = fig.axes
        assert ax.get_title() == f"t = {t * recording.scenario.dt:.1f} s"
        assert (ax.get_xlabel(), ax.get_ylabel()) == ("x (m)", "y (m)")
    seconds = recording.steps[episode] * recording.scenario.dt
    assert fig.get_suptitle() == f"a game\nepisode {episode + 1}: captured at t = {seconds:.1f} s"
    shown = labels(fig)
    assert shown[:2] == ["pursuer's trail", "evader's trail"] and "start" not in shown
    assert "darker: it sees its opponent" in shown and "capture (within 0.5 m)" in shown
    assert "evader's belief of where the pursuer is (1σ, 2σ)" in shown
    assert outside_every_arena(fig)
    first, last = frame(frames[0]), frame(frames[-1])
    assert first.shape[2] == 4 and (first != last).any()  # the marks moved over the still parts
    assert (frame(frames[0]) == first).all()  # a frame leaves nothing of the one before it
    plt.close(fig)
