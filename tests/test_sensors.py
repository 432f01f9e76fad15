"""Wedge sensor geometry: range, field-of-view edges, angle wrap-around, disks."""

from __future__ import annotations

import math

import numpy as np
import pytest

from pecli.game.sensors import in_view

EPS = 1e-6


def seen(bearing: float, distance: float, heading: float, fov: float, sensing_range: float = 6.0) -> bool:
    """Place a target at ``bearing`` (world frame, rad) and ``distance`` from an observer at the origin."""
    dx, dy = distance * math.cos(bearing), distance * math.sin(bearing)
    rotation = (np.array([math.cos(heading)]), np.array([math.sin(heading)]))
    return bool(in_view(np.array([dx]), np.array([dy]), np.array([distance]), rotation, fov, sensing_range)[0])


@pytest.mark.parametrize("heading", [0.0, 1.0, -2.5, math.pi - 1e-3, -math.pi])
@pytest.mark.parametrize("fov", [2 * math.pi / 3, math.pi, 3 * math.pi / 2, 0.1])
def test_fov_edges(heading: float, fov: float) -> None:
    half = fov / 2
    assert seen(heading, 3.0, heading, fov)
    assert seen(heading + half - EPS, 3.0, heading, fov)
    assert seen(heading - half + EPS, 3.0, heading, fov)
    assert not seen(heading + half + EPS, 3.0, heading, fov)
    assert not seen(heading - half - EPS, 3.0, heading, fov)
    assert not seen(heading + math.pi, 3.0, heading, fov)


def test_wrap_around_the_back() -> None:
    # heading just below +pi, target just past -pi in world angle: a bearing of a few mrad
    heading = math.pi - 0.01
    assert seen(-math.pi + 0.01, 2.0, heading, fov=0.1)
    assert not seen(-math.pi + 0.2, 2.0, heading, fov=0.1)


def test_range_edge() -> None:
    assert seen(0.0, 6.0 - EPS, 0.0, 2.0)
    assert seen(0.0, 6.0, 0.0, 2.0)
    assert not seen(0.0, 6.0 + EPS, 0.0, 2.0)


def test_disk_without_heading() -> None:
    bearings = np.linspace(-math.pi, math.pi, 9)
    d = np.full(9, 3.0)
    result = in_view(d * np.cos(bearings), d * np.sin(bearings), d, None, 2 * math.pi, 6.0)
    assert result.all()
    far = in_view(np.array([7.0]), np.array([0.0]), np.array([7.0]), None, 2 * math.pi, 6.0)
    assert not far.any()


def test_matches_atan2_definition() -> None:
    rng = np.random.default_rng(0)
    n = 20000
    dx, dy = rng.uniform(-8, 8, n), rng.uniform(-8, 8, n)
    distance = np.hypot(dx, dy)
    heading = rng.uniform(-math.pi, math.pi, n)
    fov = 2 * math.pi / 3
    ours = in_view(dx, dy, distance, (np.cos(heading), np.sin(heading)), fov, 6.0)
    bearing = (np.arctan2(dy, dx) - heading + math.pi) % (2 * math.pi) - math.pi
    paper = (distance <= 6.0) & (np.abs(bearing) <= fov / 2)
    assert np.array_equal(ours, paper)
