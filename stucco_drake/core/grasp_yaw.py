"""Which way to close the fingers around a round target: away from the clutter the robot felt.

A cylinder can be grasped at any yaw, but the open fingers stand out about 9 cm on either side
of it, where other objects often are. The robot knows where it touched other objects (its
tracked contact points outside the target's segment), so it closes along the yaw that keeps
both fingers farthest from those points. Pure numpy; world frame, metres and radians.
"""

from __future__ import annotations

import numpy as np

from stucco_drake.core.validation import as_finite_array

#: Distance (m) from the gripper frame to each open finger's plate centre along the closing
#: axis: finger opening 0.055 + bubble thickness 0.02 + half the plate 0.0125.
OPEN_FINGER_OFFSET = 0.0875


def cylinder_grasp_yaw(
    centre_xy,
    obstacle_points,
    current_yaw: float,
    *,
    finger_offset: float = OPEN_FINGER_OFFSET,
    clearance: float = 0.08,
    n_yaws: int = 12,
) -> float:
    """The closing yaw (rad, world) for a top-down grasp of a cylinder centred at ``centre_xy``.

    Candidates are ``current_yaw + k pi / n_yaws`` (a closing axis and its reverse are the same
    grasp). Each is scored by the distance from the nearer of its two finger centres
    (``finger_offset`` m either side along the axis) to the nearest obstacle point (x, y). The
    current yaw is kept when it already clears them by ``clearance`` (m) or there are none;
    otherwise the candidate with the largest score wins (ties: the first in the order above).

    Args:
        centre_xy: (2,) the target's centre (m, world).
        obstacle_points: (n, 2 or 3) points on other objects (m, world; z ignored).
        current_yaw: the gripper's yaw now (rad).
    """
    centre, points = checked_obstacles(centre_xy, obstacle_points)
    if len(points) == 0:
        return float(current_yaw)
    yaws = float(current_yaw) + np.pi * np.arange(n_yaws) / n_yaws
    score = _clearance(centre, points, yaws, finger_offset)
    if score[0] >= clearance:
        return float(current_yaw)
    return float(yaws[int(np.argmax(score))])


def cylinder_grasp_yaws(
    centre_xy,
    obstacle_points,
    current_yaw: float,
    *,
    n_axes: int = 3,
    finger_offset: float = OPEN_FINGER_OFFSET,
    **kwargs,
) -> np.ndarray:
    """Closing yaws (rad, world) to try in turn on a cylinder, when a descent is blocked.

    The first is :func:`cylinder_grasp_yaw`'s (``kwargs`` go to it); the other ``n_axes - 1``
    closing axes are spaced ``pi / n_axes`` from it, the one whose fingers are farther from
    the obstacle points first (ties: counter-clockwise first). Untouched clutter is not among
    the points, so a finger can still land on it; the grasp then tries the next axis.
    """
    first = cylinder_grasp_yaw(centre_xy, obstacle_points, current_yaw,
                               finger_offset=finger_offset, **kwargs)  # fmt: skip
    others = first + np.pi * np.arange(1, n_axes) / n_axes
    centre, points = checked_obstacles(centre_xy, obstacle_points)
    if len(points):
        others = others[np.argsort(-_clearance(centre, points, others, finger_offset),
                                   kind="stable")]  # fmt: skip
    return np.concatenate([[first], others])


def checked_obstacles(centre_xy, obstacle_points) -> tuple[np.ndarray, np.ndarray]:
    """(centre (2,), obstacle points (n, 2)) checked finite, z dropped (m, world)."""
    centre = as_finite_array(centre_xy, "centre_xy", (2,))
    points = np.asarray(obstacle_points, dtype=np.float64)
    if points.size == 0:
        return centre, np.zeros((0, 2))
    points = as_finite_array(points.reshape(len(points), -1)[:, :2], "obstacle_points", (None, 2))
    return centre, points


def _clearance(centre, points, yaws, finger_offset: float) -> np.ndarray:
    """Per yaw, the distance (m) from the nearer open finger's centre to the nearest point."""
    axes = np.stack([np.cos(yaws), np.sin(yaws)], axis=1)
    fingers = centre + finger_offset * np.stack([axes, -axes], axis=1)  # (n_yaws, 2, 2)
    distance = np.linalg.norm(fingers[:, :, None, :] - points[None, None], axis=-1)
    return distance.min(axis=(1, 2))
