"""Where the open fingers go down to grasp a box: beyond one of its ends, then slide along it.

A top-down grasp of a box puts each open finger beside one of its long faces. Clutter standing
there (a can flush against the face) is where the finger lands: the descent stops on the can's
top and the fingers close on nothing. Beyond the box's ends the table is often clear, and the
open fingers are wider than the box: they can go down beyond an end, straddling the box's long
axis, and slide along it to the grasp point, shoving aside what stands beside the long faces
(the box, heavier, stays between them). Which end: the one whose descent keeps the fingers
farthest from the points the robot felt on other objects; ends clear of them all by
``clearance``, the one nearer the gripper (it came from there, through space it swept). When
that descent, or the slide after it, is blocked, the straight one onto the grasp point comes
next, and the other end last: it lies on the side the robot has explored least (behind the
box, seen from where it rummaged; on the development layouts of every family a finger's spot
there is taken).

Clutter may stand beyond an end as well (a can shoved there while rummaging). With
``box_approach: end_aside`` an end's descent is shifted sideways, across the box's long axis,
to where the open fingers are farthest from the felt points; the slide then moves back in
line first, shoving aside what the shift kept the finger off (:func:`aside_shifts`).

Pure numpy; world frame, metres and radians.
"""

from __future__ import annotations

import numpy as np

from stucco_drake.core.grasp_choice import PAD_HALF_WIDTH
from stucco_drake.core.grasp_yaw import OPEN_FINGER_OFFSET, checked_obstacles
from stucco_drake.core.icp import rotations
from stucco_drake.core.validation import as_finite_array


def _long_axis(yaw: float, half_extents) -> tuple[np.ndarray, np.ndarray, float]:
    """(axis, across, half length): unit vectors (world) along the box's long horizontal axis
    and across it, and its half length (m)."""
    hx, hy = (float(h) for h in np.asarray(half_extents, dtype=np.float64)[:2])
    local = np.array([1.0, 0.0]) if hx > hy else np.array([0.0, 1.0])
    axis = rotations(np.array([yaw]))[0] @ local
    return axis, np.array([-axis[1], axis[0]]), max(hx, hy)


def _finger_room(descents, across, points, finger_offset: float, clearance: float) -> np.ndarray:
    """(k,) distance (m) from the nearer of the two open fingers' plate centres
    (``finger_offset`` either side along ``across``) at each of ``descents`` ((k, 2)) to the
    nearest of ``points`` ((n, 2), n >= 1), capped at ``clearance``."""
    fingers = descents[:, None, :] + finger_offset * np.array([across, -across])[None]
    distance = np.linalg.norm(fingers[:, :, None, :] - points[None, None], axis=-1)
    return np.minimum(distance.min(axis=(1, 2)), clearance)


def box_approach_offsets(pose, half_extents, obstacle_points, gripper_xy, *,
                         margin: float = 0.01, clearance: float = 0.08,
                         finger_offset: float = OPEN_FINGER_OFFSET) -> np.ndarray:  # fmt: skip
    """(3, 2) approach offsets (m, world) from the grasp point of a box, in the order to try:
    beyond one end, (0, 0) (straight down), beyond the other end.

    An end's offset runs along the box's long horizontal axis, a half length plus a pad's
    half width (:data:`~stucco_drake.core.grasp_choice.PAD_HALF_WIDTH`) plus ``margin`` from
    the grasp point (the box's centre), so the pads go down clear of the end. The ends are
    ordered by the distance from the nearer of the two open fingers' plate centres
    (``finger_offset`` either side across the long axis) at the descent point to the nearest
    obstacle point, farther first; when both exceed ``clearance`` (or there are no points),
    the end nearer ``gripper_xy`` first.

    Args:
        pose: (3,) the box's (x, y, yaw) (m, rad, world), its centre at (x, y).
        half_extents: the box's half sizes (hx, hy, ...) in its frame (m).
        obstacle_points: (n, 2 or 3) points felt on other objects (m, world; z ignored).
        gripper_xy: (2,) where the gripper is (m, world).
    """
    x, y, yaw = as_finite_array(pose, "pose", (3,))
    gripper = as_finite_array(gripper_xy, "gripper_xy", (2,))
    _, points = checked_obstacles((x, y), obstacle_points)
    axis, across, half_length = _long_axis(yaw, half_extents)
    ends = np.array([axis, -axis]) * (half_length + PAD_HALF_WIDTH + margin)
    descents = np.array([x, y]) + ends
    room = _finger_room(descents, across, points, finger_offset, clearance) if len(points) \
        else np.full(2, clearance)
    near = np.linalg.norm(descents - gripper, axis=1)
    order = np.lexsort((near, -room))
    return np.array([ends[order[0]], np.zeros(2), ends[order[1]]])


#: Sideways shifts (m) of an end's descent that :func:`aside_shifts` chooses among (and none).
SIDE_SHIFTS = (0.025, 0.05)


def aside_shifts(pose, half_extents, offsets, obstacle_points, *, shifts=SIDE_SHIFTS,
                 clearance: float = 0.08, finger_offset: float = OPEN_FINGER_OFFSET,
                 ) -> np.ndarray:  # fmt: skip
    """(k, 2) sideways shifts (m, world) of the descents at ``offsets`` ((k, 2), from
    :func:`box_approach_offsets`): across the box's long axis, by 0 or one of ``shifts``
    away from the obstacle point nearest the unshifted fingers (moving back in line, the
    finger then shoves what it was kept off outwards, never across the slide's path), the
    one keeping the two open fingers' plate centres farthest from ``obstacle_points`` (the
    distance capped at ``clearance``; on a tie the smallest shift). The straight descent,
    offset (0, 0), is not shifted. ``pose`` and ``half_extents`` as
    :func:`box_approach_offsets`'s."""
    x, y, yaw = as_finite_array(pose, "pose", (3,))
    offsets = np.asarray(offsets, dtype=np.float64).reshape(-1, 2)
    _, across, _ = _long_axis(yaw, half_extents)
    _, points = checked_obstacles((x, y), obstacle_points)
    chosen = np.zeros_like(offsets)
    if not len(points):
        return chosen
    fingers_at = finger_offset * np.array([across, -across])
    for i, offset in enumerate(offsets):
        if not np.any(offset):
            continue
        descent = np.array([x, y]) + offset
        gaps = np.linalg.norm(descent + fingers_at[:, None] - points[None], axis=-1)
        nearest = points[int(np.argmin(gaps.min(axis=0)))]
        away = -1.0 if (nearest - descent) @ across > 0 else 1.0
        candidates = np.array([0.0, *(away * abs(d) for d in shifts)])
        room = _finger_room(descent + candidates[:, None] * across, across, points,
                            finger_offset, clearance)  # fmt: skip
        best = np.lexsort((np.abs(candidates), -np.round(room, 9)))[0]
        chosen[i] = candidates[best] * across
    return chosen


__all__ = ["SIDE_SHIFTS", "aside_shifts", "box_approach_offsets"]
