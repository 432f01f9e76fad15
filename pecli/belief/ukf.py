"""The UKF belief baseline (paper section V): a constant-velocity unscented Kalman filter over the window.

The filter's state is the opponent's ``(x, y, v_x, v_y)`` (normalised positions, per second); it
starts at the arena's centre, predicts one window spacing (1 s in the paper) per sample and
updates with the opponent's position whenever it was seen. Sigma points and weights are
filterpy's ``MerweScaledSigmaPoints`` (alpha 0.1, beta 2, kappa 1); process noise, measurement
noise and initial covariance are 0.1 (the paper's values). The belief's mean is the filter's,
projected into the arena **(ours)**: extrapolating a sighting's velocity for up to 20 s otherwise
often "believes" the opponent beyond a wall. The filter runs batched over games;
``tests/test_belief.py`` checks it against filterpy's ``UnscentedKalmanFilter`` step by step.
"""

from __future__ import annotations

import numpy as np
import torch as th
from filterpy.kalman import MerweScaledSigmaPoints

from pecli.belief.mixture import Mixture
from pecli.belief.window import WindowDecoder

ALPHA, BETA, KAPPA = 0.1, 2.0, 1.0
NOISE = 0.1  # process noise, measurement noise and initial covariance (times the identity)


def transition(dt: float) -> np.ndarray:
    """Constant velocity over ``dt`` seconds: the 4 x 4 state transition."""
    f = np.eye(4)
    f[0, 2] = f[1, 3] = dt
    return f


class BatchUKF:
    """``B`` independent UKFs with a linear constant-velocity model and position measurements."""

    def __init__(self, batch: int, dt: float, noise: float = NOISE) -> None:
        points = MerweScaledSigmaPoints(4, alpha=ALPHA, beta=BETA, kappa=KAPPA)
        self.wm, self.wc = points.Wm, points.Wc  # (9,)
        self.spread = points.alpha**2 * (4 + points.kappa)  # lambda + n
        self.f = transition(dt)
        self.q = noise * np.eye(4)
        self.r = noise * np.eye(2)
        self.x = np.zeros((batch, 4))
        self.p = np.tile(noise * np.eye(4), (batch, 1, 1))
        self._sigmas = np.zeros((batch, 9, 4))

    def sigma_points(self) -> np.ndarray:
        """``(B, 9, 4)``: the mean, then plus and minus the columns of the scaled covariance's Cholesky factor."""
        lower = np.linalg.cholesky(self.spread * self.p)  # P' = L L^T; filterpy uses the rows of U = L^T
        offsets = np.swapaxes(lower, 1, 2)  # rows of U
        return np.concatenate([self.x[:, None], self.x[:, None] + offsets, self.x[:, None] - offsets], axis=1)

    def predict(self, rows: np.ndarray) -> None:
        """Predict one step for the games where ``rows`` is true.

        As filterpy does, the sigma points the update uses are drawn anew from the predicted mean
        and covariance (process noise included).
        """
        sigmas = self.sigma_points() @ self.f.T
        mean = np.einsum("k,bki->bi", self.wm, sigmas)
        centred = sigmas - mean[:, None]
        cov = np.einsum("k,bki,bkj->bij", self.wc, centred, centred) + self.q
        self.x = np.where(rows[:, None], mean, self.x)
        self.p = np.where(rows[:, None, None], cov, self.p)
        self._sigmas = np.where(rows[:, None, None], self.sigma_points(), self._sigmas)

    def update(self, z: np.ndarray, rows: np.ndarray) -> None:
        """Update with positions ``z`` ``(B, 2)`` for the games where ``rows`` is true (after :meth:`predict`)."""
        zs = self._sigmas[:, :, :2]
        z_mean = np.einsum("k,bki->bi", self.wm, zs)
        dz = zs - z_mean[:, None]
        dx = self._sigmas - self.x[:, None]
        s = np.einsum("k,bki,bkj->bij", self.wc, dz, dz) + self.r
        pxz = np.einsum("k,bki,bkj->bij", self.wc, dx, dz)
        gain = pxz @ np.linalg.inv(s)
        x = self.x + np.einsum("bij,bj->bi", gain, z - z_mean)
        p = self.p - gain @ s @ np.swapaxes(gain, 1, 2)
        self.x = np.where(rows[:, None], x, self.x)
        self.p = np.where(rows[:, None, None], p, self.p)


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
