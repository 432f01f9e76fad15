"""The UKF belief baseline (paper section V): a constant-velocity unscented Kalman filter over the window.

The filter's state is the opponent's ``(x, y, v_x, v_y)`` (normalised positions, per second); it
starts at the arena's centre, predicts one window spacing (1 s in the paper) per sample and
updates with the opponent's position whenever it was seen. As a UKF with filterpy's
``MerweScaledSigmaPoints`` (alpha 0.1, beta 2, kappa 1), computed in closed form (:class:`BatchUKF`);
process noise, measurement noise and initial covariance are 0.1 (the paper's values). The
belief's mean is the filter's, projected into the arena **(ours)**: extrapolating a sighting's
velocity for up to 20 s otherwise often "believes" the opponent beyond a wall. The filter runs batched over games;
``tests/test_belief.py`` checks it against filterpy's ``UnscentedKalmanFilter`` step by step.
"""

from __future__ import annotations

import numpy as np
import torch as th

from pecli.belief.mixture import Mixture
from pecli.belief.window import WindowDecoder

NOISE = 0.1  # process noise, measurement noise and initial covariance (times the identity)


def transition(dt: float) -> np.ndarray:
    """Constant velocity over ``dt`` seconds: the 4 x 4 state transition."""
    f = np.eye(4)
    f[0, 2] = f[1, 3] = dt
    return f


class BatchUKF:
    """``B`` independent UKFs with a linear constant-velocity model and position measurements.

    For a linear model the unscented transform is exact: the sigma points of ``(x, P)`` carried
    through ``F`` give back ``F x`` and ``F P F^T`` whatever the scaling, and those of the predicted
    state through ``H`` give ``H x``, ``H P H^T`` and ``P H^T``. So the filter computes those in closed
    form (no Cholesky factor, a 2 x 2 inverse written out) and equals filterpy's
    ``UnscentedKalmanFilter`` with ``MerweScaledSigmaPoints`` to rounding, about 3x faster per window.
    """

    def __init__(self, batch: int, dt: float, noise: float = NOISE) -> None:
        self.dt = dt
        self.noise = noise
        self.x = np.zeros((batch, 4))
        self.p = np.tile(noise * np.eye(4), (batch, 1, 1))

    def predict(self, rows: np.ndarray) -> None:
        """Predict one step for the games where ``rows`` is true: ``x = F x``, ``P = F P F^T + Q``."""
        games = slice(None) if rows.all() else np.flatnonzero(rows)
        x, p, dt = self.x[games], self.p[games], self.dt
        x[:, :2] += dt * x[:, 2:]
        p[:, :2] += dt * p[:, 2:]  # F P: position rows gain dt times the velocity rows
        p[:, :, :2] += dt * p[:, :, 2:]  # (F P) F^T: position columns gain dt times the velocity columns
        p[:, range(4), range(4)] += self.noise
        self.x[games], self.p[games] = x, p

    def update(self, z: np.ndarray, rows: np.ndarray) -> None:
        """Update with positions ``z`` ``(B, 2)`` for the games where ``rows`` is true (after :meth:`predict`)."""
        seen = np.flatnonzero(rows)
        if seen.size == 0:
            return
        x, p = self.x[seen], self.p[seen]
        s = p[:, :2, :2] + self.noise * np.eye(2)  # innovation covariance H P H^T + R
        adjugate = np.swapaxes(s[:, ::-1, ::-1], 1, 2) * np.array([[1.0, -1.0], [-1.0, 1.0]])  # [[d, -b], [-c, a]]
        inverse = adjugate / (s[:, 0, 0] * s[:, 1, 1] - s[:, 0, 1] * s[:, 1, 0])[:, None, None]
        gain = p[:, :, :2] @ inverse  # P H^T S^-1, (B, 4, 2)
        self.x[seen] = x + (gain @ (z[seen] - x[:, :2])[:, :, None])[:, :, 0]
        self.p[seen] = p - gain @ p[:, :2, :]  # K S K^T = K H P


class WindowUKF:
    """Runs a :class:`BatchUKF` over each history window; returns a one-component :class:`Mixture`."""

    def __init__(self, decoder: WindowDecoder) -> None:
        self.decoder = decoder

    def __call__(self, history: np.ndarray) -> Mixture:
        window = self.decoder(history)
        batch, steps = window.seen.shape
        ukf = BatchUKF(batch, self.decoder.dt)
        for t in range(steps):
            valid = window.valid[:, t]
            ukf.predict(valid)
            ukf.update(window.opp_pos[:, t], valid & window.seen[:, t])
        std = np.sqrt(np.clip(np.diagonal(ukf.p, axis1=1, axis2=2)[:, :2], 1e-9, None))
        return Mixture(
            logits=th.zeros((batch, 1)),
            means=th.as_tensor(np.clip(ukf.x[:, None, :2], -1.0, 1.0), dtype=th.float32),  # inside the arena
            stds=th.as_tensor(std[:, None, :], dtype=th.float32),
        )
