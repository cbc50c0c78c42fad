"""Where to grasp a target whose pose is known only as weighted hypotheses.

A top-down parallel grasp is a planar pose (x, y, closing yaw) of the gripper frame G: its
origin between the fingers, its x axis the closing axis. Whether it closes on the target at a
given pose is the paper's criterion (RA-L 2022 Sec. V-C: "closed on the two long sides of the
box and not on a corner, or around more than half of the tomato can"), made precise in
:func:`grasp_closes`. Over weighted hypotheses of the target's pose, a grasp's probability of
closing on the target is the weight of the hypotheses under which it does; :func:`choose_grasp`
takes the candidate with the most. Pure numpy; world frame W, metres and radians.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from stucco_drake.core.icp import rotations
from stucco_drake.core.shapes import BoxSdf, CylinderSdf
from stucco_drake.core.validation import as_finite_array

#: Half width (m) of a bubble's contact pad across the closing axis (the membrane is 0.08 wide).
PAD_HALF_WIDTH = 0.04
#: Box criterion: max angle (rad) between the closing axis and the box's short axis, and min
#: distance (m) from a pad's centre line to a vertical edge of the long face.
MAX_AXIS_ERROR, EDGE_MARGIN = math.radians(15.0), 0.02


@dataclasses.dataclass(frozen=True)
class GraspChoice:
    """The grasp chosen across hypotheses.

    Attributes:
        target_pose: (3,) the target pose (x, y, yaw) the grasp is made at (the grasp closes
            across its short side, :func:`grasp_at`); a hypothesis or a weighted mean of some.
        grasp: (3,) the gripper's (x, y, closing yaw).
        probability: weight of the hypotheses under which the grasp closes on the target.
    """

    target_pose: np.ndarray
    grasp: np.ndarray
    probability: float


def grasp_at(poses, shape: BoxSdf | CylinderSdf, closing_yaw: float = 0.0) -> np.ndarray:
    """(B, 3) the grasp (x, y, closing yaw) at target poses (B, 3) (x, y, yaw): over the
    shape's centre, closing across a box's short horizontal side; a cylinder along
    ``closing_yaw`` (rad, world)."""
    poses = np.asarray(poses, dtype=np.float64).reshape(-1, 3)
    centre = np.asarray(shape.center, dtype=np.float64)[:2]
    xy = poses[:, :2] + np.einsum("bij,j->bi", rotations(poses[:, 2]), centre)
    if isinstance(shape, BoxSdf):
        hx, hy, _ = shape.half_extents
        yaw = poses[:, 2] + (0.0 if hx <= hy else np.pi / 2)
    elif isinstance(shape, CylinderSdf):
        yaw = np.full(len(poses), float(closing_yaw))
    else:
        raise TypeError(f"unsupported target shape {type(shape).__name__}")
    return np.column_stack([xy, yaw])


def grasp_closes(grasps, poses, shape: BoxSdf | CylinderSdf, margin: float = 0.0,
                 angle_margin: float = 0.0) -> np.ndarray:  # fmt: skip
    """(G, H) whether each grasp (G, 3) closes on the target at each pose (H, 3).

    ``margin`` (m) and ``angle_margin`` (rad) tighten every bound below by that much (0: the
    paper's criterion), so that a grasp passing them still closes on a target up to about
    that far from the pose.

    With p the grasp centre in the target frame O and u the closing axis there:

    * Box (half extents a <= b across/along its long faces, centre c): the angle between u and
      the short axis is at most :data:`MAX_AXIS_ERROR`, |p_short - c_short| < a, and the pads'
      centre line meets the long faces :data:`EDGE_MARGIN` inside their vertical edges:
      |p_long - c_long| + a tan(angle) <= b - EDGE_MARGIN.
    * Cylinder (radius r): with d the distance of its axis from the closing line and s its
      coordinate along it, the pads (2 :data:`PAD_HALF_WIDTH` wide) cover more than half of
      the diameter across the closing axis, |[d - w, d + w] & [-r, r]| > r, and |s| < r.
    """
    p, u = _in_target_frame(grasps, poses)
    centre = np.asarray(shape.center, dtype=np.float64)[:2]
    p = p - centre
    if isinstance(shape, BoxSdf):
        hx, hy, _ = shape.half_extents
        short, long_ = (0, 1) if hx <= hy else (1, 0)
        a, b = sorted((hx, hy))
        angle = np.arccos(np.minimum(1.0, np.abs(u[..., short])))
        reach = np.abs(p[..., long_]) + a * np.tan(angle)
        return ((angle <= MAX_AXIS_ERROR - angle_margin) & (np.abs(p[..., short]) < a - margin)
                & (reach <= b - EDGE_MARGIN - margin))  # fmt: skip
    if isinstance(shape, CylinderSdf):
        r, w = shape.radius, PAD_HALF_WIDTH
        axis = -p  # the can's axis relative to the grasp centre
        s = np.sum(axis * u, axis=-1)
        d = np.abs(axis[..., 0] * u[..., 1] - axis[..., 1] * u[..., 0])
        covered = np.maximum(0.0, np.minimum(d + w, r) - np.maximum(d - w, -r))
        return (covered > r + margin) & (np.abs(s) < r - margin)
    raise TypeError(f"unsupported target shape {type(shape).__name__}")


def _in_target_frame(grasps, poses) -> tuple[np.ndarray, np.ndarray]:
    """(G, H, 2) grasp centres and (G, H, 2) closing axes in each target pose's frame."""
    grasps = as_finite_array(np.asarray(grasps, dtype=np.float64).reshape(-1, 3), "grasps",
                             (None, 3))  # fmt: skip
    poses = as_finite_array(np.asarray(poses, dtype=np.float64).reshape(-1, 3), "poses",
                            (None, 3))  # fmt: skip
    R_OW = np.swapaxes(rotations(poses[:, 2]), -1, -2)  # (H, 2, 2)
    offset = grasps[:, None, :2] - poses[None, :, :2]  # (G, H, 2)
    p = np.einsum("hij,ghj->ghi", R_OW, offset)
    relative = grasps[:, None, 2] - poses[None, :, 2]
    return p, np.stack([np.cos(relative), np.sin(relative)], axis=-1)


def _weighted_mean_pose(poses, weights, shape) -> np.ndarray:
    """(3,) the weighted mean of target poses: positions averaged, yaws on the circle of the
    shape's symmetry (a centred box repeats after a half turn)."""
    period = np.pi if isinstance(shape, BoxSdf) and np.allclose(shape.center[:2], 0.0) \
        else 2.0 * np.pi
    k = 2.0 * np.pi / period
    w = weights / weights.sum()
    xy = w @ poses[:, :2]
    # Yaws averaged as unit vectors of k x yaw, so a box at yaw and yaw + pi counts as one.
    yaw = np.angle(w @ np.exp(1j * k * poses[:, 2])) / k
    return np.array([xy[0], xy[1], yaw])


def choose_grasp(poses, weights, shape: BoxSdf | CylinderSdf, *, closing_yaw: float = 0.0,
                 tolerance: float = 0.01, margin: float = 0.0,
                 angle_margin: float = 0.0) -> GraspChoice:  # fmt: skip
    """The grasp most likely to close on the target over weighted pose hypotheses.

    Candidates are the grasp at each hypothesis (:func:`grasp_at`) and at two weighted means:
    of the hypotheses the best of those closes on, and of all (a mean can cover hypotheses on
    either side of it that no hypothesis's grasp covers together). Candidates within
    ``tolerance`` of the highest probability count as equal: the hypothesis first in
    ``poses`` (pass them likeliest first) wins, and a hypothesis wins over a mean, so the grasp
    stays at the likeliest pose unless another closes on materially more weight.

    Args:
        poses: (H, 3) target poses (x, y, yaw) in W.
        weights: (H,) their weights (normalised here).
        shape: the target's geometry in its frame O.
        closing_yaw: a cylinder's closing yaw (rad, world).
        tolerance: probability difference below which candidates count as equal.
        margin, angle_margin: a grasp counts as closing under a hypothesis only with this
            much to spare (m, rad; see :func:`grasp_closes`): a grasp on the edge of closing
            under two hypotheses closes under neither once the truth lies a little off both.
    """
    poses = as_finite_array(np.asarray(poses, dtype=np.float64).reshape(-1, 3), "poses",
                            (None, 3))  # fmt: skip
    weights = as_finite_array(weights, "weights", (len(poses),))
    if len(poses) == 0 or weights.sum() <= 0 or np.any(weights < 0):
        raise ValueError("choose_grasp: expected at least one pose and non-negative weights "
                         "with a positive sum")
    weights = weights / weights.sum()
    grasps = grasp_at(poses, shape, closing_yaw)
    closes = grasp_closes(grasps, poses, shape, margin, angle_margin)
    probability = np.round(closes.astype(np.float64) @ weights, 12)
    best = int(np.argmax(probability >= probability.max() - tolerance))
    choice = GraspChoice(poses[best], grasps[best], float(probability[best]))
    # Means can reach between hypotheses: of those the best grasp closes on, and of all.
    means = np.array([_weighted_mean_pose(poses[closes[best]], weights[closes[best]], shape),
                      _weighted_mean_pose(poses, weights, shape)])  # fmt: skip
    mean_grasps = grasp_at(means, shape, closing_yaw)
    mean_probability = np.round(
        grasp_closes(mean_grasps, poses, shape, margin, angle_margin) @ weights, 12)
    k = int(np.argmax(mean_probability))
    if mean_probability[k] > choice.probability + tolerance:
        choice = GraspChoice(means[k], mean_grasps[k], float(mean_probability[k]))
    return choice
