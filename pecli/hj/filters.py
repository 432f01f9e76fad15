"""The largest or smallest value a player can reach by changing one velocity axis in one step.

A player with acceleration bound ``a`` moves a velocity by any ``δ ∈ [-a dt, a dt]`` per step. On a
grid of spacing ``h`` that is a window of ``reach = a dt / h`` cells, usually not a whole number.
The linear interpolant is piecewise linear between nodes, so its maximum over the window is the
maximum over the whole nodes inside it and the two interpolated end points: a sliding-window
filter (a few shifted comparisons for small windows, SciPy's ``maximum_filter1d`` for wide ones)
plus two shifted linear interpolations, all on slices (no copies of shifted arrays). Past the grid's
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


def window_extreme(
    values: np.ndarray,
    axis: int,
    reach: float,
    kind: Extreme,
    out: np.ndarray | None = None,
    scratch: np.ndarray | None = None,
) -> np.ndarray:
    """``out[i] = kind over δ ∈ [-reach, reach] of values(i + δ)`` along ``axis``, linear between nodes.

    ``reach`` is in cells (``a dt / h``). The result has the shape and dtype of ``values``; it is
    written into ``out`` if given (not ``values`` itself), and ``scratch`` (same shape) is used for
    the end points, so that a caller repeating this on large arrays allocates nothing.
    """
    whole = int(math.floor(reach + _EPS))
    frac = reach - whole
    combine = np.maximum if kind == "max" else np.minimum
    n = values.shape[axis]
    if whole > _DIRECT_UP_TO:
        sliding = maximum_filter1d if kind == "max" else minimum_filter1d
        out = sliding(values, 2 * whole + 1, axis=axis, mode="nearest", output=out)
    else:  # a few shifted comparisons beat the general filter on small windows
        if out is None:
            out = values.copy()
        else:
            np.copyto(out, values)
        for shift in range(1, min(whole, n - 1) + 1):
            head, tail = _along(axis, 0, n - shift), _along(axis, shift, n)
            combine(out[head], values[tail], out=out[head])  # clamped indices repeat the edge: nothing to add
            combine(out[tail], values[head], out=out[tail])
    if frac > _EPS and n > whole + 1:
        # the interpolated end points at i + reach and i - reach; where they fall past the edge both
        # of their nodes clamp to the edge node, which the window holds already
        scratch = np.empty_like(values) if scratch is None else scratch
        ahead, behind = _along(axis, 0, n - whole - 1), _along(axis, whole + 1, n)
        for near, far, into in (
            (_along(axis, whole, n - 1), _along(axis, whole + 1, n), ahead),
            (_along(axis, 1, n - whole), _along(axis, 0, n - whole - 1), behind),
        ):
            end = scratch[into]
            np.subtract(values[far], values[near], out=end)
            end *= frac
            end += values[near]
            combine(out[into], end, out=out[into])
    return out


def _along(axis: int, start: int, stop: int) -> tuple[slice, ...]:
    """The index ``[..., start:stop, ...]`` on ``axis``."""
    return (slice(None),) * axis + (slice(start, stop),)
