"""How far a segment's contact points spread against the target's size, for the unions and
splits of segments in :func:`~stucco_drake.core.target_pose.estimate_target_pose`.

Units: metres; points in the world frame W, horizontal extents in its xy plane.
"""

from __future__ import annotations

import numpy as np

from stucco_drake.core.segmentation import connected_components
from stucco_drake.core.shapes import BoxSdf, CylinderSdf


def outline_extent(shape: BoxSdf | CylinderSdf) -> float:
    """The largest distance between two points of ``shape``'s cross-section (m): a box's
    diagonal, a cylinder's diameter."""
    if isinstance(shape, BoxSdf):
        return float(2.0 * np.hypot(*shape.half_extents[:2]))
    return 2.0 * float(shape.radius)


def xy_extent(points) -> float:
    """The largest horizontal distance between two of ``points`` ((n, 3) or (n, 2), m)."""
    xy = np.asarray(points)[:, :2]
    return float(np.sqrt(np.max(np.sum((xy[:, None] - xy[None]) ** 2, axis=-1))))


def split_wider_segments(points, labels, reach: float) -> np.ndarray:
    """Split every segment whose points span more than ``reach`` (m, horizontally) into the
    parts that link at ``reach`` (in 3-D, as the segmentation links); returns new labels.

    Linking in 3-D keeps two cans apart whose contacts overlap in plan at different heights;
    a target touched at its top and bottom may fall into two parts, which the unions of
    :func:`~stucco_drake.core.target_pose.estimate_target_pose` join
    again (their horizontal span fits the reach).

    A part keeps its segment's label if it holds the segment's first point; the others are
    numbered on from the largest label, in order of segment and then of first point.
    Negative labels (noise) are left alone. A segment whose points all link at ``reach`` keeps
    its label whatever its span.
    """
    points = np.asarray(points)
    labels = np.asarray(labels)
    split = labels.copy()
    next_label = int(labels.max(initial=-1)) + 1
    for label in np.unique(labels[labels >= 0]):
        members = np.flatnonzero(labels == label)
        if len(members) < 2 or xy_extent(points[members]) <= reach:
            continue
        parts = connected_components(points[members], reach)
        for part in range(1, int(parts.max()) + 1):
            split[members[parts == part]] = next_label
            next_label += 1
    return split
