"""(config, point) pairs on integer grid cells: the culls before any grid lookup.

A pair's quantised grid coordinate is its point's rounded cell minus its config's rounded cell
(cells of the robot's grid, along the axes of frame E, points offset by the lower node of the
crop box of :class:`~stucco_drake.core.penetration.RobotPenetration`). Only pairs whose
quantised coordinate falls inside that box can penetrate deep enough to count. The tests here
run on integers (one subtraction and one unsigned comparison per axis per pair), so that only
the few pairs left are looked up in the grid.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from stucco_drake.core.sdf import GridSdf

#: Integer grid coordinates use int16 while every coordinate stays within this many cells.
_INT16_LIMIT = 16000
#: Stand-in coordinate of a skipped config: every difference with it falls outside the grid.
_SKIP = 16383


def quantise(coordinates, resolution: float, offset, skip_nan: bool):
    """Round (3, ...) positions (m) to grid cells of ``resolution`` (m), minus ``offset``
    cells per axis. With ``skip_nan``, NaN entries (skipped configs) get a cell so far away
    that every pair with it falls outside the grid."""
    scaled = coordinates / np.float32(resolution) - offset.reshape(
        3, *([1] * (coordinates.ndim - 1))
    )
    nan = np.isnan(scaled) if skip_nan else None
    if nan is not None and nan.any():
        scaled = np.where(nan, _SKIP, scaled)
    return np.rint(scaled)


def candidate_pairs(point_cells, config_cells, extent):
    """(config, point) index pairs that fall in the crop box in at least one particle.

    A contact's point and config take a few distinct positions across particles, so the
    box test on their ranges over all particles (n_configs x n_points work) discards most
    pairs before the per-particle test (n_particles x pairs work). Conservative: a pair
    kept here may still be culled per particle. Skipped configs have huge coordinates, so a
    config skipped in every particle never passes.
    """
    possible = None
    for axis in range(3):
        points = point_cells[axis].astype(np.int32)
        configs = config_cells[axis].astype(np.int32)
        # Some particle has 0 <= point - config < extent only if the ranges allow it.
        upper = points.max(axis=0)[None, :] - configs.min(axis=0)[:, None] >= 0
        lower = points.min(axis=0)[None, :] - configs.max(axis=0)[:, None] < extent[axis]
        axis_possible = upper & lower
        possible = axis_possible if possible is None else possible & axis_possible
    config_index, point_index = np.nonzero(possible)
    return config_index, point_index


@dataclass(frozen=True)
class CellPairs:
    """One orientation's candidate (config, point) pairs, on integer grid cells.

    Attributes:
        point_cells: (3, n_particles, n_points) points' cells, less the crop box's lower node
            (int16 when every coordinate fits, else int32).
        config_cells: (3, n_particles or 1, n_configs) configs' cells, same type.
        config_of_pair, point_of_pair: (n_pairs,) the pairs some particle may hold in the box.
        extent: (3,) the crop box's size in cells.
        unsigned: the unsigned type of the cells' width.
        point_nodes, config_nodes: flat crop index of each point's and config's cell (int64):
            a pair's node is the point's minus the config's.
    """

    point_cells: np.ndarray
    config_cells: np.ndarray
    config_of_pair: np.ndarray
    point_of_pair: np.ndarray
    extent: np.ndarray
    unsigned: type
    point_nodes: np.ndarray
    config_nodes: np.ndarray

    @classmethod
    def build(cls, points_e, configs_e, grid: GridSdf, crop_lo, extent) -> CellPairs | None:
        """The pairs of ``points_e`` (3, n_particles, n_points) and ``configs_e``
        (3, n_particles or 1, n_configs) (m, along E's axes; NaN configs skipped) that may fall
        in the crop box of ``extent`` cells from node ``crop_lo``; None when none may."""
        origin_cells = grid.lower / grid.resolution
        point_cells = quantise(points_e, grid.resolution, origin_cells + crop_lo, skip_nan=False)
        config_cells = quantise(configs_e, grid.resolution, np.zeros(3), skip_nan=True)
        small = max(np.abs(point_cells).max(), np.abs(config_cells).max()) <= _INT16_LIMIT
        itype, utype = (np.int16, np.uint16) if small else (np.int32, np.uint32)
        if not small:
            config_cells = np.where(config_cells == _SKIP, 1 << 30, config_cells)
        point_cells = point_cells.astype(itype)
        config_cells = config_cells.astype(itype)
        config_of_pair, point_of_pair = candidate_pairs(point_cells, config_cells, extent)
        if config_of_pair.size == 0:
            return None
        # Flat crop index of a pair = point's flat index - config's (both in cells): two
        # gathers per surviving pair instead of six. Skipped configs only reach culled pairs.
        strides = np.array([extent[1] * extent[2], extent[2], 1])
        point_nodes = np.tensordot(strides, point_cells.astype(np.int64), axes=1)
        config_nodes = np.tensordot(strides, config_cells.astype(np.int64), axes=1)
        return cls(point_cells, config_cells, config_of_pair, point_of_pair, extent, utype,
                   point_nodes, config_nodes)  # fmt: skip

    @property
    def size(self) -> int:
        """Number of candidate pairs."""
        return self.config_of_pair.size

    @property
    def shared_configs(self) -> bool:
        """Whether all particles hold the same configs (one row of them)."""
        return self.config_cells.shape[1] == 1

    def inside_crop(self, start: int, stop: int, scratch, gathered, mask, axis_mask):
        """Flat indices ``particle * size + pair`` (particles counted from ``start``) of the
        pairs of particles ``start:stop`` inside the crop box; ``scratch`` and ``gathered``
        (cell type) and ``mask``, ``axis_mask`` (bool) are work arrays of at least
        ``(stop - start) * size`` entries (``gathered`` twice that)."""
        n_pairs = self.size
        size = (stop - start) * n_pairs
        config_rows = slice(0, 1) if self.shared_configs else slice(start, stop)
        n_config_rows = 1 if self.shared_configs else stop - start
        cells, inside, axis_inside = (b[:size].reshape(-1, n_pairs)
                                      for b in (scratch, mask, axis_mask))  # fmt: skip
        point_side = gathered[:size].reshape(-1, n_pairs)
        config_side = gathered[size : size + n_config_rows * n_pairs].reshape(-1, n_pairs)
        for axis in range(3):
            np.take(self.point_cells[axis, start:stop], self.point_of_pair, axis=1,
                    out=point_side)  # fmt: skip
            np.take(self.config_cells[axis, config_rows], self.config_of_pair, axis=1,
                    out=config_side)  # fmt: skip
            np.subtract(point_side, config_side, out=cells)
            # Negative differences wrap to large unsigned values: one test for 0 <= g < n.
            np.less(cells.view(self.unsigned), self.extent[axis],
                    out=inside if axis == 0 else axis_inside)  # fmt: skip
            if axis:
                np.logical_and(inside, axis_inside, out=inside)
        return np.flatnonzero(inside)
