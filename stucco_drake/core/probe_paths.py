"""Paths of the gripper's origin around a box in the plane: whether a straight move enters it,
and the shortest way round its corners, and the gripper's planar footprint (used by the
guarded probes, :mod:`~stucco_drake.core.probing`). Points (x, y) in the world frame W (m),
yaw about z (rad).
"""

from __future__ import annotations

import itertools

import numpy as np


def rotation_2d(yaw: float) -> np.ndarray:
    """(2, 2) the planar rotation by ``yaw`` (rad)."""
    c, s = np.cos(yaw), np.sin(yaw)
    return np.array([[c, -s], [s, c]])


def segment_enters_box(a, b, centre, half, yaw) -> bool:
    """Whether the segment a-b (W) passes through the interior of the box (centre, half
    extents, yaw), by clipping it against the box's slabs in the box's frame."""
    R = rotation_2d(yaw)
    p, d = R.T @ (np.asarray(a) - centre), R.T @ (np.asarray(b) - np.asarray(a))
    lo, hi = 0.0, 1.0
    for axis in range(2):
        if abs(d[axis]) < 1e-12:
            if abs(p[axis]) >= half[axis]:
                return False
            continue
        t1, t2 = (-half[axis] - p[axis]) / d[axis], (half[axis] - p[axis]) / d[axis]
        lo, hi = max(lo, min(t1, t2)), min(hi, max(t1, t2))
        if lo >= hi:
            return False
    return hi - lo > 1e-9


def travel_waypoints(start, goal, centre, half, yaw) -> list[np.ndarray]:
    """Waypoints (W) from ``start`` to ``goal`` that keep out of the box (centre, half extents,
    yaw): straight when the segment clears it, else around its corners the shorter way; from
    a start inside or on the box, out through its nearest side first."""
    start, goal = np.asarray(start, dtype=np.float64), np.asarray(goal, dtype=np.float64)
    if not segment_enters_box(start, goal, centre, half, yaw):
        return [goal]
    R = rotation_2d(yaw)
    local = R.T @ (start - centre)
    if np.all(np.abs(local) < half + 2e-3):
        # Inside or on the box (just backed off from it): out through the nearest side first.
        axis = int(np.argmin(half - np.abs(local)))
        local[axis] = np.copysign(half[axis] + 3e-3, local[axis])
        exit_point = centre + R @ local
        return [exit_point, *travel_waypoints(exit_point, goal, centre, half, yaw)]
    # Corners pushed 1 mm further out, so that paths along the edges clear the box.
    signs = np.array([[1, 1], [-1, 1], [-1, -1], [1, -1]], dtype=np.float64)  # counter-clockwise
    corners = centre + (signs * (half + 1e-3)) @ R.T
    best, best_length = [goal], np.inf
    for first in range(4):
        if segment_enters_box(start, corners[first], centre, half, yaw):
            continue
        for direction in (1, -1):
            path, k = [corners[first]], first
            for _ in range(4):
                if not segment_enters_box(path[-1], goal, centre, half, yaw):
                    break
                k = (k + direction) % 4
                path.append(corners[k])
            points = [start, *path, goal]
            length = sum(np.linalg.norm(q - p) for p, q in itertools.pairwise(points))
            if length < best_length:
                best, best_length = [*path, goal], length
    return best


def gripper_footprint(penetration, rotation_WE) -> np.ndarray:
    """(m, 2) the gripper's planar footprint about its origin in W axes (m): the cells inside
    the robot of a grid pxpen (``penetration.robot_sdf``, in the end-effector frame E),
    every height, turned by ``rotation_WE`` (3, 3)."""
    grid = penetration.robot_sdf
    inside = np.argwhere(np.asarray(grid.values) < 0)
    points_E = np.asarray(grid.lower) + inside * float(grid.resolution)
    xy = (points_E @ np.asarray(rotation_WE, dtype=np.float64).T)[:, :2]
    # The convex hull's extremes suffice for supports and radii; keep the outermost cells.
    return np.unique(np.round(xy, 4), axis=0)


__all__ = ["gripper_footprint", "rotation_2d", "segment_enters_box", "travel_waypoints"]
