"""Where along the gripper's front a push met the target: evidence of where the target's face ends.

A push that senses contact stops on the first thing its front meets. A soft, flat-fronted
gripper pressed on a face wider than itself touches along its whole front, and the sensed
point lies near the front's middle; on a face narrower than the front, or near a corner, it
lies over the part of the front the target covers. So a pose hypothesis predicts, for each
contact point sensed by a straight push, where across the push the point should lie: the
middle of the target's cross-section cells nearest ahead of the gripper within its width.
Two poses that put the same points on their surface can differ here: a box touched on its
end face fits the points as well turned by 90° (its long face there, slid along it), but the
turned box fills the gripper's whole front where the end face covers only part of it.

Pure numpy. Planar points (x, y) in the world frame W (m).
"""

from __future__ import annotations

import numpy as np

from stucco_drake.core.icp import transform
from stucco_drake.core.probe_paths import gripper_footprint

#: Depth (m) of the band of cross-section cells nearest ahead of the gripper that count as
#: where it meets the target.
FRONT_BAND = 0.01
#: Most a point's contact location costs: three standard deviations.
LOCATION_CAP = 4.5
#: Shortest planar displacement (m) of an action for its contacts to count as met by a push.
MIN_PUSH = 0.005


def push_frames(positions, point_steps, points) -> tuple[np.ndarray, np.ndarray]:
    """(mask (n,), directions (n, 2)): which contact ``points`` (n, 3) were met by a push,
    and its unit direction (W): the point's action (``point_steps`` (n,)) moved the
    gripper at least :data:`MIN_PUSH` in the plane (``positions`` (k, 3): the end effector
    at each action's end) and the point lies ahead of where it stopped (a contact sensed
    while backing off lies behind: the push that met it was the action before)."""
    positions = np.asarray(positions, dtype=np.float64)[:, :2]
    steps = np.asarray(point_steps, dtype=np.int64)
    motion = positions[steps] - positions[np.maximum(steps - 1, 0)]
    length = np.linalg.norm(motion, axis=1)
    directions = motion / np.maximum(length, 1e-12)[:, None]
    ahead = np.einsum("ni,ni->n", np.asarray(points, dtype=np.float64)[:, :2]
                      - positions[steps], directions) > 0.0  # fmt: skip
    return (steps > 0) & (length >= MIN_PUSH) & ahead, directions


def lateral_offsets(poses, fill, points, grippers, directions, footprint) -> np.ndarray:
    """(B, n) how far across its push (m, along the push direction turned +90 degrees) each
    point lies from where the target at each pose would meet the gripper: the mean lateral
    position of the cross-section cells ``fill`` ((m, 2) in the target's frame O) posed at
    ``poses`` (B, 3) that lie ahead of the gripper at ``grippers`` (n, 2) within the lateral
    extent of its ``footprint`` ((f, 2) about its origin, W axes) and within
    :data:`FRONT_BAND` of the nearest; NaN where no cell lies ahead within that width."""
    poses = np.asarray(poses, dtype=np.float64).reshape(-1, 3)
    u = np.asarray(directions, dtype=np.float64)
    v = np.column_stack([-u[:, 1], u[:, 0]])
    lateral = np.asarray(footprint, dtype=np.float64) @ v.T  # (f, n)
    low, high = lateral.min(axis=0), lateral.max(axis=0)
    posed = transform(poses, fill)
    relative = posed[:, None, :, :] - np.asarray(grippers)[None, :, None, :2]  # (B, n, m, 2)
    along = np.einsum("bnmi,ni->bnm", relative, u)
    across = np.einsum("bnmi,ni->bnm", relative, v)
    ahead = (along > 0.0) & (across >= low[None, :, None]) & (across <= high[None, :, None])
    nearest = np.where(ahead, along, np.inf).min(axis=2, keepdims=True)
    band = ahead & (along <= nearest + FRONT_BAND)
    count = band.sum(axis=2)
    predicted = np.where(band, across, 0.0).sum(axis=2) / np.maximum(count, 1)
    sensed = np.einsum("ni,ni->n", np.asarray(points, dtype=np.float64)[:, :2]
                       - np.asarray(grippers)[:, :2], v)  # fmt: skip
    return np.where(count > 0, sensed[None, :] - predicted, np.nan)


def contact_location_costs(poses, explained, fill, points, grippers, directions, footprint,
                           noise: float, cap: float = LOCATION_CAP) -> np.ndarray:  # fmt: skip
    """(B,) the cost of each pose's predicted contact locations: over the points it explains
    (``explained`` (B, n)), the squared lateral offset (:func:`lateral_offsets`) per
    ``2 noise^2`` (m), each at most ``cap``; a point no cell of the pose lies ahead of costs
    ``cap`` (the gripper could not have met the pose there)."""
    poses = np.asarray(poses, dtype=np.float64).reshape(-1, 3)
    costs = np.zeros(len(poses))
    block = max(1, (1 << 19) // max(1, len(points) * len(fill)))  # bounded memory
    for k in range(0, len(poses), block):
        offsets = lateral_offsets(poses[k:k + block], fill, points, grippers, directions,
                                  footprint)  # fmt: skip
        each = np.minimum(np.nan_to_num(offsets, nan=np.inf) ** 2 / (2.0 * noise**2), cap)
        costs[k:k + block] = np.where(explained[k:k + block], each, 0.0).sum(axis=1)
    return costs


def location_costs_of(free, fill, points, carried, noise: float | None):
    """The function ``(poses, explained) -> (B,) costs`` of :func:`contact_location_costs`
    for the contact ``points`` (n, 3) the robot sensed at ``free``'s configs
    (:class:`~stucco_drake.core.free_space.FreeSpace`), each carried by ``carried``
    (n, 3; None: not at all) since (the gripper that met it is carried alike), the target's
    cross-section
    ``fill`` ((m, 2) in O); None when ``noise`` is None or no point was met by a push."""
    if noise is None or free is None or len(free.positions) == 0:
        return None
    points = np.asarray(points, dtype=np.float64)
    carried = np.zeros_like(points) if carried is None else np.asarray(carried)
    sensed = points - carried
    pushed, directions = push_frames(free.positions, free.point_steps, sensed)
    if not pushed.any():
        return None
    rotation = np.eye(3) if free.rotation is None else free.rotation
    footprint = gripper_footprint(free.penetration, rotation)
    steps = np.asarray(free.point_steps)[pushed]
    grippers = (np.asarray(free.positions)[steps] + carried[pushed])[:, :2]
    met = points[pushed]

    def costs(poses, explained):
        return contact_location_costs(poses, np.asarray(explained)[:, pushed], fill, met,
                                      grippers, directions[pushed], footprint, noise)

    return costs


__all__ = ["FRONT_BAND", "LOCATION_CAP", "MIN_PUSH", "contact_location_costs", "lateral_offsets",
           "location_costs_of", "push_frames"]
