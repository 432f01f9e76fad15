"""The cross-check backend: the same ``rel4d`` problem solved by ``hj-reachability`` (JAX), in continuous time.

``hj-reachability`` solves the Hamilton–Jacobi–Isaacs PDE ``∂V/∂t + min(0, H) = 0`` backwards from
``V = l`` over the horizon (a backward reachable tube), with WENO5 derivatives, Lax–Friedrichs
dissipation and third-order TVD Runge–Kutta steps whose size the CFL condition sets. The
dynamics are the continuous ones, ``ṙ = w`` and ``ẇ = a_e - a_p`` with both inputs in their
boxes, on the same grid; the relative velocity is not clipped (the grid's edge extrapolates).
Its value is the continuous-time closed form's counterpart, so compare it with
:func:`pecli.hj.oracle.continuous_value`. The order (``maxmin``/``minmax``) does not matter in
continuous time: the dynamics separate the inputs, so the two orders agree (Isaacs' condition).

Install it with pecli's ``hj`` extra (``pip install -e ".[hj]"`` in the checkout, or ``pip install
"hj-reachability>=0.7"``); only ``rel4d`` is offered.
"""

from __future__ import annotations

import numpy as np

from pecli.errors import PecliError
from pecli.hj.problem import Problem


def available() -> bool:
    """Whether ``hj-reachability`` (and JAX) can be imported."""
    try:
        import hj_reachability  # noqa: F401
    except ImportError:
        return False
    return True


def solve_with_hj_reachability(problem: Problem, accuracy: str = "very_high") -> np.ndarray:
    """The value of ``problem`` (``rel4d``) from ``hj-reachability``, float32, shape ``problem.grid.shape``."""
    if problem.model != "rel4d":
        raise PecliError(f"the hj-reachability backend solves rel4d only, not {problem.model}")
    try:
        import hj_reachability as hj
        import jax.numpy as jnp
    except ImportError:
        raise PecliError(
            "hj-reachability is not installed: pip install 'hj-reachability>=0.7' (pecli's hj extra)"
        ) from None

    game, grid = problem.game, problem.grid

    class Relative(hj.ControlAndDisturbanceAffineDynamics):
        """State ``(w_x, r_x, w_y, r_y)``; control: the pursuer's acceleration (min),
        disturbance: the evader's (max)."""

        def __init__(self) -> None:
            p = game.pursuer_a_max * jnp.ones(2)
            e = game.evader_a_max * jnp.ones(2)
            super().__init__("min", "max", hj.sets.Box(-p, p), hj.sets.Box(-e, e))

        def open_loop_dynamics(self, state, time):
            return jnp.array([0.0, state[0], 0.0, state[2]])

        def control_jacobian(self, state, time):
            return jnp.array([[-1.0, 0.0], [0.0, 0.0], [0.0, -1.0], [0.0, 0.0]])

        def disturbance_jacobian(self, state, time):
            return jnp.array([[1.0, 0.0], [0.0, 0.0], [0.0, 1.0], [0.0, 0.0]])

    lows = jnp.array([a.low for a in grid.axes])
    highs = jnp.array([a.high for a in grid.axes])
    hj_grid = hj.Grid.from_lattice_parameters_and_boundary_conditions(hj.sets.Box(lows, highs), grid.shape)
    target = jnp.hypot(hj_grid.states[..., 1], hj_grid.states[..., 3]) - game.capture_distance
    settings = hj.SolverSettings.with_accuracy(accuracy, hamiltonian_postprocessor=hj.solver.backwards_reachable_tube)
    values = hj.step(settings, Relative(), hj_grid, 0.0, target, -problem.steps * game.dt, progress_bar=False)
    return np.asarray(values, dtype=np.float32)
