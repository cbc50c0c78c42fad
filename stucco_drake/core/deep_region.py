"""Where the robot is deep enough that a (config, point) pair can penetrate beyond a tolerance.

Screens for the in-contact penetration check (:mod:`stucco_drake.core.state_pairs`): a ball in
the end-effector frame E around the deep nodes, and each grid cell's smallest corner value.
Both are exact for the trilinear interpolant (which lies between its cell's corner values), so
no pair that penetrates is screened out, whatever the grid's values. For configs whose frame
keeps E's z axis along the world's (a planar gripper turned about the vertical, up to a small
tilt) a tighter screen needs no rotation at all: per layer of cells along z, the farthest any
deep cell reaches from E's z axis, against the pair's horizontal offset, which turning about z
leaves unchanged (:func:`within_layer_reach`).
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
        layer_reach2: (n_layers + 4,) float32: entry L + 2, for the layer L of cells along z
            (L = -1 .. n_layers, one beyond the grid either way), is the largest squared
            distance (m^2) from E's z axis of any point of a deep cell in layers L - 1 .. L + 1;
            -1 where there is none and at both ends (layers -2 and n_layers + 1 stand for
            everything beyond).
        extent: the farthest any point of the grid lies from E's origin (m).
    """

    center: np.ndarray
    radius: float
    cell_minimum: np.ndarray
    grown_minimum: np.ndarray
    level: float
    layer_reach2: np.ndarray
    extent: float


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
    layer_reach2 = _layer_reach2(grid, corners < level)
    return DeepRegion(center, reach + (math.sqrt(3.0) + 1.0) * grid.resolution,
                      cell_minimum.ravel(), grown_minimum.ravel(), level, layer_reach2,
                      _extent(grid))  # fmt: skip


def _extent(grid: GridSdf) -> float:
    upper = grid.lower + (np.array(grid.values.shape) - 1) * grid.resolution
    return float(np.linalg.norm(np.maximum(np.abs(grid.lower), np.abs(upper))))


def _layer_reach2(grid: GridSdf, deep_cells: np.ndarray) -> np.ndarray:
    """Squared reach from E's z axis per layer of cells, grown by one layer each way and
    padded (see :class:`DeepRegion`); each cell reaches as far as its farthest corner."""
    h = grid.resolution
    x = grid.lower[0] + h * np.arange(deep_cells.shape[0] + 1)
    y = grid.lower[1] + h * np.arange(deep_cells.shape[1] + 1)
    corner_x2 = np.maximum(x[:-1] ** 2, x[1:] ** 2)
    corner_y2 = np.maximum(y[:-1] ** 2, y[1:] ** 2)
    cell_reach2 = corner_x2[:, None] + corner_y2[None, :]
    per_layer = np.where(deep_cells, cell_reach2[:, :, None], -1.0).max(axis=(0, 1))
    padded = np.pad(per_layer, 2, constant_values=-1.0)
    grown = np.pad(np.maximum.reduce([padded[:-2], padded[1:-1], padded[2:]]), 1,
                   constant_values=-1.0)  # fmt: skip
    # float32, rounded up: the screen must not be tighter than the float64 bound.
    return np.where(grown < 0, -1.0, grown * (1 + 1e-6)).astype(np.float32)


def axial_slack2(rotations: np.ndarray, region: DeepRegion, resolution: float):
    """Per orientation slot: whether :func:`within_layer_reach` may screen its configs, and the
    squared slack (m^2) it must add. A tilt t = |R e_z - e_z| moves a point's E-frame z by at
    most t * extent (allowed while under half a cell: the grown layers cover it) and its
    squared horizontal distance by at most 2 * extent * dev + dev^2; 1e-7 m^2 covers float32
    rounding of the offsets and the rotations (about 1e-8 m at 0.1 m)."""
    rotations = np.asarray(rotations, dtype=np.float64)
    tilt = np.linalg.norm(rotations[:, :, 2] - np.array([0.0, 0.0, 1.0]), axis=1)
    deviation = tilt * region.extent
    usable = deviation < 0.5 * resolution
    slack2 = 2.0 * region.extent * deviation + deviation**2 + 1e-7
    return usable, slack2.astype(np.float32)


def within_layer_reach(grid: GridSdf, region: DeepRegion, offset, slack2) -> np.ndarray:
    """Which world offsets (3, k) float32 (point minus config, m) of configs turned about the
    vertical (:func:`axial_slack2`'s ``usable``) could lie in a deep cell: their squared
    horizontal distance within their z layer's reach plus ``slack2`` (k,)."""
    layer = np.floor(offset[2] * np.float32(1.0 / grid.resolution)
                     - np.float32(grid.lower[2] / grid.resolution))  # fmt: skip
    n_layers = grid.values.shape[2] - 1
    reach2 = region.layer_reach2[np.clip(layer, -2, n_layers + 1).astype(np.int64) + 2]
    return offset[0] ** 2 + offset[1] ** 2 <= reach2 + slack2


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
