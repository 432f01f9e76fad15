"""Noise-free wedge sensors (paper section III-A).

An observer at ``p`` with heading ``psi`` sees a target iff ``d(p, target) <= range`` and the
bearing ``atan2(dy, dx) - psi``, wrapped to [-pi, pi), lies within ``[-fov/2, fov/2]``.
A point mass has no heading: its field of view is a disk (``fov = 2 pi``).

The angular test is evaluated as ``cos(bearing) >= cos(fov/2)``, i.e.
``dx cos psi + dy sin psi >= d cos(fov/2)``: the same set (cos is monotonic on [0, pi]),
no ``atan2`` and no wrapping. A target exactly on the wedge's edge may fall either side
by one rounding error.
"""

from __future__ import annotations

import math

import numpy as np


def in_view(
    dx: np.ndarray,
    dy: np.ndarray,
    distance: np.ndarray,
    heading_cos_sin: tuple[np.ndarray, np.ndarray] | None,
    fov: float,
    sensing_range: float,
) -> np.ndarray:
    """Whether each target is seen; shapes ``(n,)``.

    Args:
        dx, dy: target position minus observer position, m.
        distance: ``hypot(dx, dy)``, m.
        heading_cos_sin: ``(cos psi, sin psi)`` of the observer's heading, or ``None`` if it has none.
        fov: field-of-view angle, rad, in (0, 2 pi].
        sensing_range: m.
    """
    seen = distance <= sensing_range
    if heading_cos_sin is not None and fov < 2.0 * math.pi:
        c, s = heading_cos_sin
        seen &= c * dx + s * dy >= math.cos(0.5 * fov) * distance
    return seen
