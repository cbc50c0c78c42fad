"""pxpen: how deep points lie inside the robot at given end-effector poses, batched and culled."""

from __future__ import annotations

import math

import numpy as np

from stucco_drake.core.cell_pairs import CellPairs, candidate_pairs, quantise
from stucco_drake.core.deep_region import deep_region
from stucco_drake.core.sdf import GridSdf
from stucco_drake.core.state_pairs import ordered_sums, penetrating_entries


def _in_frame(rotation: np.ndarray, array: np.ndarray) -> np.ndarray:
    """Coordinates of world vectors ``array[3, ...]`` (float32) along the axes of ``rotation``."""
    if np.array_equal(rotation, np.eye(3)):
        return array
    return np.tensordot(rotation.T.astype(np.float32), array, axes=1)


def per_orientation_sums(excess_sums, points, configs, rotation_index, rotations, tolerance):
    """All-pairs excess sums (see ``RobotPenetration.all_pairs_excess_sums``) by one
    ``excess_sums(points_e, configs_e, tolerance)`` pass per orientation slot, each over only
    the configs held at that slot (the others NaN, skipped)."""
    if len(rotations) == 1:
        return excess_sums(_in_frame(rotations[0], points),
                           _in_frame(rotations[0], configs), tolerance)  # fmt: skip
    per_particle = np.zeros(points.shape[1])
    per_point = np.zeros(points.shape[1:])
    for index, rotation in enumerate(rotations):
        in_group = rotation_index == index
        # Only the columns some particle holds in this orientation: a closed-loop run has
        # about one orientation per action, so each pass checks a few configs, not all n.
        columns = np.flatnonzero(in_group.any(axis=0))
        if columns.size == 0:
            continue
        group_configs = np.where(
            in_group[:, columns], _in_frame(rotation, configs[:, :, columns]), np.nan
        )
        a, b = excess_sums(_in_frame(rotation, points), group_configs.astype(np.float32),
                           tolerance)  # fmt: skip
        per_particle += a
        per_point += b
    return per_particle, per_point


def _check_encloses_robot(grid: GridSdf) -> None:
    """Refuses a grid the robot reaches the boundary of.

    A point beyond the grid counts as outside the robot (no penetration). That is exact only
    when the robot lies inside the grid: every boundary node outside the robot (positive), so
    the interpolated surface never meets the grid's faces.
    """
    v = grid.values
    faces = (v[0], v[-1], v[:, 0], v[:, -1], v[:, :, 0], v[:, :, -1])
    lowest = min(float(face.min()) for face in faces)
    if lowest <= 0.0:
        raise ValueError(
            f"robot_sdf: the grid does not enclose the robot (a boundary node has signed "
            f"distance {lowest:.4g} m <= 0); build it over a box with a margin around the robot"
        )


def deep_box_corners(grid: GridSdf, depth: float = 0.0) -> np.ndarray | None:
    """(8, 3) corners (m, the grid's frame) of the box of grid nodes deeper than ``depth`` (m)
    inside the robot, grown by one cell (a lookup interpolates those nodes: no point outside
    it is deeper); None when no node is that deep."""
    deep = np.argwhere(grid.values < -depth)
    if len(deep) == 0:
        return None
    lower = grid.lower + (deep.min(axis=0) - 1) * grid.resolution
    upper = grid.lower + (deep.max(axis=0) + 1) * grid.resolution
    return np.stack(np.meshgrid(*zip(lower, upper, strict=True)), -1).reshape(-1, 3)


