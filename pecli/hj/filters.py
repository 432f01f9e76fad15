"""The largest or smallest value a player can reach by changing one velocity axis in one step.

A player with acceleration bound ``a`` moves a velocity by any ``δ ∈ [-a dt, a dt]`` per step. On a
grid of spacing ``h`` that is a window of ``reach = a dt / h`` cells, usually not a whole number.
The linear interpolant is piecewise linear between nodes, so its maximum over the window is the
maximum over the whole nodes inside it and the two interpolated end points: a sliding-window
filter (SciPy's ``maximum_filter1d``) plus two shifted linear interpolations. Past the grid's
edge the value of the edge node is used ("nearest"), which is exactly the game's clipping of a
velocity to its limit when the axis ends at that limit.
"""

from __future__ import annotations

import math
from typing import Literal

import numpy as np
from scipy.ndimage import maximum_filter1d, minimum_filter1d

Extreme = Literal["max", "min"]
_EPS = 1e-6  # windows this close to a whole number of cells are whole
_DIRECT_UP_TO = 4  # whole-cell reach up to which shifted comparisons replace SciPy's filter


def window_extreme(values: np.ndarray, axis: int, reach: float, kind: Extreme) -> np.ndarray:
    """``out[i] = kind over δ ∈ [-reach, reach] of values(i + δ)`` along ``axis``, linear between nodes.

    ``reach`` is in cells (``a dt / h``). The result has the shape and dtype of ``values``.
    """
    whole = int(math.floor(reach + _EPS))
    frac = reach - whole
    combine = np.maximum if kind == "max" else np.minimum
    sliding = maximum_filter1d if kind == "max" else minimum_filter1d
    if whole > _DIRECT_UP_TO:
        out = sliding(values, 2 * whole + 1, axis=axis, mode="nearest")
    else:  # a few shifted comparisons beat the general filter on small windows
        out = values.copy()
        n = values.shape[axis]
        for shift in range(1, min(whole, n - 1) + 1):
            head, tail = _along(axis, 0, n - shift), _along(axis, shift, n)
            combine(out[head], values[tail], out=out[head])  # clamped indices repeat the edge: nothing to add
            combine(out[tail], values[head], out=out[tail])
    if frac > _EPS:  # the interpolated end points of the window, at i + reach and i - reach
        for sign in (1, -1):
            near = _shifted(values, sign * whole, axis)
            far = _shifted(values, sign * (whole + 1), axis)
            combine(out, near + frac * (far - near), out=out)
    return out


def _shifted(values: np.ndarray, offset: int, axis: int) -> np.ndarray:
    """``values(i + offset)`` along ``axis`` with indices clamped to the axis ("nearest")."""
    n = values.shape[axis]
    index = np.clip(np.arange(n) + offset, 0, n - 1)
    return np.take(values, index, axis=axis)


def _along(axis: int, start: int, stop: int) -> tuple[slice, ...]:
    """The index ``[..., start:stop, ...]`` on ``axis``."""
    return (slice(None),) * axis + (slice(start, stop),)
