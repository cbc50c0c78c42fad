"""The target's pose estimated from a replayed episode log, and how far it is from the truth.

Two estimators see the same tracker and log: the segment-selection rules of
:func:`~stucco_drake.core.target_pose.estimate_target_pose` (what the grasp of Table II used) and
the weighted hypotheses of :func:`~stucco_drake.core.pose_hypotheses.pose_hypotheses` (contact,
free-space and shape evidence, with a confidence). :func:`score_estimates` measures both against
the target's logged final pose without simulating a grasp, so rules can be developed on many
logged layouts cheaply. Units: m, rad; world frame W. The target is object 0 of a log.
"""

from __future__ import annotations

import numpy as np

from stucco_drake.core.free_space import FreeSpace
from stucco_drake.core.grasp_choice import grasp_at, grasp_closes
from stucco_drake.core.icp import cross_section_sdf, rotations, sample_outline, transform
from stucco_drake.core.motion_scale import (
    MOTION_SCALES,
    motion_scaled_hypotheses,
    scales_under_push_limit,
)
from stucco_drake.core.penetration import RobotPenetration
from stucco_drake.core.pose_hypotheses import (
    HypothesisParams,
    PoseHypotheses,
)
from stucco_drake.core.shapes import BoxSdf, CylinderSdf
from stucco_drake.core.target_pose import NoSegmentToFit, TargetPoseEstimate, estimate_target_pose
from stucco_drake.eval.episode_log import EpisodeLog, shape_sdf

#: Fewest points of a segment for a pose fit (three pin a planar pose).
MIN_SEGMENT_POINTS = 3


def log_target_shape(log: EpisodeLog) -> BoxSdf | CylinderSdf:
    """The target's (object 0's) shape in its own frame, from the log's shape rows."""
    rows = log.object_shapes[log.shape_object == 0]
    if len(rows) != 1 or np.any(rows[0][4:7] != 0.0):
        raise ValueError(f"{log.scene} seed {log.seed}: the target is not one centred primitive")
    return shape_sdf(rows[0])


def point_steps(log: EpisodeLog) -> np.ndarray:
    """(n,) the action (index into ``log.ee_position``) at which each contact was sensed."""
    return np.repeat(np.arange(log.n_actions), np.diff(log.contact_offsets))


def log_motion_scales(log: EpisodeLog, params: HypothesisParams | None = None) -> tuple:
    """The motion scales the hypotheses search on ``log``, as its episode's estimator did:
    every one, or with ``params.still_when_unslidable`` only 0 when the push limit could not
    slide the target (its ``info["target_slide"]``,
    :func:`~stucco_drake.core.motion_scale.scales_under_push_limit`). ValueError for a log
    recorded without it."""
    if not (params or HypothesisParams()).still_when_unslidable:
        return tuple(MOTION_SCALES)
    slide = log.info.get("target_slide")
    if slide is None:
        raise ValueError(f"{log.scene} seed {log.seed}: still_when_unslidable needs the "
                         "target's mass and friction, which this log predates")
    return scales_under_push_limit(**slide)


def rules_estimate(rng, log: EpisodeLog, tracker, shape,
                   penetration: RobotPenetration) -> TargetPoseEstimate | None:  # fmt: skip
    """The segment-selection estimate the Table II grasp uses (30 restarts, the robot's pxpen at
    the configs since the chosen segment was last touched), or None when no segment has
    :data:`MIN_SEGMENT_POINTS` points (nor a part narrower than the target)."""
    points, labels = tracker.map_points(), np.asarray(tracker.segment())
    if np.bincount(labels[labels >= 0], minlength=1).max() < MIN_SEGMENT_POINTS:
        return None
    try:
        return estimate_target_pose(
            rng, points, labels, shape, penetration, log.ee_position, log.ee_rotation[-1],
            min_points=MIN_SEGMENT_POINTS, penetration_configs="since_touch",
            point_steps=point_steps(log),
        )  # fmt: skip
    except NoSegmentToFit:  # segments wider than the target, in pieces too small to fit
        return None


