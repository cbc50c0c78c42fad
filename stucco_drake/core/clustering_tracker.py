"""Single-estimate trackers that re-cluster every contact step (the paper's baseline wiring)."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from stucco_drake.core.segmentation import connected_components
from stucco_drake.core.validation import as_finite_array

#: A clustering: (n, 3) points -> (n,) int labels, -1 for noise.
Clustering = Callable[[np.ndarray], np.ndarray]


def single_linkage(radius: float) -> Clustering:
    """Connected components at ``radius``: DBSCAN with min_samples = 1 (m)."""

    def cluster(points: np.ndarray) -> np.ndarray:
        return connected_components(points, radius)

    return cluster


class ClusteringTracker:
    """One estimate of every contact point, moved by hard cluster assignments (paper Sec. V-A).

    At each step with contacts: append each new point at its pre-motion position p - dx,
    re-cluster all points, and move every member of a new point's cluster by the mean dx of that
    cluster's new points. Noise (label -1) never moves. Nothing is ever revised in hindsight.

    Args:
        cluster: the clustering applied at every contact step.
    """

    def __init__(self, cluster: Clustering):
        self.cluster = cluster
        self._points = np.zeros((0, 3))
        self._labels = np.zeros(0, dtype=np.int64)

    @property
    def n_contacts(self) -> int:
        return len(self._points)

    def map_points(self) -> np.ndarray:
        """(n, 3) the single estimate of every contact point (m, world)."""
        return self._points.copy()

    def segment(self) -> np.ndarray:
        """(n,) cluster labels of the points at the last contact step."""
        return self._labels.copy()

    def update(self, rng, ee_position, contact_points=None, contact_dx=None, ee_rotation=None):
        """Same signature as :meth:`SoftTracker.update`; ``rng`` and the pose go unused."""
        as_finite_array(ee_position, "ee_position", (3,))
        if contact_points is None or len(contact_points) == 0:
            return
        points = as_finite_array(contact_points, "contact_points", (None, 3))
        dx = as_finite_array(contact_dx, "contact_dx", (len(points), 3))
        first_new = len(self._points)
        self._points = np.concatenate([self._points, points - dx])
        labels = np.asarray(self.cluster(self._points))
        new_labels = labels[first_new:]
        for label in np.unique(new_labels[new_labels >= 0]):
            members = labels == label
            self._points[members] += dx[new_labels == label].mean(axis=0)
        noise = np.flatnonzero(new_labels < 0)
        self._points[first_new + noise] += dx[noise]  # a lone new point still lands on p_t
        self._labels = labels
