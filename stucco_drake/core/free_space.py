"""Free space as a raster: how deep each spot of a horizontal slice was inside the robot.

A blind robot knows one thing for certain besides its contacts: wherever its own geometry went
without sensing a contact, no object was there at that moment. Along a push that sensed
nothing the end-effector follows a straight line between the configs logged at the ends of its
action (the planar controller's reference does, from the measured start), so those pushes are
swept densely here; an action that sensed a contact counts only its end config (the part swept
after the touch may have pushed the object along).

:func:`swept_configs` lists the configs with the action each belongs to;
:class:`SweptSlice` rasterises them at one height: for each cell of a 2-D grid in the world's
x-y plane and each action a, the deepest (m) the cell's centre lay inside the robot at any
config of action a or later. A pose hypothesis last touched in action a then looks up its
cross-section's points in layer a: a few array lookups per point instead of a penetration query
per (config, point) pair. Units: m; world frame W; the robot's geometry in its end-effector
frame E.

:class:`FreeSpace` is what the target-pose hypotheses are given of where the robot went, and
:func:`free_space_costs` their cost of a pose whose cross-section lay inside the robot there
(:mod:`~stucco_drake.core.pose_hypotheses`).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from stucco_drake.core.hypothesis_params import HypothesisParams
from stucco_drake.core.penetration import RobotPenetration, deep_box_corners

#: Raster cells (configs x footprint) evaluated per block: bounds scratch memory.
_CELL_BUDGET = 1 << 20


def swept_configs(positions, free_actions, spacing: float) -> tuple[np.ndarray, np.ndarray]:
    """The end-effector origins the robot went through, and the action of each.

    Args:
        positions: (k, 3) end-effector origins in W at the end of each action (m), oldest first.
        free_actions: (k,) whether each action sensed no contact; the straight path from the
            previous action's end to its own is then swept, every ``spacing`` m or closer.
            The first action has no logged start: only its end counts.
        spacing: largest distance between two swept configs (m).

    Returns:
        (m, 3) configs and (m,) the index of the action each belongs to, ascending.
    """
    positions = np.asarray(positions, dtype=np.float64).reshape(-1, 3)
    free = np.asarray(free_actions, dtype=bool).reshape(-1)
    if len(free) != len(positions):
        raise ValueError(f"free_actions: expected {len(positions)} flags, got {len(free)}")
    if not (np.isfinite(spacing) and spacing > 0):
        raise ValueError(f"spacing: must be > 0 m, got {spacing!r}")
    configs, actions = [], []
    for a, end in enumerate(positions):
        if a > 0 and free[a]:
            start = positions[a - 1]
            n = max(1, int(np.ceil(np.linalg.norm(end - start) / spacing)))
            fractions = np.arange(1, n + 1)[:, None] / n  # the start is the previous action's
            configs.append(start + fractions * (end - start))
            actions.append(np.full(n, a))
        else:
            configs.append(end[None])
            actions.append(np.array([a]))
    if not configs:
        return np.zeros((0, 3)), np.zeros(0, dtype=np.int64)
    return np.concatenate(configs), np.concatenate(actions).astype(np.int64)


@dataclasses.dataclass(frozen=True)
class SweptSlice:
    """Depth inside the robot on a horizontal slice, since each action.

    Attributes:
        lower: (2,) world x, y of cell (0, 0)'s centre (m).
        resolution: cell size (m).
        height: world z of the slice (m).
        depth_since: (k + 1, nx, ny) float32: layer a holds, per cell, the largest
            penetration depth (m, >= 0) of the cell's centre into the robot at any config of
            action a or later; layer k is all zero.
    """

    lower: np.ndarray
    resolution: float
    height: float
    depth_since: np.ndarray

    @classmethod
    def build(cls, penetration: RobotPenetration, configs, actions, n_actions: int,
              rotation, height: float, resolution: float = 0.0025) -> SweptSlice:  # fmt: skip
        """Rasterise the robot at ``configs`` ((m, 3) in W, of ``actions`` (m,) < n_actions,
        one shared R_WE ``rotation`` or None) on the slice at ``height`` (m)."""
        configs = np.asarray(configs, dtype=np.float64).reshape(-1, 3)
        actions = np.asarray(actions, dtype=np.int64).reshape(-1)
        reach = _footprint_reach(penetration, rotation)
        if len(configs) == 0 or reach is None:
            return cls(np.zeros(2), resolution, height, np.zeros((n_actions + 1, 1, 1), np.float32))
        lower = configs[:, :2].min(axis=0) - reach[0] - resolution
        upper = configs[:, :2].max(axis=0) + reach[1] + resolution
        shape = np.ceil((upper - lower) / resolution).astype(int) + 1
        # One footprint of cell offsets serves every config: each config is snapped to the cell
        # grid and the footprint spans the robot's reach around it, plus a cell for the snap.
        span = [np.arange(int(np.floor(lo / resolution)) - 1, int(np.ceil(hi / resolution)) + 2)
                for lo, hi in zip(-reach[0], reach[1], strict=True)]  # fmt: skip
        offsets = np.stack(np.meshgrid(*span, indexing="ij"), -1).reshape(-1, 2)
        snapped = np.rint((configs[:, :2] - lower) / resolution).astype(np.int64)
        per_action = np.zeros((n_actions + 1, shape[0] * shape[1]), dtype=np.float32)
        block = max(1, _CELL_BUDGET // len(offsets))
        for start in range(0, len(configs), block):
            cells = snapped[start:start + block, None] + offsets[None]  # (b, f, 2)
            cells = np.clip(cells, 0, shape - 1)
            centres = lower + cells * resolution
            points = np.concatenate([centres, np.full((*centres.shape[:2], 1), height)], -1)
            depth = penetration(configs[start:start + block, None], points, rotation)
            hit = depth > 0.0
            flat = (cells[..., 0] * shape[1] + cells[..., 1])[hit]
            rows = np.broadcast_to(actions[start:start + block, None], hit.shape)[hit]
            np.maximum.at(per_action, (rows, flat), depth[hit].astype(np.float32))
        # Layer a: the deepest over actions a and later (a running maximum from the last).
        depth_since = np.maximum.accumulate(per_action[::-1], axis=0)[::-1]
        return cls(lower, float(resolution), float(height),
                   depth_since.reshape(n_actions + 1, *shape))  # fmt: skip

    def depth(self, xy, since) -> np.ndarray:
        """(...,) depth (m) of world points ``xy`` (..., 2) in the layer of action ``since``
        (an int, or (...,) ints broadcasting with ``xy``'s leading dimensions): their nearest
        cell's; 0 beyond the raster, where no config reached."""
        xy = np.asarray(xy, dtype=np.float64)
        layers, nx, ny = self.depth_since.shape
        ix = np.rint((xy[..., 0] - self.lower[0]) / self.resolution).astype(np.int64)
        iy = np.rint((xy[..., 1] - self.lower[1]) / self.resolution).astype(np.int64)
        inside = (ix >= 0) & (ix < nx) & (iy >= 0) & (iy < ny)
        layer = np.clip(np.asarray(since, dtype=np.int64), 0, layers - 1)
        flat = (layer * nx + np.clip(ix, 0, nx - 1)) * ny + np.clip(iy, 0, ny - 1)
        values = np.take(self.depth_since.reshape(-1), flat)
        return np.where(inside, values, np.float32(0.0))


def _footprint_reach(penetration: RobotPenetration, rotation):
    """How far (m) the robot's inside reaches from the end-effector origin along world -x, -y
    and +x, +y ((2,) each), from the grid nodes inside it; None when none is inside."""
    corners = deep_box_corners(penetration.robot_sdf)
    if corners is None:
        return None
    if rotation is not None:
        corners = corners @ np.asarray(rotation, dtype=np.float64).T  # into world axes
    return -corners[:, :2].min(axis=0), corners[:, :2].max(axis=0)


@dataclasses.dataclass(frozen=True)
class FreeSpace:
    """Where the robot has been: its pxpen and the end-effector configs, oldest first.

    Attributes:
        penetration: the robot's pxpen.
        positions: (k, 3) end-effector origins in W (m), one per action (at its end), oldest
            first.
        rotation: (3, 3) R_WE shared by all configs (None: identity).
        point_steps: (n,) index into ``positions`` of the config at which each contact point
            was sensed (the point's action).
        free_actions: (k,) whether each action sensed no contact: its straight path from the
            previous action's end is swept (see :mod:`~stucco_drake.core.free_space`); None:
            only the configs at the actions' ends count.
        slices: the :class:`SweptSlice` rasters built from it so far, by (height, sweep
            spacing, resolution): each is built once however many searches ask for it.
    """

    penetration: RobotPenetration
    positions: np.ndarray
    rotation: np.ndarray | None
    point_steps: np.ndarray
    free_actions: np.ndarray | None = None
    slices: dict = dataclasses.field(default_factory=dict, compare=False, repr=False)


def swept_slice(free: FreeSpace | None, height: float,
                params: HypothesisParams) -> SweptSlice | None:  # fmt: skip
    """The robot's free space on the slice at ``height`` (m) since each action, or None
    without any config."""
    if free is None or len(free.positions) == 0:
        return None
    key = (float(height), params.sweep_spacing, params.raster_resolution)
    if key not in free.slices:
        flags = (np.zeros(len(free.positions), dtype=bool) if free.free_actions is None
                 else free.free_actions)  # fmt: skip
        configs, actions = swept_configs(free.positions, flags, params.sweep_spacing)
        free.slices[key] = SweptSlice.build(free.penetration, configs, actions,
                                            len(free.positions), free.rotation, height,
                                            params.raster_resolution)  # fmt: skip
    return free.slices[key]


def free_space_costs(poses, explained, swept: SweptSlice | None, point_steps, fill,
                     params: HypothesisParams) -> np.ndarray:  # fmt: skip
    """(B,) free-space cost of each pose, its cross-section ``fill`` ((m, 2) in O) posed on
    the slice: the depth beyond ``free_space_tolerance`` to which each of its points lay
    inside the robot at any config since the last action that sensed a point the pose
    explains (all configs when it explains none), summed over the points, per
    ``free_space_scale``."""
    if swept is None:
        return np.zeros(len(poses))
    steps = np.where(explained, np.asarray(point_steps)[None], -1).max(axis=1)
    since = np.maximum(steps, 0)
    costs = np.empty(len(poses))
    block = max(1, (1 << 20) // len(fill))
    for k in range(0, len(poses), block):
        x, y, yaw = poses[k:k + block, :, None].transpose(1, 0, 2)
        c, s = np.cos(yaw), np.sin(yaw)
        # The posed fill, R(yaw) f + (x, y), as two (b, m) planes (cheaper than a (b, m, 2)
        # einsum, and all a nearest-cell lookup needs).
        posed = np.stack([c * fill[:, 0] - s * fill[:, 1] + x,
                          s * fill[:, 0] + c * fill[:, 1] + y], axis=-1)  # fmt: skip
        depth = swept.depth(posed, since[k:k + block, None])
        excess = np.maximum(depth - params.free_space_tolerance, 0.0)
        costs[k:k + block] = excess.sum(axis=1) / params.free_space_scale
    return costs


__all__ = ["FreeSpace", "SweptSlice", "free_space_costs", "swept_configs", "swept_slice"]
