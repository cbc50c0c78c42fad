"""Where the robot is deep enough that a (config, point) pair can penetrate beyond a tolerance.

Screens for the in-contact penetration check (:mod:`stucco_drake.core.state_pairs`): a ball in
the end-effector frame E around the deep nodes, and each grid cell's smallest corner value.
Both are exact for the trilinear interpolant (which lies between its cell's corner values), so
no pair that penetrates is screened out, whatever the grid's values.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from stucco_drake.core.sdf import GridSdf

#: Nodes this close above -tolerance (m) still count as deep: float32 interpolation rounding.
_DEPTH_SLACK = 1e-6


@dataclass(frozen=True)
class DeepRegion:
    """Where a (config, point) pair can penetrate the robot deeper than a tolerance.

    Attributes:
        center, radius: a ball in frame E (m) holding every such point relative to its config.
            The interpolant is below -tolerance only if a corner of the point's cell is, and
            every corner is within sqrt(3) cells of the point; one more cell covers rounding.
        cell_minimum: (nx * ny * nz,) float32, the smallest of each cell's 8 corner values,
            indexed by its lowest corner's flat node index (+inf on the grid's last layers).
        grown_minimum: the same over each cell and its 26 neighbours: a screen for coordinates
            known only to within a cell.
        level: a pair whose cell minimum is not below this cannot penetrate that deep.
    """

    center: np.ndarray
    radius: float
    cell_minimum: np.ndarray
    grown_minimum: np.ndarray
    level: float


def deep_region(grid: GridSdf, tolerance: float) -> DeepRegion | None:
    """:class:`DeepRegion` of ``grid`` at ``tolerance`` (m); None if nothing is that deep."""
    level = -tolerance + _DEPTH_SLACK
    deep = np.argwhere(grid.values < level)
    if len(deep) == 0:
        return None
    nodes = grid.lower + deep * grid.resolution
    center = 0.5 * (nodes.min(axis=0) + nodes.max(axis=0))
    reach = float(np.sqrt(((nodes - center) ** 2).sum(axis=1)).max())
    v = grid.values
    corners = np.minimum.reduce([v[i : v.shape[0] - 1 + i, j : v.shape[1] - 1 + j,
                                   k : v.shape[2] - 1 + k]
                                 for i in (0, 1) for j in (0, 1) for k in (0, 1)])  # fmt: skip
    padded = np.pad(corners, 1, constant_values=np.inf)
    nx, ny, nz = corners.shape
    grown = np.minimum.reduce([padded[i : nx + i, j : ny + j, k : nz + k]
                               for i in range(3) for j in range(3) for k in range(3)])  # fmt: skip
    cell_minimum = np.full(v.shape, np.inf, dtype=np.float32)
    grown_minimum = np.full(v.shape, np.inf, dtype=np.float32)
    cell_minimum[:-1, :-1, :-1] = corners
    grown_minimum[:-1, :-1, :-1] = grown
    return DeepRegion(center, reach + (math.sqrt(3.0) + 1.0) * grid.resolution,
                      cell_minimum.ravel(), grown_minimum.ravel(), level)  # fmt: skip


def could_penetrate(grid: GridSdf, region: DeepRegion, cells, within_a_cell=False):
    """Which grid coordinates ``cells`` (3 float32 arrays, cells from ``grid.lower``) lie in
    the grid, in a cell with a corner deeper than the region's level: the same cell as the
    interpolation uses, so exact (no Lipschitz assumption). ``within_a_cell``: the coordinates
    are off by less than a cell; the screen then grows the grid and each cell by one."""
    flat = np.zeros(cells[0].shape, dtype=np.int64)
    inside = np.ones(cells[0].shape, dtype=bool)
    strides = (grid.values.shape[1] * grid.values.shape[2], grid.values.shape[2], 1)
    grow = 1 if within_a_cell else 0
    for coordinate, stride, count in zip(cells, strides, grid.values.shape, strict=True):
        inside &= (coordinate >= -grow) & (coordinate <= count - 1 + grow)
        flat += np.clip(np.floor(coordinate), 0, count - 2).astype(np.int64) * stride
    minimum = region.grown_minimum if within_a_cell else region.cell_minimum
    return inside & (minimum[np.where(inside, flat, 0)] < region.level)
