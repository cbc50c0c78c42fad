"""Particle weights in log space: normalisation, effective sample size, systematic resampling."""

from __future__ import annotations

import numpy as np
from scipy.special import logsumexp


def normalize_log_weights(log_weights: np.ndarray) -> np.ndarray:
    """Shift log weights so that their exponentials sum to one."""
    return log_weights - logsumexp(log_weights)


def effective_sample_size(log_weights: np.ndarray) -> float:
    """1 / sum(w^2) of the normalised weights: between 1 and the number of particles."""
    weights = np.exp(normalize_log_weights(log_weights))
    return float(1.0 / np.sum(weights * weights))


def systematic_resample(log_weights: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Ancestor index of each new particle by systematic resampling (one uniform offset).

    A particle of weight w gets floor(N w) or ceil(N w) copies, so the heaviest one (w >= 1/N)
    always survives.
    """
    n = len(log_weights)
    cumulative = np.cumsum(np.exp(normalize_log_weights(log_weights)))
    cumulative[-1] = 1.0  # guard against round-off leaving the last bin short
    positions = (rng.random() + np.arange(n)) / n
    return np.minimum(np.searchsorted(cumulative, positions, side="right"), n - 1)
