"""The GM-PHD filter baseline: a Gaussian-mixture probability hypothesis density over objects.

Objects are static points in the plane (x, y) observed directly by contacts (Vo & Ma 2006,
without spawning). Each contact step runs one predict-update-prune cycle on the step's new
pre-motion contact points; the stored points are then labelled by their nearest extracted
object. As the authors did, the intensity itself is never moved by the contacts' dx.
"""

from __future__ import annotations

import numpy as np

from stucco_drake.core.baselines.online import OnlineClustering
from stucco_drake.core.baselines.params import GmPhdParams


class GmPhdFilter:
    """The GM-PHD recursion (Vo & Ma 2006, Tables 1-3) with F = H = I.

    Attributes:
        weights: (J,) component weights; their sum is the expected number of objects.
        means: (J, 2) component means (m, world x, y).
        covariances: (J, 2, 2) component covariances (m^2).
    """

    def __init__(self, params: GmPhdParams | None = None):
        self.params = p = params or GmPhdParams()
        x0, y0, x1, y1 = p.birth_bounds
        xs = np.linspace(x0, x1, p.birth_grid)
        ys = np.linspace(y0, y1, p.birth_grid)
        grid_x, grid_y = np.meshgrid(xs, ys)  # x varies fastest, as the authors' grid
        self._birth_means = np.column_stack([grid_x.ravel(), grid_y.ravel()])
        n_birth = len(self._birth_means)
        self._birth_weights = np.full(n_birth, p.birth_weight / n_birth)
        self._birth_covariances = np.broadcast_to(p.birth_covariance * np.eye(2), (n_birth, 2, 2))
        self.weights = np.zeros(0)
        self.means = np.zeros((0, 2))
        self.covariances = np.zeros((0, 2, 2))

    def step(self, observations) -> None:
        """One predict-update-prune cycle with the (m, 2) observed positions (m, world)."""
        z = np.asarray(observations, dtype=np.float64).reshape(-1, 2)
        p = self.params
        # Predict: births, then survivors with F = I and Q = q I (objects do not move).
        w = np.concatenate([self._birth_weights, p.survival * self.weights])
        m = np.concatenate([self._birth_means, self.means])
        survivors = self.covariances + p.process_noise * np.eye(2)
        cov = np.concatenate([self._birth_covariances, survivors])
        # Update with H = I and R = r I.
        s = cov + p.observation_noise * np.eye(2)
        s_inv = np.linalg.inv(s)
        gain = cov @ s_inv
        posterior = cov - gain @ cov if p.update_covariance else cov  # (I - K H) P
        diff = z[:, None, :] - m[None]  # (m, J, 2)
        mahalanobis = np.einsum("mji,jik,mjk->mj", diff, s_inv, diff)
        likelihood = np.exp(-0.5 * mahalanobis) / (2 * np.pi * np.sqrt(np.linalg.det(s)))
        detected = p.detection * w[None] * likelihood
        detected /= p.clutter_intensity + detected.sum(axis=1, keepdims=True)
        detected_means = m[None] + np.einsum("jik,mjk->mji", gain, diff)
        self.weights = np.concatenate([(1.0 - p.detection) * w, detected.ravel()])
        self.means = np.concatenate([m, detected_means.reshape(-1, 2)])
        self.covariances = np.concatenate([cov, np.tile(posterior, (len(z), 1, 1))])
        self._prune()

    def _prune(self) -> None:
        """Vo & Ma Table 2: truncate, merge neighbours of the heaviest, keep the heaviest few."""
        p = self.params
        total = self.weights.sum()
        keep = self.weights > p.truncate
        w, m, cov = self.weights[keep], self.means[keep], self.covariances[keep]
        cov_inv = np.linalg.inv(cov)
        left = np.ones(len(w), dtype=bool)
        merged_w, merged_m, merged_cov = [], [], []
        while left.any():
            heaviest = np.flatnonzero(left)[np.argmax(w[left])]
            d = m - m[heaviest]
            near = left & (np.einsum("ji,jik,jk->j", d, cov_inv, d) <= p.merge)
            weight = w[near].sum()
            mean = w[near] @ m[near] / weight
            spread = mean - m[near]
            merged_cov.append(
                np.einsum("j,jik->ik", w[near], cov[near] + spread[:, :, None] * spread[:, None])
                / weight
            )
            merged_w.append(weight)
            merged_m.append(mean)
            left &= ~near
        order = np.argsort(merged_w, kind="stable")[::-1][: p.max_components]
        self.weights = np.asarray(merged_w)[order]
        self.means = np.asarray(merged_m).reshape(-1, 2)[order]
        self.covariances = np.asarray(merged_cov).reshape(-1, 2, 2)[order]
        if self.weights.sum() > 0:
            # Keep the expected number of objects that pruning dropped, as the authors did.
            self.weights *= total / self.weights.sum()

    def extract(self) -> np.ndarray:
        """(k, 2) object positions (m): round(bias * total weight) picks of the heaviest peak,
        each pick lowering it by 1; bias doubles until at least one object is picked."""
        total = float(self.weights.sum())
        if total <= 0.0:
            return np.zeros((0, 2))
        bias = self.params.bias
        count = round(bias * total)
        while count < 1:  # a contact was just made, so there is at least one object
            bias *= 2.0
            count = round(bias * total)
        peaks = self.weights.copy()
        picks = np.empty(count, dtype=np.int64)
        for index in range(count):
            picks[index] = np.argmax(peaks)
            peaks[picks[index]] -= 1.0
        return self.means[picks]


class GmPhdClustering(OnlineClustering):
    """Labels points by their nearest object extracted from a :class:`GmPhdFilter`.

    The filter runs on the planar (x, y) part of the step's new pre-motion points; the contact
    height is carried along unused.
    """

    def __init__(self, params: GmPhdParams | None = None):
        self.filter = GmPhdFilter(params)

    def begin_step(self, rng, new_points):
        self.filter.step(np.asarray(new_points)[:, :2])

    def __call__(self, points):
        return self.final_labels(points)

    def final_labels(self, points):
        objects = self.filter.extract()
        if len(objects) == 0:
            return np.zeros(len(points), dtype=np.int64)
        d2 = ((np.asarray(points)[:, None, :2] - objects[None]) ** 2).sum(axis=2)
        nearest = np.argmin(d2, axis=1)  # a repeated pick resolves to its first copy
        return np.unique(nearest, return_inverse=True)[1].astype(np.int64)
