"""The discrete momentum observer and the wrench fit, in pure numpy (no simulator).

:class:`stucco_drake.systems.wrench_estimator.ExternalWrenchEstimator` evaluates the robot model
(M, C v, τ_g, J) with Drake and hands the numbers to these functions; its docstring derives the
discrete form.
"""

from __future__ import annotations

import numpy as np


def memory_size(n_dof: int) -> int:
    """Length of the observer memory for ``n_dof`` joints: [n, p0, integral, a_prev, M_prev]."""
    return 1 + 3 * n_dof + n_dof * n_dof


def observer_step(
    memory: np.ndarray,
    r_prev: np.ndarray,
    M: np.ndarray,
    known: np.ndarray,
    tau: np.ndarray,
    v: np.ndarray,
    h: float,
    gain: float,
    torque_lags_state: bool,
) -> tuple[np.ndarray, np.ndarray]:
    """One sample of the momentum observer; returns (new memory, residual r).

    Args:
        memory: (memory_size(n),) [n, p0, integral, a_prev, M_prev (row-major)], all zeros at
            first. n counts samples; a_prev is the known part of the last momentum increment.
        r_prev: (n,) the residual of the previous sample (N·m).
        M: (n, n) mass matrix at this sample's q (kg·m²).
        known: (n,) τ_g - C v at this sample's (q, v) (N·m).
        tau: (n,) measured joint torque (N·m).
        v: (n,) joint velocity (rad/s).
        h: sample period (s).
        gain: K_O (1/s).
        torque_lags_state: True when ``tau`` is the torque of the step that led to this sample
            (it joins this increment); False when it acts over the coming step (it is kept).

    r = K_O (p - p0 - Σ (β + h r)) with β = a_prev + (M - M_prev) v (+ h τ), so that
    r_{k+1} = (1 - K_O h) r_k + K_O h τ_ext,k for a plant stepped as Drake's discrete plants are.
    """
    nd = v.size
    p0, integral = slice(1, 1 + nd), slice(1 + nd, 1 + 2 * nd)
    a_prev, M_prev = slice(1 + 2 * nd, 1 + 3 * nd), slice(1 + 3 * nd, None)
    p = M @ v
    hu = h * tau
    new = memory.copy()
    if memory[0] == 0:
        # First sample: no step has been observed yet; the integral starts at p(0).
        new[p0], new[integral], r = p, 0.0, np.zeros(nd)
    else:
        beta = memory[a_prev] + (M - memory[M_prev].reshape(nd, nd)) @ v
        if torque_lags_state:
            beta += hu
        new[integral] += beta + h * r_prev
        r = gain * (p - memory[p0] - new[integral])
    new[0] = memory[0] + 1
    new[a_prev] = h * known if torque_lags_state else h * known + hu
    new[M_prev] = M.ravel()
    return new, r


def wrench_least_squares(J: np.ndarray, tau_ext: np.ndarray, damping: float) -> np.ndarray:
    """The spatial force F (6,) whose joint torques Jᵀ F best match ``tau_ext``.

    Damped least squares, (J Jᵀ + λ² I) F = J τ_ext, with J (6, n) the Jacobian of the point's
    spatial velocity [ω; v], so F is [torque; force] at that point in J's expressed-in frame.
    """
    return np.linalg.solve(J @ J.T + damping**2 * np.eye(J.shape[0]), J @ tau_ext)
