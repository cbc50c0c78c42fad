"""Log-weight arithmetic of the particle filters against scipy and closed forms."""

from __future__ import annotations

import math

import numpy as np
from scipy.special import logsumexp

from stucco_drake.core.resampling import log_sum_exp, normalize_log_weights


def test_log_sum_exp_is_scipys_bit_for_bit():
    """The tracker's results depend on every bit of its weights: 20,000 arrays of 1-300
    entries, wide ranges, tied maxima, -inf entries and constant arrays all agree exactly."""
    rng = np.random.default_rng(0)
    for i in range(20_000):
        n = int(rng.integers(1, 300))
        kind = i % 5
        if kind == 0:
            a = rng.normal(size=n) * 10 ** rng.uniform(-3, 4)
        elif kind == 1:
            a = -np.abs(rng.normal(size=n)) * 1e3
            a[rng.integers(n, size=3)] = a.max()
        elif kind == 2:
            a = np.full(n, -math.log(n))
        elif kind == 3:
            a = rng.normal(size=n)
            a[rng.random(n) < 0.3] = -np.inf
            a[0] = 0.0
        else:
            a = np.round(rng.normal(size=n), 2)
        assert log_sum_exp(a) == logsumexp(a), (kind, a)


def test_log_sum_exp_closed_forms_and_edge_cases():
    assert log_sum_exp(np.zeros(3)) == math.log(3.0)
    assert math.isclose(log_sum_exp(np.array([0.0, math.log(3.0)])), math.log(4.0))
    assert log_sum_exp(np.array([-np.inf, -np.inf])) == -np.inf
    assert math.isnan(log_sum_exp(np.array([0.0, np.nan])))
    weights = np.exp(normalize_log_weights(np.array([-1e3, -1e3 + math.log(3.0)])))
    # Log weights near -1e3 carry about 1e-13 of absolute round-off.
    np.testing.assert_allclose(weights, [0.25, 0.75], rtol=1e-12)
