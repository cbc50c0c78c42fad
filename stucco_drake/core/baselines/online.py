"""Clusterings refitted at every contact step, and the tracker that runs them.

The tracking itself (append p - dx, re-cluster, move each new point's cluster) is
:class:`~stucco_drake.core.clustering_tracker.ClusteringTracker`'s; this module only adds what
some clusterings need from a step (the caller's generator, the new observations) and the
authors' final labelling of the moved points.
"""

from __future__ import annotations

import warnings

import numpy as np
from sklearn.cluster import DBSCAN, Birch, KMeans
from sklearn.exceptions import ConvergenceWarning
from threadpoolctl import threadpool_limits

from stucco_drake.core.baselines.params import BirchParams, DbscanParams, KMeansParams
from stucco_drake.core.clustering_tracker import ClusteringTracker
from stucco_drake.core.validation import as_finite_array


class OnlineClustering:
    """A clustering called once per contact step on all stored points (m, world), new ones last.

    Subclasses override :meth:`__call__`; stateful ones also :meth:`begin_step` and
    :meth:`final_labels`.
    """

    def begin_step(self, rng: np.random.Generator, new_points: np.ndarray) -> None:
        """Called before the step's clustering with the (m, 3) new pre-motion points (m)."""

    def __call__(self, points: np.ndarray) -> np.ndarray:
        """(n,) labels of the (n, 3) points (m), -1 for noise; fits the clustering."""
        raise NotImplementedError

    def final_labels(self, points: np.ndarray) -> np.ndarray:
        """Labels of the moved points for evaluation (the authors refit on them)."""
        return self(points)


class BirchClustering(OnlineClustering):
    """BIRCH without a global step: every leaf subcluster (radius <= threshold) is an object."""

    def __init__(self, params: BirchParams | None = None):
        self.params = params or BirchParams()

    def __call__(self, points):
        return Birch(threshold=self.params.threshold, n_clusters=None).fit_predict(points)


class DbscanClustering(OnlineClustering):
    """DBSCAN; with min_samples = 1 it is single linkage at eps."""

    def __init__(self, params: DbscanParams | None = None):
        self.params = params or DbscanParams()

    def __call__(self, points):
        p = self.params
        return DBSCAN(eps=p.eps, min_samples=p.min_samples).fit_predict(points)


class IncrementalKMeans(OnlineClustering):
    """k-means whose k starts at 1 and never decreases.

    Each step fits k and k + 1 clusters and keeps k + 1 once enough points are stored and its
    inertia is below ``inertia_ratio`` times that of k. Initialisation is seeded from the
    caller's generator (one draw per step, shared by both fits).
    """

    def __init__(self, params: KMeansParams | None = None):
        self.params = params or KMeansParams()
        self.k = 1
        self._seed = 0
        self._model: KMeans | None = None

    def begin_step(self, rng, new_points):
        self._seed = int(rng.integers(2**31 - 1))

    def _fit(self, points, k) -> KMeans:
        # A few dozen points: starting OpenMP threads costs more than the fit (7x here).
        with warnings.catch_warnings(), threadpool_limits(limits=1, user_api="openmp"):
            # Fewer distinct points than clusters only makes a fit's inertia 0, which the
            # ratio test already handles.
            warnings.simplefilter("ignore", ConvergenceWarning)
            model = KMeans(n_clusters=k, n_init=self.params.n_init, random_state=self._seed)
            return model.fit(points)

    def __call__(self, points):
        model = self._fit(points, self.k)
        if len(points) >= max(self.params.min_points, self.k + 1):
            more = self._fit(points, self.k + 1)
            if more.inertia_ < self.params.inertia_ratio * model.inertia_:
                self.k += 1
                model = more
        self._model = model
        return model.labels_

    def final_labels(self, points):
        if self._model is None:
            return np.zeros(len(points), dtype=np.int64)
        return self._model.predict(points)  # the authors' predict, not a refit


def singletons_for_noise(labels) -> np.ndarray:
    """Give every noise point (-1) its own new label, as the authors score noise."""
    labels = np.array(labels, dtype=np.int64)
    noise = labels < 0
    start = labels.max(initial=-1) + 1
    labels[noise] = start + np.arange(noise.sum())
    return labels


class BaselineTracker(ClusteringTracker):
    """:class:`ClusteringTracker` running an :class:`OnlineClustering`.

    Args:
        cluster: the clustering; it is given the caller's generator and the step's new
            pre-motion points before each re-clustering.
    """

    cluster: OnlineClustering

    def update(self, rng, ee_position, contact_points=None, contact_dx=None, ee_rotation=None):
        """Same signature as :meth:`SoftTracker.update` (m, world); the pose goes unused."""
        if not isinstance(rng, np.random.Generator):
            raise ValueError(f"rng: expected numpy.random.Generator, got {type(rng).__name__}")
        as_finite_array(ee_position, "ee_position", (3,))
        if contact_points is not None and len(contact_points):
            points = as_finite_array(contact_points, "contact_points", (None, 3))
            dx = as_finite_array(contact_dx, "contact_dx", (len(points), 3))
            self.cluster.begin_step(rng, points - dx)
        super().update(rng, ee_position, contact_points, contact_dx, ee_rotation)

    def segment(self) -> np.ndarray:
        """(n,) final labels of the moved points; each noise point is its own object."""
        if self.n_contacts == 0:
            return np.zeros(0, dtype=np.int64)
        return singletons_for_noise(self.cluster.final_labels(self.map_points()))
