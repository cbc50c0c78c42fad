"""Tracking metrics of the paper (contact error, Fowlkes-Mallows index, ambiguity) and the
error of a target pose estimate."""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

from stucco_drake.core.shapes import BoxSdf, CylinderSdf
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


def target_pose_error(estimate, truth, shape: BoxSdf | CylinderSdf) -> tuple[float, float]:
    """(position error in m, yaw error in rad) of an estimated planar pose of a target.

    Args:
        estimate, truth: (x, y, yaw) of the target's frame in the world (m, m, rad).
        shape: the target's shape in its frame, upright (its axis along z).

    The position error is the horizontal distance between the shape's centres placed at the
    two poses (the centre, not the frame origin, is what a turn by a symmetry leaves in
    place). The yaw error is the smallest turn about that centre that takes one pose's shape
    onto the other's: modulo pi for a box (pi/2 for a square one); NaN for a cylinder, which
    looks the same at any yaw.
    """
    estimate = as_finite_array(estimate, "estimate", (3,))
    truth = as_finite_array(truth, "truth", (3,))
    centre = np.asarray(shape.center, dtype=np.float64)[:2]

    def centre_in_world(pose: np.ndarray) -> np.ndarray:
        c, s = np.cos(pose[2]), np.sin(pose[2])
        return pose[:2] + np.array([[c, -s], [s, c]]) @ centre

    distance = float(np.linalg.norm(centre_in_world(estimate) - centre_in_world(truth)))
    if isinstance(shape, CylinderSdf):
        return distance, float("nan")
    hx, hy, _ = shape.half_extents
    period = np.pi / 2 if hx == hy else np.pi
    turn = (estimate[2] - truth[2]) % period
    return distance, float(min(turn, period - turn))


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


def paired_median_gap(values, reference, rng: np.random.Generator,
                      n_boot: int = 2000) -> dict:  # fmt: skip
    """How much larger the median of ``values`` is than that of ``reference``, paired by trial.

    ``values[i]`` and ``reference[i]`` are two settings' results on trial i (e.g. CE in cm);
    trials where either is not finite are dropped. The gap is median(values) -
    median(reference); its 95 % interval is the percentile interval of that gap over
    ``n_boot`` resamples of the trials (with replacement, the same trials for both, drawn
    from ``rng``). Returns ``gap``, ``low``, ``high``, ``n`` (paired trials) and ``n_lower``
    (trials on which ``values`` is lower). An interval that holds 0 means the trials do not
    tell the two medians apart.
    """
    a = np.asarray(values, dtype=np.float64).ravel()
    b = np.asarray(reference, dtype=np.float64).ravel()
    if a.shape != b.shape:
        raise ValueError(f"paired_median_gap: {a.size} values against {b.size} references")
    keep = np.isfinite(a) & np.isfinite(b)
    a, b = a[keep], b[keep]
    if a.size == 0:
        raise ValueError("paired_median_gap: no trial with both values finite")
    draws = rng.integers(0, a.size, size=(n_boot, a.size))
    gaps = np.median(a[draws], axis=1) - np.median(b[draws], axis=1)
    low, high = np.percentile(gaps, [2.5, 97.5])
    return {"gap": float(np.median(a) - np.median(b)), "low": float(low), "high": float(high),
            "n": int(a.size), "n_lower": int(np.count_nonzero(a < b))}
