"""Penetration of posed target restarts into the robot, for choosing a target pose.

The restart the target-pose estimator keeps is the one that penetrates the end-effector
configs least (paper Sec. V-C); which configs count is :func:`penetration_window`'s choice.
Units: m; positions in the world frame W, the robot's geometry in its end-effector frame E.
"""

from __future__ import annotations

import numpy as np

from stucco_drake.core.icp import cross_section_sdf, sample_outline, transform
from stucco_drake.core.penetration import RobotPenetration, deep_box_corners
from stucco_drake.core.shapes import BoxSdf, CylinderSdf

#: Pair budget of one vectorised penetration block: (restart, config) pairs x model points.
_PAIR_POINT_BUDGET = 1 << 20

#: Which of the configs passed to
#: :func:`~stucco_drake.core.target_pose.estimate_target_pose` the restarts are checked against
#: for penetration (besides an integer N: the last N).
PENETRATION_CONFIGS = ("all", "latest", "since_touch")


def sample_cross_section(shape: BoxSdf | CylinderSdf, spacing: float) -> np.ndarray:
    """(m, 2) points covering ``shape``'s cross-section in frame O: its outline plus a grid inside.

    The interior matters for penetration: a robot lying wholly inside a wrongly posed object
    touches none of its outline points.
    """
    outline = sample_outline(shape, spacing)
    lower, upper = outline.min(axis=0), outline.max(axis=0)
    axes = [np.arange(lo + spacing / 2, hi, spacing) for lo, hi in zip(lower, upper, strict=True)]
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 2)
    return np.concatenate([outline, grid[cross_section_sdf(shape)(grid) < 0.0]])


def penetration_window(n_configs: int, rule: str | int, segment_steps=None) -> slice:
    """The configs (a slice of the ``n_configs`` passed, oldest first) to test for penetration.

    ``"all"``: every one (the authors' code). ``"latest"``: x_t only (the paper's text).
    ``"since_touch"``: from the config at which the chosen segment was last sensed on, the
    latest of ``segment_steps`` (its points' config indices), onwards: earlier configs may
    overlap where the target lies now, because it was pushed since. An integer N: the last N.
    """
    if rule == "all":
        return slice(0, n_configs)
    if rule == "latest":
        return slice(max(n_configs - 1, 0), n_configs)
    if rule == "since_touch":
        if segment_steps is None or len(segment_steps) == 0:
            raise ValueError("penetration_configs: 'since_touch' needs point_steps")
        return slice(min(int(np.max(segment_steps)), max(n_configs - 1, 0)), n_configs)
    if isinstance(rule, int | np.integer) and not isinstance(rule, bool) and rule >= 1:
        return slice(max(n_configs - int(rule), 0), n_configs)
    raise ValueError(
        f"penetration_configs: expected one of {PENETRATION_CONFIGS} or an int >= 1, got {rule!r}"
    )



def restart_penetration(
    penetration: RobotPenetration,
    poses,
    model_xy,
    height: float,
    config_positions,
    config_rotation=None,
    tolerance: float = 0.0,
) -> np.ndarray:
    """(B,) summed robot penetration beyond ``tolerance`` (m) of the posed model at every config.

    Each restart's model points ``model_xy`` (m, 2, frame O), posed by ``poses`` (B, 3) at world
    height ``height`` (m), are looked up in the robot at every config (``config_positions``
    (k, 3) in W, one shared ``config_rotation`` R_WE). A point can penetrate deeper than
    ``tolerance`` only inside the box of grid nodes deeper than that, grown by one cell (the
    lookup interpolates those nodes), so (restart, config) pairs and then single points outside
    that box are culled before the lookups.
    """
    poses = np.asarray(poses, dtype=np.float64)
    configs = np.asarray(config_positions, dtype=np.float64)
    scores = np.zeros(len(poses))
    corners = deep_box_corners(penetration.robot_sdf, tolerance)
    if len(configs) == 0 or corners is None:
        return scores
    lower, upper = corners.min(axis=0), corners.max(axis=0)
    robot_reach = np.linalg.norm(corners, axis=1).max()
    model_reach = np.linalg.norm(model_xy, axis=1).max()
    gap = np.linalg.norm(configs[None, :, :2] - poses[:, None, :2], axis=-1)
    restart, config = np.nonzero(gap <= robot_reach + model_reach)
    posed = transform(poses, model_xy)
    posed = np.concatenate([posed, np.full((*posed.shape[:2], 1), height)], axis=-1)
    block = max(1, _PAIR_POINT_BUDGET // len(model_xy))
    for start in range(0, len(restart), block):  # blocks of pairs, bounded memory
        b, k = restart[start : start + block], config[start : start + block]
        relative = posed[b] - configs[k, None, :]
        if config_rotation is not None:
            relative = relative @ config_rotation  # rows R_WE^T r: along the robot's axes
        pair, point = np.nonzero(np.all((relative >= lower) & (relative <= upper), axis=-1))
        depth = penetration(configs[k[pair]], posed[b[pair], point], config_rotation)
        excess = np.maximum(depth - tolerance, 0.0)
        scores += np.bincount(b[pair], excess, minlength=len(poses))
    return scores
