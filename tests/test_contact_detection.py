"""The pure-numpy side: momentum observer, residual statistics and per-action bookkeeping."""

from __future__ import annotations

import numpy as np
import pytest

from stucco_drake.core.detection import (
    ActionContactAccumulator,
    ResidualStatistics,
    chi2_statistic,
    chi2_threshold,
    fit_residual_statistics,
)
from stucco_drake.core.momentum_observer import memory_size, observer_step, wrench_least_squares


def test_fit_recovers_covariance_plus_floor():
    rng = np.random.default_rng(0)
    a = rng.normal(size=(6, 6))
    cov = a @ a.T / 6
    samples = rng.multivariate_normal(np.arange(6.0), cov, size=200_000)
    stats = fit_residual_statistics(samples, floor_std=0.1, key="k")
    np.testing.assert_allclose(stats.mean, np.arange(6.0), atol=0.02)
    np.testing.assert_allclose(stats.covariance, cov + 0.01 * np.eye(6), atol=0.02)
    # With Σ^-1 (a negligible floor), the statistic of Gaussian samples has mean d (chi-square).
    stats = fit_residual_statistics(samples, floor_std=1e-4)
    chi2 = chi2_statistic(samples[:5000], stats.precision(), stats.mean)
    assert abs(chi2.mean() - 6.0) < 0.3


def test_save_load_round_trip(tmp_path):
    stats = ResidualStatistics.isotropic([0.05] * 3 + [0.5] * 3)
    stats = ResidualStatistics(stats.mean + 1.0, stats.covariance, n_samples=7, key="abc")
    stats.save(tmp_path / "s.npz")
    loaded = ResidualStatistics.load(tmp_path / "s.npz")
    np.testing.assert_array_equal(loaded.mean, stats.mean)
    np.testing.assert_array_equal(loaded.covariance, stats.covariance)
    assert (loaded.n_samples, loaded.key) == (7, "abc")


def test_invalid_statistics_rejected():
    with pytest.raises(ValueError, match="positive definite"):
        ResidualStatistics(np.zeros(2), np.diag([1.0, -1.0]))
    with pytest.raises(ValueError, match="NaN"):
        fit_residual_statistics(np.full((3, 2), np.nan), floor_std=0.1)
    with pytest.raises(ValueError, match="false_alarm_rate"):
        chi2_threshold(6, 0.0)


def test_threshold_values():
    assert chi2_threshold(6, 1e-5) == pytest.approx(33.107, abs=1e-3)
    assert chi2_threshold(1, 0.3173) == pytest.approx(1.0, abs=1e-3)  # one sigma


def test_accumulator_sums_displacement_of_contact_steps_per_action():
    A = ActionContactAccumulator
    s = A.initial_state()
    # action 0: five steps along x of 1 cm, in contact at steps 2 and 3 (two displacements)
    for i, contact in enumerate([False, False, True, True, False]):
        s = A.step(s, 0, contact, [0.01 * i, 0.0, 0.0])
    current = A.current(s)
    assert current.action_index == 0 and current.in_contact and current.n_contact_steps == 2
    np.testing.assert_allclose(current.dx, [0.02, 0.0, 0.0])
    assert A.completed(s).action_index == -1
    # action 1 starts: the boundary step's motion (in contact) still belongs to action 0
    s = A.step(s, 1, True, [0.05, 0.01, 0.0])
    done = A.completed(s)
    assert done.action_index == 0 and done.n_contact_steps == 3
    np.testing.assert_allclose(done.dx, [0.03, 0.01, 0.0])
    assert A.current(s).action_index == 1 and not A.current(s).in_contact
    np.testing.assert_array_equal(A.current(s).dx, np.zeros(3))
    # a free action closes with no contact and zero dx; min_contact_steps debounces
    s = A.step(s, 1, False, [0.06, 0.01, 0.0])
    s = A.step(s, 2, False, [0.07, 0.01, 0.0])
    assert not A.completed(s).in_contact and A.completed(s).action_index == 1
    np.testing.assert_array_equal(A.completed(s).dx, np.zeros(3))


def test_accumulator_keeps_the_peak_force_of_the_contact_steps_per_action():
    A = ActionContactAccumulator
    s = A.initial_state()
    # action 0: 40 N while free (not counted), then 3 N and 25 N in contact
    for force, contact in ((40.0, False), (3.0, True), (25.0, True), (1.0, False)):
        s = A.step(s, 0, contact, [0.0, 0.0, 0.0], force)
    assert A.current(s).peak_force == 25.0
    s = A.step(s, 1, False, [0.0, 0.0, 0.0], 50.0)  # closes action 0; its boundary step is free
    assert A.completed(s).peak_force == 25.0
    s = A.step(s, 2, False, [0.0, 0.0, 0.0], 2.0)
    assert A.completed(s).peak_force == 0.0  # action 1 had no step in contact
    # no force given: NaN, as an ActionContact made without one
    s = A.initial_state()
    s = A.step(A.step(s, 0, True, [0.0, 0.0, 0.0]), 1, False, [0.0, 0.0, 0.0])
    assert np.isnan(A.completed(s).peak_force)


def test_momentum_observer_is_a_first_order_filter_of_the_external_torque():
    """A 2-joint system with a configuration-dependent mass matrix, stepped like Drake's discrete
    plants (M_n (v_{n+1} - v_n) = h (τ + known + τ_ext)); the observer must give exactly
    r_{n+1} = (1 - K h) r_n + K h τ_ext,n, in both torque timings."""
    rng = np.random.default_rng(0)
    h, gain = 1e-3, 50.0

    def mass(q):
        return np.array([[2.0 + np.cos(q[1]), 0.3], [0.3, 1.0 + 0.5 * np.sin(q[0]) ** 2]])

    for lags in (True, False):
        q, v = np.zeros(2), np.zeros(2)
        memory, r, expected = np.zeros(memory_size(2)), np.zeros(2), np.zeros(2)
        tau_prev = np.zeros(2)
        for n in range(400):
            tau = rng.normal(size=2)
            tau_ext = np.array([1.0, -2.0]) if n >= 100 else np.zeros(2)
            known = -np.array([0.5 * v[0] * v[1], 9.81 * np.sin(q[0])])
            # The observer reads the state; with lagging torque it reads the torque of the step
            # that led here, else the one about to act.
            memory, r_new = observer_step(
                memory, r, mass(q), known, tau_prev if lags else tau, v, h, gain, lags
            )
            if n >= 2:
                np.testing.assert_allclose(r_new, expected, atol=1e-9)
            if n >= 1:
                expected = (1 - gain * h) * r_new + gain * h * tau_ext
            r = r_new
            v = v + h * np.linalg.solve(mass(q), tau + known + tau_ext)
            q = q + h * v
            tau_prev = tau
        assert np.allclose(r, [1.0, -2.0], atol=1e-3)


def test_wrench_least_squares_inverts_jacobian_transpose():
    rng = np.random.default_rng(1)
    J = rng.normal(size=(6, 7))
    F = rng.normal(size=6)
    np.testing.assert_allclose(wrench_least_squares(J, J.T @ F, 1e-6), F, atol=1e-8)
