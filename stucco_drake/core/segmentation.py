"""Segmentation of contact points into objects (paper Algorithm 3)."""

from __future__ import annotations

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components as _components
from scipy.spatial import cKDTree


def connected_components(points, radius: float) -> np.ndarray:
    """Label points by the connected components of the graph linking pairs closer than ``radius``.

    This is Algorithm 3 exactly: with A_ij = exp(-d_ij^2 / l) > p_c, i.e. d_ij < sqrt(-l ln p_c),
    objects are the connected components of A (a full transitive closure, not a one-level
    expansion). It is also single-linkage clustering, and DBSCAN with min_samples = 1.

    Args:
        points: (n, 3) or (n, 2) positions (m).
        radius: link distance (m).

    Returns:
        (n,) int labels 0..k-1, numbered in order of each component's first point.
    """
    points = np.asarray(points, dtype=np.float64)
    n = len(points)
    if n == 0:
        return np.zeros(0, dtype=np.int64)
    pairs = cKDTree(points).query_pairs(radius, output_type="ndarray")
    graph = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(n, n))
    _, labels = _components(graph, directed=False)
    # Renumber so that labels follow the order in which components first appear.
    _, first = np.unique(labels, return_index=True)
    order = np.argsort(np.argsort(first))
    return order[labels].astype(np.int64)
