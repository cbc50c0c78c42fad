"""A coverage sweep: the same raster of pushes across the workspace for every layout.

The non-adaptive baseline of a rummaging policy: it knows where the objects may be (a band of
the table in front of the gripper) but nothing of where they are. The band is cut into lanes
along world y, one gripper footprint wide so that they tile it without gaps; the gripper
pushes down every lane along +x and withdraws along it, lane after lane from the band's end
nearer its start. Nothing it senses changes the raster.

Planar points (x, y) in the world frame W (m).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable

import numpy as np


@dataclasses.dataclass(frozen=True)
class CoverageParams:
    """The raster of :func:`coverage_waypoints` (m).

    Attributes:
        depth: how far along +x from the gripper's start a lane is pushed (every lane starts
            and ends at the start's x, behind the objects, in free space).
        y_range: the band's extent along y (its lanes' centres lie within it).
        lane_width: distance between neighbouring lanes (None: the gripper footprint's width
            along y, so that the lanes tile the band).
        nearest_first: start at the lane nearest the gripper and sweep out to the nearer end
            of the band, then the rest of the band from the start outwards (objects in
            front of the start are met first); otherwise (the raster) start at the band's
            end nearer the gripper and sweep to the other end (the band is crossed once).
        from_start: lay the lanes out from the gripper's start (one lane straight ahead of
            it, the others ``lane_width`` apart, out to the first beyond each end of
            ``y_range``): where the user puts the gripper is where the search begins.
            Otherwise both ends of ``y_range`` are lanes and the lanes share the rest evenly.
    """

    depth: float = 0.38
    # The extent of the prescribed scripts' gripper paths over the four paper scenes.
    y_range: tuple[float, float] = (-0.17, 0.28)
    lane_width: float | None = None
    nearest_first: bool = False
    from_start: bool = True


def lane_centres(params: CoverageParams, footprint_width: float,
                 start_y: float = 0.0) -> np.ndarray:  # fmt: skip
    """The lanes' y (m), in increasing order, at most ``lane_width`` (or ``footprint_width``)
    apart across ``y_range``: from ``start_y`` (``from_start``), else both ends included."""
    width = params.lane_width or float(footprint_width)
    if width <= 0:
        raise ValueError(f"coverage lane width must be positive, got {width}")
    lo, hi = params.y_range
    if params.from_start:
        first = int(np.floor((lo - start_y) / width + 1e-9))
        last = int(np.ceil((hi - start_y) / width - 1e-9))
        return start_y + width * np.arange(first, last + 1)
    count = int(np.ceil((hi - lo) / width - 1e-9)) + 1
    return np.linspace(lo, hi, max(count, 1))


def coverage_waypoints(start_xy, params: CoverageParams, footprint_width: float,
                       in_workspace: Callable[[np.ndarray], bool] | None = None,
                       back: float = 0.0) -> np.ndarray:  # fmt: skip
    """(M, 2) the sweep's waypoints (W): lane by lane in the order ``nearest_first`` says,
    each (x0 - back, y), (x0 + depth, y), (x0 - back, y), x0 the start's x. With
    ``in_workspace``, a lane whose far end lies outside is pushed less deep and one whose
    end lies outside is moved less far back (both in 5 mm steps); a lane whose point at x0
    lies outside is left out."""
    inside = in_workspace or (lambda xy: True)
    x0, start_y = (float(v) for v in np.asarray(start_xy, dtype=np.float64)[:2])
    lanes = lane_centres(params, footprint_width, start_y)
    if lanes[-1] - start_y < start_y - lanes[0]:
        lanes = lanes[::-1]
    if params.nearest_first:
        nearest = int(np.argmin(np.abs(lanes - start_y)))
        lanes = np.concatenate([lanes[nearest::-1], lanes[nearest + 1:]])
    points = []
    for y in lanes:
        depth = params.depth
        while depth > 0 and not inside(np.array([x0 + depth, y])):
            depth -= 0.005
        if depth > 0 and inside(np.array([x0, y])):
            end = x0 - back
            while end < x0 and not inside(np.array([end, y])):
                end = min(end + 0.005, x0)
            points += [(end, y), (x0 + depth, y), (end, y)]
    return np.asarray(points, dtype=np.float64)


def waypoint_steps(start_xy, waypoints, max_step: float) -> np.ndarray:
    """(N, 2) planar steps (m, W) that take the gripper from ``start_xy`` through
    ``waypoints``, each at most ``max_step`` per axis (the controller's clip): every leg cut
    into equal steps, as few as the clip allows."""
    position = np.asarray(start_xy, dtype=np.float64).copy()
    steps = []
    for point in np.asarray(waypoints, dtype=np.float64).reshape(-1, 2):
        leg = point - position
        count = int(np.ceil(np.max(np.abs(leg)) / max_step - 1e-9))
        if count > 0:  # a waypoint where the gripper already is takes no step
            steps += [leg / count] * count
        position = point
    return np.asarray(steps, dtype=np.float64).reshape(-1, 2)
