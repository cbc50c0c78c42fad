"""pxpen from the user's own signed distance: any batched function of points in the EE frame.

:class:`~stucco_drake.core.penetration.RobotPenetration` (a signed-distance grid) is the fast
default. :class:`FunctionPenetration` takes the robot's geometry as a callable instead, for a
robot whose distance is known in closed form or from another library, with no grid and no
bounds: every (config, point) pair is evaluated exactly, in blocks. It offers the same batched
interface the trackers use, so ``SoftTracker(FunctionPenetration(f))`` works as is; the contact
motion models that need the robot's surface normals (``normal``, ``cone``) and the touched-side
rule need a grid.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from stucco_drake.core.penetration import per_orientation_sums

#: The signature: points (k, 3) in the end-effector frame E (m, float64) -> signed distance
#: (k,) to the robot's surface (m, negative inside).
SignedDistance = Callable[[np.ndarray], np.ndarray]


class FunctionPenetration:
    """pxpen(x, p) = max(0, -sdf(p_E)) with the robot's signed distance ``sdf`` in frame E.

    A pose x is (p_WE, R_WE); a world point p_W is evaluated at p_E = R_WE^T (p_W - p_WE).

    Args:
        signed_distance: batched :data:`SignedDistance` of the robot (may be called with up to
            ``pair_budget`` points at a time; must return one finite value per point).
        pair_budget: (config, point) pairs per call, bounding scratch memory.
    """

    #: No grid: trackers and contact motion that need one say so.
    robot_sdf = None

    def __init__(self, signed_distance: SignedDistance, pair_budget: int = 1 << 18):
        if not callable(signed_distance):
            raise ValueError("signed_distance: expected a callable of (k, 3) points")
        self.signed_distance = signed_distance
        self.pair_budget = int(pair_budget)

    def _depths(self, relative: np.ndarray) -> np.ndarray:
        """max(0, -sdf) of (k, 3) points (m), the function called in blocks."""
        out = np.empty(len(relative))
        for start in range(0, len(relative), self.pair_budget):
            block = relative[start : start + self.pair_budget]
            distance = np.asarray(self.signed_distance(block), dtype=np.float64).reshape(-1)
            if distance.shape != (len(block),) or not np.all(np.isfinite(distance)):
                raise ValueError(f"signed_distance: expected {len(block)} finite values, got "
                                 f"shape {distance.shape}")  # fmt: skip
            out[start : start + len(block)] = np.maximum(-distance, 0.0)
        return out

    def __call__(self, config_positions, points, config_rotation=None) -> np.ndarray:
        """Depth (m, >= 0) of ``points[..., 3]`` inside the robot at ``config_positions[..., 3]``
        (leading dimensions broadcast; one R_WE for all configs, identity when omitted)."""
        relative = np.asarray(points, dtype=np.float64) - np.asarray(config_positions, np.float64)
        if config_rotation is not None:
            relative = relative @ np.asarray(config_rotation, dtype=np.float64)
        return self._depths(relative.reshape(-1, 3)).reshape(relative.shape[:-1])

    def excess_sums(self, points_e, configs_e, tolerance: float):
        """Per particle and per point, the sum over configs of max(0, depth - tolerance).

        Same arguments and results as ``RobotPenetration.excess_sums``: (3, n_particles,
        n_points) points and (3, n_particles or 1, n_configs) configs along the EE axes, NaN
        configs skipped."""
        _, n_particles, n_points = points_e.shape
        per_point = np.zeros((n_particles, n_points))
        for particle in range(n_particles):
            configs = configs_e[:, particle if configs_e.shape[1] > 1 else 0]
            used = ~np.isnan(configs).any(axis=0)
            if n_points == 0 or not used.any():
                continue
            relative = (points_e[:, particle, None, :].astype(np.float64)
                        - configs[:, used, None].astype(np.float64))  # fmt: skip
            depth = self._depths(relative.reshape(3, -1).T).reshape(-1, n_points)
            per_point[particle] = np.maximum(depth - tolerance, 0.0).sum(axis=0)
        return per_point.sum(axis=1), per_point

    def all_pairs_excess_sums(self, points, configs, rotation_index, rotations, tolerance: float):
        """Every config of each particle against every point of it, each config in its own
        orientation (same arguments and results as ``RobotPenetration``'s)."""
        return per_orientation_sums(self.excess_sums, points, configs, rotation_index, rotations,
                                    tolerance)  # fmt: skip


__all__ = ["FunctionPenetration", "SignedDistance"]