def hypotheses_estimate(rng, log: EpisodeLog, tracker, shape, penetration: RobotPenetration,
                        params: HypothesisParams | None = None,
                        scales=MOTION_SCALES) -> PoseHypotheses | None:  # fmt: skip
    """Weighted hypotheses over poses and motion ``scales`` from the contacts where sensed
    and where the tracker's MAP particle has them
    (:func:`~stucco_drake.core.motion_scale.motion_scaled_hypotheses`), with the free space of
    every logged config (swept along the actions that sensed no contact), or None when no
    segment has enough points."""
    params = params or HypothesisParams()
    points, labels = tracker.map_points(), np.asarray(tracker.segment())
    if np.bincount(labels[labels >= 0], minlength=1).max() < params.min_explained:
        return None
    steps = point_steps(log)
    free = FreeSpace(penetration, log.ee_position, log.ee_rotation[-1], steps,
                     free_actions=np.diff(log.contact_offsets) == 0)
    # Each point's action's peak force (older logs did not keep the forces).
    forces = log.action_peak_force[steps] if len(log.action_peak_force) else None
    return motion_scaled_hypotheses(rng, log.contact_points, points, labels, shape,
                                    free_space=free, params=params, scales=scales,
                                    point_forces=forces)  # fmt: skip


def target_surface_distance(shape, points, pose) -> np.ndarray:
    """(n,) signed distance (m, negative inside) of ``points`` (n, 3) to the target's
    cross-section posed at ``pose`` (x, y, yaw)."""
    local = np.einsum("ni,ij->nj", np.asarray(points, dtype=np.float64)[:, :2] - pose[:2],
                      rotations(pose[2]))  # fmt: skip
    return cross_section_sdf(shape)(local)


def outline_error(shape, estimate, truth, spacing: float = 0.005) -> float:
    """Symmetric Hausdorff distance (m) between the target's outline at two poses (x, y, yaw):
    0 for a box turned by pi, whatever the yaw for a cylinder."""
    outline = sample_outline(shape, spacing)
    a, b = transform(np.array([estimate, truth], dtype=np.float64), outline)
    d = np.sqrt(np.sum((a[:, None] - b[None]) ** 2, axis=-1))
    return float(max(d.min(axis=0).max(), d.min(axis=1).max()))


def score_estimates(log: EpisodeLog, tracker, penetration: RobotPenetration,
                    params: HypothesisParams | None = None, scales=MOTION_SCALES) -> dict:
    """Both estimators on one replayed log against the target's final pose: a row with the
    target's contact count, each estimate's position and outline errors (m; NaN when it gave
    none) and the hypotheses' (searched at the motion ``scales``) confidence and count.
    Generators seeded by ``[log.seed, 1]`` as the grasp's."""
    shape = log_target_shape(log)
    truth = log.object_poses[-1, 0][[0, 1, -1]]
    on_target = log.contact_object == 0
    row = {"scene": log.scene, "seed": int(log.seed),
           "target_contacts": int(np.count_nonzero(on_target))}  # fmt: skip
    # How well the tracked points that were sensed on the target fit its true final outline:
    # the floor under any pose estimate (CE counts the nearest surface of any object instead).
    offsets = np.abs(target_surface_distance(shape, tracker.map_points()[on_target], truth))
    row["target_points_median_m"] = float(np.median(offsets)) if len(offsets) else np.nan
    row["target_points_within_5mm"] = float(np.mean(offsets < 0.005)) if len(offsets) else np.nan
    rules = rules_estimate(np.random.default_rng([log.seed, 1]), log, tracker, shape, penetration)
    found = hypotheses_estimate(np.random.default_rng([log.seed, 1]), log, tracker, shape,
                                penetration, params, scales)  # fmt: skip
    closing_yaw = float(np.arctan2(log.ee_rotation[-1][1, 0], log.ee_rotation[-1][0, 0]))
    for name, pose in (("rules", None if rules is None else rules.pose),
                       ("hypotheses", None if found is None else found.pose)):  # fmt: skip
        row[f"{name}_position_m"] = np.nan if pose is None else float(
            np.hypot(*(pose[:2] - truth[:2])))  # fmt: skip
        row[f"{name}_outline_m"] = np.nan if pose is None else outline_error(shape, pose, truth)
        # The paper's criterion for the grasp at the estimate, at the target's true pose (the
        # target does not move on the way down): the grasp's outcome without simulating it.
        row[f"{name}_closes"] = pose is not None and bool(
            grasp_closes(grasp_at(pose, shape, closing_yaw), truth, shape)[0, 0])
    row["confidence"] = 0.0 if found is None else found.confidence
    row["hypotheses"] = 0 if found is None else len(found.poses)
    return row
