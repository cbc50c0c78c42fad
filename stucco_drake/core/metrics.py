"""Tracking metrics of the paper: contact error, Fowlkes-Mallows index, ambiguity."""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

from stucco_drake.core.validation import as_finite_array


def contact_error(points, surfaces: Sequence[Callable[[np.ndarray], np.ndarray]]) -> float:
    """Mean distance (m) from each tracked point to the nearest true object surface.

    Args:
        points: (n, 3) tracked contact points (m, world).
        surfaces: one signed-distance function per object (walls included) at the objects'
            final poses, each mapping (n, 3) world points to (n,) distances (m). The distance to
            a surface is |signed distance|, so points inside an object count too.

    Raises:
        ValueError: when there are no points or no surfaces, since the error is then undefined.
    """
    points = as_finite_array(points, "points", (None, 3))
    if len(points) == 0:
        raise ValueError("contact_error: no tracked points (the contact error is undefined)")
    if len(surfaces) == 0:
        raise ValueError("contact_error: no object surfaces given")
    distances = np.stack([np.abs(np.asarray(s(points), dtype=np.float64)) for s in surfaces])
    return float(distances.min(axis=0).mean())


def fowlkes_mallows(labels_true, labels_pred) -> float:
    """Fowlkes-Mallows index of two labelings of the same points, in [0, 1].

    FMI = TP / sqrt((TP + FP)(TP + FN)) over pairs of points: TP pairs share a cluster in both
    labelings. As in scikit-learn (which the paper used), the index is 0 when no pair shares a
    cluster in both, including when every point is a singleton in both.
    """
    labels_true = np.asarray(labels_true)
    labels_pred = np.asarray(labels_pred)
    if labels_true.shape != labels_pred.shape or labels_true.ndim != 1:
        raise ValueError(
            f"fowlkes_mallows: labelings must be 1-D of equal length, got {labels_true.shape} "
            f"and {labels_pred.shape}"
        )
    if labels_true.size == 0:
        raise ValueError("fowlkes_mallows: empty labelings")
    _, true_index = np.unique(labels_true, return_inverse=True)
    _, pred_index = np.unique(labels_pred, return_inverse=True)
    contingency = np.zeros((true_index.max() + 1, pred_index.max() + 1), dtype=np.int64)
    np.add.at(contingency, (true_index, pred_index), 1)

    def pairs(counts):
        counts = counts.astype(np.float64)
        return float(np.sum(counts * (counts - 1) / 2))

    together_both = pairs(contingency)
    together_pred = pairs(contingency.sum(axis=0))
    together_true = pairs(contingency.sum(axis=1))
    if together_both == 0.0:
        return 0.0
    return float(together_both / np.sqrt(together_pred * together_true))


#: Distance (m) from the robot to the second-closest object at which ambiguity reaches 0.
AMBIGUITY_DISTANCE = 0.15


def ambiguity(robot_object_distances, in_contact) -> float:
    """The paper's ambiguity score of a run, in [0, 1].

    Per step, with d2 the robot's distance to the second-closest of the objects it touched
    during the run, ambiguity = max(0, 0.15 - d2) / 0.15 (1 when two objects touch the robot, 0
    from 0.15 m on). The run's score is the mean over the steps in contact; 0 when fewer than
    two objects were touched or no step was in contact.

    Args:
        robot_object_distances: (T, k) distance (m) from the robot to each object the run
            touched, per step.
        in_contact: (T,) bool, steps in contact.
    """
    distances = as_finite_array(robot_object_distances, "robot_object_distances", (None, None))
    in_contact = np.asarray(in_contact, dtype=bool)
    if in_contact.shape != (len(distances),):
        raise ValueError(f"in_contact: expected shape ({len(distances)},), got {in_contact.shape}")
    if distances.shape[1] < 2 or not in_contact.any():
        return 0.0
    second = np.sort(distances, axis=1)[:, 1]
    per_step = np.maximum(0.0, AMBIGUITY_DISTANCE - second) / AMBIGUITY_DISTANCE
    return float(per_step[in_contact].mean())
