"""Target pose for Blind Object Retrieval: ICP on every segment, then the paper's selection rule.

Frames and units: contact points, end-effector configs and the returned pose are in the world
frame W (metres); the pose (x, y, yaw) is the planar pose of the target's shape frame O (radians
for yaw). See :mod:`stucco_drake.core.icp` for the fitting itself.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from stucco_drake.core.icp import cross_section_sdf, icp_2d, sample_outline, transform
from stucco_drake.core.penetration import RobotPenetration
from stucco_drake.core.shapes import BoxSdf, CylinderSdf
from stucco_drake.core.validation import as_finite_array, as_rotation

#: Pair budget of one vectorised penetration block: (restart, config) pairs x model points.
_PAIR_POINT_BUDGET = 1 << 20


@dataclasses.dataclass(frozen=True)
class SegmentReport:
    """ICP summary of one segment.

    Attributes:
        label: the segment's label.
        n_points: its contact points.
        position_variance: sum of the unbiased variances of the restarts' x and y (m^2); NaN
            when the segment had too few points to be fitted.
        best_rms: lowest ICP RMS over its restarts (m); NaN when not fitted.
    """

    label: int
    n_points: int
    position_variance: float
    best_rms: float


@dataclasses.dataclass(frozen=True)
class TargetPoseEstimate:
    """The chosen target pose and how it was chosen.

    Attributes:
        x, y: position of the target's frame O in W (m).
        yaw: its rotation about world z (rad, in [-pi, pi)).
        segment: label of the chosen segment.
        rms: ICP RMS of the chosen restart (m).
        penetration: its summed robot penetration beyond the tolerance (m, over all
            (config, model point) pairs; 0 when nothing penetrates).
        restarts: (B, 3) every restart's pose (x, y, yaw) for the chosen segment.
        segments: one report per segment, in increasing label order.
    """

    x: float
    y: float
    yaw: float
    segment: int
    rms: float
    penetration: float
    restarts: np.ndarray
    segments: tuple[SegmentReport, ...]

    @property
    def pose(self) -> np.ndarray:
        """(3,) (x, y, yaw) in W (m, m, rad)."""
        return np.array([self.x, self.y, self.yaw])


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
    grid = penetration.robot_sdf
    deep = np.argwhere(grid.values < -tolerance)
    if len(configs) == 0 or len(deep) == 0:
        return scores
    lower = grid.lower + (deep.min(axis=0) - 1) * grid.resolution
    upper = grid.lower + (deep.max(axis=0) + 1) * grid.resolution
    corners = np.stack(np.meshgrid(*zip(lower, upper, strict=True)), -1).reshape(-1, 3)
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


def estimate_target_pose(
    rng: np.random.Generator,
    points,
    labels,
    shape: BoxSdf | CylinderSdf,
    penetration: RobotPenetration | None = None,
    config_positions=None,
    config_rotation=None,
    *,
    n_restarts: int = 30,
    spacing: float = 0.002,
    fill_spacing: float = 0.005,
    penetration_tolerance: float = 0.002,
    max_iterations: int = 50,
    tolerance: float = 1e-5,
    min_points: int = 3,
    initial_pose=None,
    start: str = "surface",
) -> TargetPoseEstimate:
    """Estimate the target's planar pose from segmented contact points (paper Sec. V-C).

    1. Every segment (label >= 0; negative labels are noise) with at least ``min_points``
       points is fitted by :func:`~stucco_drake.core.icp.icp_2d` with ``n_restarts`` starts
       against the target's outline at contact height (three contacts are the fewest that can
       pin a planar pose).
    2. The segment whose restarts' positions vary least (sum of unbiased x and y variances) is
       taken as the target. Position, not yaw, is compared, so a box's 180-degree symmetry
       does not count as spread.
    3. Within it, the restart that penetrates the end-effector configs least is taken, ties
       (typically several restarts that penetrate nothing) broken by the lowest ICP RMS. This
       is the paper's rule; the authors' code instead takes the smallest |min signed distance|
       to the gripper (closest to just touching) with no RMS tie-break.

    Penetration is the robot's own: :class:`RobotPenetration` depth of the posed target's
    cross-section (outline plus interior, ``fill_spacing`` m) at every config, summed beyond
    ``penetration_tolerance`` (m) per pair. The robot's geometry is used, not the target's SDF
    at the config origins, because the gripper reaches centimetres beyond its origin: a pose
    lying across the fingers must count. The tolerance (default: the sim's intersection
    tolerance) forgives the millimetres a correct, touching pose sinks into the gripper through
    contact noise, so such poses tie at zero and the ICP error decides between them.
    Pass every config visited (the authors' code does); passing only x_t reads the paper
    literally. Without ``penetration`` or configs the restart is chosen by RMS alone.

    Args:
        rng: caller-seeded generator for the ICP starts (segments in increasing label order).
        points: (n, 3) contact points in W (m), e.g. ``SoftTracker.map_points()``.
        labels: (n,) integer segment labels, e.g. ``SoftTracker.segment()``.
        shape: the target's known geometry in its frame O.
        penetration: the robot's pxpen, or None.
        config_positions: (k, 3) end-effector origins in W (m), or None.
        config_rotation: one (3, 3) R_WE for all configs (identity when omitted).
        n_restarts, max_iterations, tolerance, start: ICP settings (see ``icp_2d``);
            ``n_restarts`` >= 2 for a variance.
        spacing: model outline spacing for ICP (m).
        fill_spacing: spacing of the cross-section points checked for penetration (m).
        penetration_tolerance: per-pair penetration ignored (m).
        min_points: segments with fewer points are reported but not fitted.
        initial_pose: optional (3,) warm start replacing each segment's first restart.

    Raises:
        ValueError: naming the argument, e.g. no contact points or no segment to fit.
    """
    points = as_finite_array(points, "points", (None, 3))
    if len(points) == 0:
        raise ValueError("points: no contact points")
    labels = np.asarray(labels)
    if labels.shape != (len(points),) or not np.issubdtype(labels.dtype, np.integer):
        raise ValueError(f"labels: expected {len(points)} integer labels, got {labels.shape}")
    model = sample_outline(shape, spacing)
    fill = sample_cross_section(shape, fill_spacing)
    configs = None
    if config_positions is not None:
        configs = as_finite_array(config_positions, "config_positions", (None, 3))
    if config_rotation is not None:
        config_rotation = as_rotation(config_rotation, "config_rotation")
    if penetration is not None and not isinstance(penetration, RobotPenetration):
        raise ValueError(f"penetration: expected a RobotPenetration, got {type(penetration)}")
    if int(n_restarts) < 2:
        raise ValueError(f"n_restarts: the variance rule needs at least 2, got {n_restarts!r}")

    reports, fits = [], {}
    for label in np.unique(labels[labels >= 0]):
        members = points[labels == label]
        if len(members) < min_points:
            reports.append(SegmentReport(int(label), len(members), np.nan, np.nan))
            continue
        result = icp_2d(
            rng, members[:, :2], model, n_restarts, max_iterations, tolerance, initial_pose, start
        )
        spread = float(np.sum(np.var(result.poses[:, :2], axis=0, ddof=1)))
        # The model is posed at the segment's mean contact height for the penetration check.
        fits[int(label)] = (spread, result, float(members[:, 2].mean()))
        reports.append(SegmentReport(int(label), len(members), spread, float(result.rms.min())))
    if not fits:
        raise ValueError(f"labels: no segment has at least {min_points} points")
    chosen = min(fits, key=lambda label: fits[label][0])
    _, result, height = fits[chosen]
    scores = np.zeros(n_restarts)
    if penetration is not None and configs is not None:
        scores = restart_penetration(
            penetration,
            result.poses,
            fill,
            height,
            configs,
            config_rotation,
            penetration_tolerance,
        )
    # Exact ties are the common case (several restarts with no penetration at all); the small
    # absolute slack only absorbs summation round-off.
    tied = np.flatnonzero(scores <= scores.min() + 1e-12)
    best = tied[np.argmin(result.rms[tied])]
    x, y, yaw = result.poses[best]
    return TargetPoseEstimate(
        x=float(x),
        y=float(y),
        yaw=float(yaw),
        segment=chosen,
        rms=float(result.rms[best]),
        penetration=float(scores[best]),
        restarts=result.poses.copy(),
        segments=tuple(reports),
    )
