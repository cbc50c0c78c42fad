"""Contact detection from an external-wrench residual (paper Sec. IV-A, Eq. 1), in pure numpy.

Three pieces, each free of any simulator:

- :class:`ResidualStatistics`: mean and covariance of the residual measured in free space (the
  paper's "precision matrix of the residual, measured by executing random actions in free
  space" is the inverse of this covariance), saved to and loaded from ``.npz``.
- :func:`chi2_statistic` and :func:`chi2_threshold`: the test r^T Σ^-1 r > threshold.
- :class:`ActionContactAccumulator`: per-action bookkeeping between two tracker updates: whether
  any step was in contact and the end-effector displacement made while in contact (the paper's
  dx_t, Algorithm 1 line "observe x_t and dx_t").
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
from scipy import stats

from stucco_drake.core.npz import save_npz_atomically

#: Version of the ``.npz`` layout written by :meth:`ResidualStatistics.save`.
_FORMAT_VERSION = 1


@dataclasses.dataclass(frozen=True)
class ResidualStatistics:
    """Free-space statistics of a residual vector (any dimension d; the wrench has d = 6).

    Attributes:
        mean: (d,) sample mean, in the residual's units (for the wrench: N·m then N).
        covariance: (d, d) sample covariance plus the diagonal floor it was fitted with.
        n_samples: number of residual samples the statistics come from.
        key: content hash of what produced them (robot model files and observer settings), so a
            cached file is never used for another robot or another observer.
    """

    mean: np.ndarray
    covariance: np.ndarray
    n_samples: int = 0
    key: str = ""

    def __post_init__(self):
        mean = np.asarray(self.mean, dtype=np.float64).reshape(-1)
        cov = np.asarray(self.covariance, dtype=np.float64)
        d = mean.size
        if cov.shape != (d, d):
            raise ValueError(f"ResidualStatistics: covariance must be ({d}, {d}), got {cov.shape}")
        if not (np.all(np.isfinite(mean)) and np.all(np.isfinite(cov))):
            raise ValueError("ResidualStatistics: mean or covariance has NaN or infinite entries")
        if not np.allclose(cov, cov.T, rtol=1e-9, atol=1e-15):
            raise ValueError("ResidualStatistics: covariance is not symmetric")
        try:
            np.linalg.cholesky(cov)
        except np.linalg.LinAlgError as err:
            raise ValueError("ResidualStatistics: covariance is not positive definite") from err
        object.__setattr__(self, "mean", mean)
        object.__setattr__(self, "covariance", 0.5 * (cov + cov.T))

    @property
    def dim(self) -> int:
        """Dimension d of the residual."""
        return self.mean.size

    def precision(self) -> np.ndarray:
        """Σ^-1, the (d, d) precision matrix, symmetric."""
        inv = np.linalg.inv(self.covariance)
        return 0.5 * (inv + inv.T)

    @classmethod
    def isotropic(cls, std) -> ResidualStatistics:
        """Zero mean and a diagonal covariance diag(std^2); ``std`` is a (d,) array of std devs."""
        std = np.asarray(std, dtype=np.float64).reshape(-1)
        return cls(mean=np.zeros(std.size), covariance=np.diag(std**2))

    def save(self, path: str | Path) -> None:
        """Write to ``path`` (.npz), atomically (write a temporary file, then rename it)."""
        save_npz_atomically(
            path,
            mean=self.mean,
            covariance=self.covariance,
            n_samples=self.n_samples,
            key=np.array(self.key),
            format=_FORMAT_VERSION,
        )

    @classmethod
    def load(cls, path: str | Path) -> ResidualStatistics:
        """Read a file written by :meth:`save`; ValueError for another layout version."""
        with np.load(Path(path), allow_pickle=False) as data:
            if int(data["format"]) != _FORMAT_VERSION:
                raise ValueError(f"{path}: residual statistics format {int(data['format'])}")
            return cls(
                mean=data["mean"],
                covariance=data["covariance"],
                n_samples=int(data["n_samples"]),
                key=str(data["key"]),
            )


def fit_residual_statistics(samples, floor_std, key: str = "") -> ResidualStatistics:
    """Mean and covariance of free-space residual ``samples`` (N, d), plus a diagonal floor.

    The floor, diag(floor_std^2), is added to the sample covariance. Why: with an exact robot model
    and no sensor noise (a simulator) the free-space residual is zero up to rounding, so a raw
    covariance would make Σ^-1 huge and flag round-off as contact. The floor states the smallest
    wrench the detector is meant to resolve; it is the whole covariance in that noise-free case.
    """
    x = np.asarray(samples, dtype=np.float64)
    if x.ndim != 2 or x.shape[0] < 2:
        raise ValueError(f"fit_residual_statistics: expected (N >= 2, d) samples, got {x.shape}")
    if not np.all(np.isfinite(x)):
        raise ValueError("fit_residual_statistics: samples contain NaN or infinite values")
    floor = np.broadcast_to(np.asarray(floor_std, dtype=np.float64), (x.shape[1],))
    if np.any(floor <= 0):
        raise ValueError("fit_residual_statistics: floor_std must be positive")
    cov = np.cov(x, rowvar=False) + np.diag(floor**2)
    return ResidualStatistics(x.mean(axis=0), cov, n_samples=x.shape[0], key=key)


def chi2_statistic(residual, precision, mean=None) -> np.ndarray | float:
    """(r - mean)^T P (r - mean) for one residual (d,) or a batch (N, d); P is (d, d)."""
    r = np.asarray(residual, dtype=np.float64)
    if mean is not None:
        r = r - mean
    value = np.einsum("...i,ij,...j->...", r, precision, r)
    return float(value) if np.ndim(value) == 0 else value


def chi2_threshold(dof: int, false_alarm_rate: float) -> float:
    """The r^T Σ^-1 r level that a zero-mean Gaussian residual of ``dof`` dimensions exceeds with
    probability ``false_alarm_rate`` per sample (the chi-square survival quantile)."""
    if not 0.0 < false_alarm_rate < 1.0:
        raise ValueError(
            f"chi2_threshold: false_alarm_rate must lie in (0, 1), got {false_alarm_rate}"
        )
    return float(stats.chi2.isf(false_alarm_rate, dof))


@dataclasses.dataclass(frozen=True)
class ActionContact:
    """What the detector saw during one action (between two tracker updates).

    Attributes:
        action_index: the index of the action, as given by the action clock (-1: none yet).
        in_contact: True when at least ``min_contact_steps`` steps of the action were in contact.
        dx: (3,) end-effector displacement (world frame, m) summed over the steps in contact:
            the paper's dx_t, the motion that the touched objects are assumed to follow.
        n_contact_steps: number of steps whose residual exceeded the threshold.
        peak_force: the largest magnitude of the estimated external force on the end effector
            over those steps (N; NaN when no force was given, 0 with no step in contact).
            Whether the touched object gave way: a light object slides at a few newtons, a
            heavy or blocked one resists up to the controller's push limit.
    """

    action_index: int = -1
    in_contact: bool = False
    dx: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros(3))
    n_contact_steps: int = 0
    peak_force: float = float("nan")


class ActionContactAccumulator:
    """Per-step contact flags and end-effector positions, summed per action.

    State is one flat float vector (so a Drake system can keep it as discrete state); these
    static methods read and write it. Layout (``SIZE`` entries):
    ``[prev_position(3), has_prev, action, dx(3), n_contact, done_action, done_dx(3), done_n,
    peak_force, done_peak_force]``.

    At each step, the displacement since the previous step counts into dx when that step is in
    contact. When the action index changes, the displacement of the boundary step is still
    counted in the old action (it was made under the old command), then the old action is closed
    (its summary is kept as the "completed" action) and the new one starts from zero. The peak
    force is the largest ``force`` given at a step in contact (NaN: none given).
    """

    SIZE = 16
    _PREV, _HAS_PREV, _ACTION, _DX, _N = slice(0, 3), 3, 4, slice(5, 8), 8
    _DONE_ACTION, _DONE_DX, _DONE_N = 9, slice(10, 13), 13
    _PEAK, _DONE_PEAK = 14, 15

    @classmethod
    def initial_state(cls) -> np.ndarray:
        """No previous position, action -1, nothing accumulated, no completed action."""
        s = np.zeros(cls.SIZE)
        s[cls._ACTION] = -1.0
        s[cls._DONE_ACTION] = -1.0
        s[cls._PEAK] = s[cls._DONE_PEAK] = np.nan
        return s

    @classmethod
    def step(cls, state, action_index: int, in_contact: bool, position,
             force: float = float("nan")) -> np.ndarray:  # fmt: skip
        """The state after one step at end-effector ``position`` (3,) in world (m), with the
        estimated external force's magnitude ``force`` (N; NaN: not measured)."""
        s = np.array(state, dtype=np.float64)
        position = np.asarray(position, dtype=np.float64)
        if s[cls._HAS_PREV] and in_contact:
            s[cls._DX] += position - s[cls._PREV]
        if in_contact:
            s[cls._N] += 1.0
        if not np.isnan(force):
            peak = 0.0 if np.isnan(s[cls._PEAK]) else s[cls._PEAK]
            s[cls._PEAK] = max(peak, float(force)) if in_contact else peak
        if int(s[cls._ACTION]) != int(action_index):
            if s[cls._ACTION] >= 0:  # close the running action; before the first one, nothing
                s[cls._DONE_ACTION] = s[cls._ACTION]
                s[cls._DONE_DX] = s[cls._DX]
                s[cls._DONE_N] = s[cls._N]
                s[cls._DONE_PEAK] = s[cls._PEAK]
            s[cls._ACTION] = float(action_index)
            s[cls._DX] = 0.0
            s[cls._N] = 0.0
            s[cls._PEAK] = np.nan
        s[cls._PREV] = position
        s[cls._HAS_PREV] = 1.0
        return s

    @classmethod
    def current(cls, state, min_contact_steps: int = 1) -> ActionContact:
        """The action under way, as accumulated so far."""
        return ActionContact(
            int(state[cls._ACTION]),
            bool(state[cls._N] >= min_contact_steps),
            np.array(state[cls._DX]),
            int(state[cls._N]),
            float(state[cls._PEAK]),
        )

    @classmethod
    def completed(cls, state, min_contact_steps: int = 1) -> ActionContact:
        """The last action that has ended (action_index -1 before the first one ends)."""
        return ActionContact(
            int(state[cls._DONE_ACTION]),
            bool(state[cls._DONE_N] >= min_contact_steps),
            np.array(state[cls._DONE_DX]),
            int(state[cls._DONE_N]),
            float(state[cls._DONE_PEAK]),
        )