class RobotPenetration:
    """The paper's pxpen(x, p): penetration depth (m) of point p into the robot at EE pose x.

    The robot's geometry is a :class:`~stucco_drake.core.sdf.GridSdf` in the end-effector frame E
    (for the Drake scene, built once from Drake's distance queries and cached). A pose x is
    (p_WE, R_WE): a world point p_W is looked up at p_E = R_WE^T (p_W - p_WE). The grid must
    enclose the robot (every boundary node positive; a ValueError otherwise), so a point beyond
    it is outside the robot and its penetration, 0, is exact.

    Args:
        robot_sdf: signed distance of the robot in frame E (m, negative inside).
        pair_budget: (config, point) pairs per vectorised block; bounds scratch memory.
        deduplicate: evaluate each distinct (config, point) value pair once when particles
            share most of their contacts (as they do after resampling); the sums are the same.
    """

    def __init__(self, robot_sdf: GridSdf, pair_budget: int = 1 << 20, deduplicate: bool = True):
        if not isinstance(robot_sdf, GridSdf):
            raise ValueError(f"robot_sdf: expected a GridSdf, got {type(robot_sdf).__name__}")
        _check_encloses_robot(robot_sdf)
        self.robot_sdf = robot_sdf
        self.pair_budget = int(pair_budget)
        self.deduplicate = bool(deduplicate)
        self._workspace: dict[str, np.ndarray] = {}
        self._crops: dict[float, tuple] = {}
        self._deep_regions: dict[float, tuple | None] = {}

    def __call__(self, config_positions, points, config_rotation=None) -> np.ndarray:
        """Depth (m, >= 0) of ``points[..., 3]`` inside the robot at ``config_positions[..., 3]``.

        Leading dimensions broadcast. ``config_rotation`` is one R_WE (3, 3) for all configs
        (identity when omitted).
        """
        relative = np.asarray(points, dtype=np.float64) - np.asarray(config_positions, np.float64)
        if config_rotation is not None:
            relative = relative @ np.asarray(config_rotation, dtype=np.float64)
        return np.maximum(-self.robot_sdf(relative), 0.0)

    def all_pairs_excess_sums(self, points, configs, rotation_index, rotations, tolerance: float):
        """:meth:`excess_sums` of every config against every point of the same particle, each
        config in its own orientation, over the distinct (config, point) states only.

        Args:
            points, configs: (3, n_particles, n) float32 world positions (m).
            rotation_index: (n_particles, n) orientation slot of each config.
            rotations: (n_slots, 3, 3) R_WE of each slot.
            tolerance: penetration (m) ignored per pair.

        Returns:
            per_particle (n_particles,) and per_point (n_particles, n) float64 sums of
            max(0, depth - tolerance), added in the order of one pass per orientation slot.
        """
        key = float(tolerance)
        if key not in self._deep_regions:
            self._deep_regions[key] = deep_region(self.robot_sdf, key)
        entries = penetrating_entries(
            self.robot_sdf, tolerance, self._deep_regions[key], points, configs, rotation_index,
            rotations, self.pair_budget,
        )  # fmt: skip
        if entries is None:
            return self._per_orientation_sums(points, configs, rotation_index, rotations,
                                              tolerance)  # fmt: skip
        return ordered_sums(entries, points.shape[1], points.shape[2])

    def _per_orientation_sums(self, points, configs, rotation_index, rotations, tolerance):
        """:meth:`all_pairs_excess_sums` by one :meth:`excess_sums` pass per orientation slot
        (each particle's pairs checked separately): for particles that share few states."""
        return per_orientation_sums(self.excess_sums, points, configs, rotation_index,
                                    rotations, tolerance)  # fmt: skip

    def _buffer(self, name: str, size: int, dtype) -> np.ndarray:
        """Reused scratch memory: fresh multi-megabyte arrays cost page faults on every call."""
        buffer = self._workspace.get(name)
        if buffer is None or buffer.size < size or buffer.dtype != dtype:
            buffer = np.empty(size, dtype=dtype)
            self._workspace[name] = buffer
        return buffer[:size]

    def _crop(self, tolerance: float):
        """Node box where a pair can penetrate deeper than ``tolerance``, and its node values.

        A pair's quantised grid coordinate g (rounded point minus rounded config) is within one
        cell per axis of its true coordinate t, so every corner of t's cell is within two cells
        of g. The interpolant at t is below -tolerance only if a corner is, so g lies in the box
        of such nodes grown by two cells; and since node values sample a 1-Lipschitz distance,
        the interpolant is at least value(g) - 2 sqrt(3) h: pairs with value(g) >= ``level``
        cannot penetrate that deep. Nodes of the box outside the grid get -inf (always checked).
        """
        key = float(tolerance)
        if key not in self._crops:
            grid = self.robot_sdf
            deep = np.argwhere(grid.values < -tolerance)
            if len(deep) == 0:
                self._crops[key] = None
            else:
                lo = deep.min(axis=0) - 2
                hi = deep.max(axis=0) + 3
                values = np.full(tuple(hi - lo), -np.inf, dtype=np.float32)
                src_lo = np.maximum(lo, 0)
                src_hi = np.minimum(hi, grid.values.shape)
                values[
                    tuple(slice(a - b, c - b) for a, b, c in zip(src_lo, lo, src_hi, strict=True))
                ] = grid.values[tuple(slice(a, c) for a, c in zip(src_lo, src_hi, strict=True))]
                level = -tolerance + 2.0 * math.sqrt(3.0) * grid.resolution * 1.001
                self._crops[key] = (lo, values, level)
        return self._crops[key]

    @staticmethod
    def _distinct_states(coordinates):
        """Group equal columns entries across particles: (state ids, representatives) or None.

        ``coordinates`` (3, n_particles, m): after resampling most particles hold identical
        copies of a contact, so each column takes only a few distinct values. Returns
        ``ids`` (n_particles, m), the state of each entry within its column, ``offsets`` (m,)
        where each column's states start in a flat numbering and ``representative`` (total,)
        a particle holding each state. Grouping hashes the float bits and is then verified
        exactly; None when it fails (a hash collision, or NaN entries).
        """
        bits = np.ascontiguousarray(coordinates).view(np.uint32).astype(np.uint64)
        key = bits[0] * np.uint64(0x9E3779B97F4A7C15)
        key ^= bits[1] * np.uint64(0xC2B2AE3D27D4EB4F)
        key ^= bits[2] * np.uint64(0x165667B19E3779F9)
        order = np.argsort(key, axis=0, kind="stable")
        sorted_key = np.take_along_axis(key, order, axis=0)
        first = np.ones(sorted_key.shape, dtype=bool)
        first[1:] = sorted_key[1:] != sorted_key[:-1]
        rank = np.cumsum(first, axis=0) - 1
        ids = np.empty(rank.shape, dtype=np.int64)
        np.put_along_axis(ids, order, rank, axis=0)
        counts = rank[-1] + 1
        offsets = np.concatenate([[0], np.cumsum(counts)[:-1]])
        representative = order.T[first.T]  # column-major: column c's states in rank order
        columns = np.arange(coordinates.shape[2])
        held = coordinates[:, representative[offsets + ids], columns]
        if not np.array_equal(held, coordinates):
            return None
        return ids, offsets, counts, representative

    def _deduplicated_sums(self, points_e, configs_e, tolerance, crop):
        """:meth:`excess_sums` evaluating each distinct (config, point) value pair once.

        Returns None when the particles are too diverse for this to pay off (or a config is
        skipped with NaN), and the caller takes the per-particle path.
        """
        n_particles, n_points = points_e.shape[1:]
        if np.isnan(configs_e).any():  # NaN never equals itself, so grouping would fail anyway
            return None
        point_states = self._distinct_states(points_e)
        config_states = self._distinct_states(configs_e)
        if point_states is None or config_states is None:
            return None
        p_ids, p_offsets, p_counts, p_rep = point_states
        c_ids, c_offsets, c_counts, c_rep = config_states
        grid = self.robot_sdf
        origin_cells = grid.lower / grid.resolution
        crop_lo, crop_values, _ = crop
        config_of_pair, point_of_pair = candidate_pairs(
            quantise(points_e, grid.resolution, origin_cells + crop_lo, skip_nan=False),
            quantise(configs_e, grid.resolution, np.zeros(3), skip_nan=True),
            np.array(crop_values.shape),
        )
        combos = c_counts[config_of_pair] * p_counts[point_of_pair]
        total = int(combos.sum())
        if total > n_particles * config_of_pair.size // 4:
            return None
        per_particle = np.zeros(n_particles)
        per_point = np.zeros((n_particles, n_points))
        if total == 0:
            return per_particle, per_point
        pair = np.repeat(np.arange(config_of_pair.size), combos)
        local = np.arange(total) - np.repeat(np.cumsum(combos) - combos, combos)
        config, point = config_of_pair[pair], point_of_pair[pair]
        config_state, point_state = np.divmod(local, p_counts[point])
        config_holder = c_rep[c_offsets[config] + config_state]
        point_holder = p_rep[p_offsets[point] + point_state]
        inverse_h = np.float32(1.0 / grid.resolution)
        cells = [
            (points_e[a, point_holder, point] - configs_e[a, config_holder, config]) * inverse_h
            - np.float32(origin_cells[a])
            for a in range(3)
        ]
        excess = np.maximum(-grid.at_cell_coordinates(*cells) - tolerance, 0.0)
        hit = np.flatnonzero(excess > 0.0)
        if hit.size == 0:
            return per_particle, per_point
        # Which particles hold each penetrating value pair: both entries in the right state.
        holds = (c_ids[:, config[hit]] == config_state[hit]) & (
            p_ids[:, point[hit]] == point_state[hit]
        )
        particle, which = np.nonzero(holds)
        values = excess[hit][which].astype(np.float64)
        per_particle += np.bincount(particle, values, minlength=n_particles)
        per_point += np.bincount(
            particle * n_points + point[hit][which], values, minlength=n_particles * n_points
        ).reshape(n_particles, n_points)
        return per_particle, per_point

    def excess_sums(self, points_e, configs_e, tolerance: float):
        """Sum, per particle and per point, the penetration beyond ``tolerance`` of every pair.

        Args:
            points_e: (3, n_particles, n_points) float32 point coordinates along the EE axes
                (world points already rotated by R_WE^T of the configs' common orientation).
            configs_e: (3, n_particles or 1, n_configs) float32 EE origins along the same axes;
                NaN marks a config to skip (it belongs to another orientation).
            tolerance: penetration (m) ignored per pair.

        Returns:
            per_particle (n_particles,) and per_point (n_particles, n_points) float64 sums of
            max(0, depth - tolerance) over all (config, point) pairs.

        Every pair is first culled on integer grid coordinates (one subtraction and one unsigned
        comparison per axis, :mod:`~stucco_drake.core.cell_pairs`), then screened by the nearest
        node's value, and only the few pairs left are interpolated exactly. Work runs in blocks
        of about ``pair_budget`` pairs.
        """
        _, n_particles, n_points = points_e.shape
        per_particle = np.zeros(n_particles)
        per_point = np.zeros((n_particles, n_points))
        crop = self._crop(tolerance)
        if n_points == 0 or configs_e.shape[2] == 0 or crop is None:
            return per_particle, per_point
        # Grouping hashes every point: it pays off only against more than a few configs.
        if self.deduplicate and configs_e.shape[1] > 1 and configs_e.shape[2] >= 8:
            sums = self._deduplicated_sums(points_e, configs_e, tolerance, crop)
            if sums is not None:
                return sums
        crop_lo, crop_values, _ = crop
        pairs = CellPairs.build(points_e, configs_e, self.robot_sdf, crop_lo,
                                np.array(crop_values.shape))  # fmt: skip
        if pairs is None:
            return per_particle, per_point
        block = max(1, min(n_particles, self.pair_budget // pairs.size))
        work = self._cull_buffers(block * pairs.size, pairs.point_cells.dtype)
        for start in range(0, n_particles, block):  # blocks of particles, bounded memory
            stop = min(start + block, n_particles)
            found = self._block_excess(points_e, configs_e, pairs, start, stop, work, crop,
                                       tolerance)  # fmt: skip
            if found is None:
                continue
            particle, point, excess = found
            per_particle[start:stop] += np.bincount(particle, excess, minlength=stop - start)
            per_point[start:stop] += np.bincount(
                particle * n_points + point, excess, minlength=(stop - start) * n_points
            ).reshape(stop - start, n_points)
        return per_particle, per_point

    def _cull_buffers(self, size: int, dtype) -> tuple[np.ndarray, ...]:
        """Work arrays of :meth:`CellPairs.inside_crop` for ``size`` pairs of cells of type
        ``dtype`` (reused across calls, see :meth:`_buffer`)."""
        name = np.dtype(dtype).name
        return (self._buffer(f"cells_{name}", size, dtype),
                self._buffer(f"gathered_{name}", 2 * size, dtype),
                self._buffer("mask", size, np.bool_),
                self._buffer("axis_mask", size, np.bool_))  # fmt: skip

    def _block_excess(self, points_e, configs_e, pairs: CellPairs, start: int, stop: int, work,
                      crop, tolerance: float):  # fmt: skip
        """The pairs of particles ``start:stop`` that may penetrate beyond ``tolerance`` (m):
        ``(particle - start, point, excess)``, excess = max(0, depth - tolerance) (m), or None
        when no pair comes near. Pairs inside the crop box are screened by their nearest node's
        value (see :meth:`_crop`), and only the pairs left are interpolated exactly."""
        flat = pairs.inside_crop(start, stop, *work)
        if flat.size == 0:
            return None
        particle = flat // pairs.size
        pair = flat - particle * pairs.size
        config = pairs.config_of_pair[pair]
        point = pairs.point_of_pair[pair]
        rows = start + particle
        config_particle = np.zeros_like(rows) if pairs.shared_configs else rows
        _, crop_values, level = crop
        node = pairs.point_nodes[rows, point] - pairs.config_nodes[config_particle, config]
        near = crop_values.ravel()[node] < level
        if not near.any():
            return None
        particle, point, rows, config, config_particle = (
            v[near] for v in (particle, point, rows, config, config_particle)
        )
        grid = self.robot_sdf
        inverse_h = np.float32(1.0 / grid.resolution)
        origin_cells = (grid.lower / grid.resolution).astype(np.float32)
        cells = [
            (points_e[a, rows, point] - configs_e[a, config_particle, config]) * inverse_h
            - origin_cells[a]
            for a in range(3)
        ]
        excess = np.maximum(-grid.at_cell_coordinates(*cells) - tolerance, 0.0)
        return particle, point, excess
