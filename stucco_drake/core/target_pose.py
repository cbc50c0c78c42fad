"""Target pose for Blind Object Retrieval: ICP on every segment, then a segment selection rule.

Frames and units: contact points, end-effector configs and the returned pose are in the world
frame W (metres); the pose (x, y, yaw) is the planar pose of the target's shape frame O (radians
for yaw). See :mod:`stucco_drake.core.icp` for the fitting itself and
:mod:`stucco_drake.core.segment_selection` for the estimator's steps and the reasons for each.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from stucco_drake.core.icp import sample_outline
from stucco_drake.core.penetration import RobotPenetration
from stucco_drake.core.pose_penetration import sample_cross_section
from stucco_drake.core.segment_selection import (
    GroupFit,
    ShapeEvidence,
    candidate_groups,
    choose_segment,
    fit_groups,
    restart_scores,
    shape_evidence,
)
from stucco_drake.core.shapes import BoxSdf, CylinderSdf
from stucco_drake.core.validation import as_finite_array, as_rotation

#: Segment selection rules of :func:`estimate_target_pose`.
SELECTIONS = ("shape", "paper")

#: Penetration (m) forgiven per pair at the configs before the penetration window at which the
#: chosen segment was touched: how far the target may have moved since (see
#: :func:`~stucco_drake.core.segment_selection.restart_scores`).
TOUCH_TOLERANCE = 0.01


class NoSegmentToFit(ValueError):
    """No segment (nor part of one narrower than the target) holds enough points to fit."""


@dataclasses.dataclass(frozen=True)
class SegmentReport:
    """ICP summary of one segment, or of the union of two.

    Attributes:
        label: the segment's label (the lower one of a union).
        n_points: its contact points.
        position_variance: sum of the unbiased variances of the restarts' x and y (m^2); NaN
            when the segment had too few points to be fitted.
        best_rms: lowest ICP RMS over its restarts (m); NaN when not fitted.
        shape_excess: how much worse the target's outline explains the points than the best
            circle or line does, as a log-likelihood-ratio statistic (dimensionless, see
            :func:`~stucco_drake.core.outline_fit.shape_excess`); NaN when not fitted. A
            union's is the sum of its fitted members' (see
            :func:`~stucco_drake.core.segment_selection.shape_evidence`).
        consistent: whether the segment passed the shape test (``shape_excess`` at most the
            threshold; for a union, whether every fitted member did); True when the rule does
            not test shapes, False when not fitted.
        merged_with: the other segment's label of a union; empty for a segment alone.
    """

    label: int
    n_points: int
    position_variance: float
    best_rms: float
    shape_excess: float = np.nan
    consistent: bool = False
    merged_with: tuple[int, ...] = ()

    @property
    def members(self) -> tuple[int, ...]:
        """The labels of the segments whose points were fitted together."""
        return (self.label, *self.merged_with)


@dataclasses.dataclass(frozen=True)
class TargetPoseEstimate:
    """The chosen target pose and how it was chosen.

    Attributes:
        x, y: position of the target's frame O in W (m).
        yaw: its rotation about world z (rad, in [-pi, pi)).
        segment: label of the chosen segment (of a chosen union, its member with the most
            points).
        members: labels of every segment whose points were fitted: ``(segment,)``, or both
            of a union (see ``merge_segments``).
        rms: ICP RMS of the chosen restart (m).
        penetration: its summed robot penetration beyond the tolerance (m, over all
            (config, model point) pairs; 0 when nothing penetrates).
        restarts: (B, 3) every restart's pose (x, y, yaw) for the chosen segment.
        segments: one report per segment, in increasing label order.
        unions: one report per union of two segments that was a candidate.
        labels: (n,) the segment labels the estimate used, one per contact point: the
            caller's, with every segment wider than the target split into its parts (see
            ``split_segments``; new parts numbered from the caller's largest label + 1).
            ``segment``, ``members`` and the reports refer to these.
    """

    x: float
    y: float
    yaw: float
    segment: int
    members: tuple[int, ...]
    rms: float
    penetration: float
    restarts: np.ndarray
    segments: tuple[SegmentReport, ...]
    unions: tuple[SegmentReport, ...] = ()
    labels: np.ndarray | None = None

    @property
    def pose(self) -> np.ndarray:
        """(3,) (x, y, yaw) in W (m, m, rad)."""
        return np.array([self.x, self.y, self.yaw])


def estimate_target_pose(
    rng: np.random.Generator, points, labels, shape: BoxSdf | CylinderSdf,
    penetration: RobotPenetration | None = None, config_positions=None, config_rotation=None,
    *, n_restarts: int = 30, spacing: float = 0.002, fill_spacing: float = 0.005,
    penetration_tolerance: float = 0.002, max_iterations: int = 50, tolerance: float = 1e-5,
    min_points: int = 3, initial_pose=None, start: str = "surface", selection: str = "shape",
    contact_noise: float = 0.002, shape_threshold: float = 9.0,
    penetration_configs: str | int = "all", point_steps=None, merge_segments: bool = True,
    split_segments: bool = True, touch_tolerance: float | None = TOUCH_TOLERANCE,
) -> TargetPoseEstimate:  # fmt: skip
    """Estimate the target's planar pose from segmented contact points (paper Sec. V-C).

    1. Candidates (:func:`~stucco_drake.core.segment_selection.candidate_groups`): the
       segments; with ``selection="shape"`` each one wider than the target split into its parts
       (``split_segments``) and the union of any two that fit within it added
       (``merge_segments``). Each with ``min_points`` points is fitted by ICP (``fit_groups``).
    2. ``selection="shape"`` (default) sets aside the groups a circle or a line explains much
       better than the target's outline (``shape_evidence``).
    3. The group taken as the target (``choose_segment``): the paper's least spread of the
       restarts' positions, or with ``"shape"`` the best of spread, shape evidence and the
       outline's own fit as log-scores.
    4. Its restart that penetrates the robot least at the configs (``restart_scores``), ties
       broken by the lowest ICP RMS.

    Args:
        rng: caller-seeded generator for the ICP starts (segments in increasing label order).
        points: (n, 3) contact points in W (m), e.g. ``SoftTracker.map_points()``.
        labels: (n,) integer segment labels, e.g. ``SoftTracker.segment()``.
        shape: the target's known geometry in its frame O.
        penetration: the robot's pxpen, or None.
        config_positions: (k, 3) end-effector origins in W (m), every config visited, oldest
            first, or None.
        config_rotation: one (3, 3) R_WE for all configs (identity when omitted).
        n_restarts, max_iterations, tolerance, start: ICP settings (see ``icp_2d``);
            ``n_restarts`` >= 2 for a variance.
        spacing: model outline spacing for ICP (m).
        fill_spacing: spacing of the cross-section points checked for penetration (m).
        penetration_tolerance: per-pair penetration ignored (m).
        min_points: segments with fewer points are reported but not fitted.
        initial_pose: optional (3,) warm start replacing each segment's first restart.
        selection: "shape" (default) or "paper", the segment selection rule (see above).
        contact_noise: standard deviation of the contact points about the touched surface
            (m), the shape test's noise floor.
        shape_threshold: largest shape excess (dimensionless) a target segment may have.
        penetration_configs: which configs the restarts are checked against: "all" (default),
            "latest", "since_touch" (needs ``point_steps``) or the last N, see
            :func:`~stucco_drake.core.pose_penetration.penetration_window`.
        point_steps: (n,) index into ``config_positions`` of the config at which each point
            was sensed (for ``penetration_configs="since_touch"``).
        merge_segments: whether unions of two segments compete as candidates (see above).
        split_segments: whether a segment wider than the target is replaced by its parts.
        touch_tolerance: per-pair penetration forgiven (m, default 1 cm) at the configs before
            the window at which the chosen segment was sensed (needs ``point_steps``); None
            leaves them out.

    Raises:
        ValueError: naming the argument, e.g. no contact points or no segment to fit.
    """
    given = _checked_inputs(points, labels, shape, spacing, fill_spacing, config_positions,
                            config_rotation, penetration, n_restarts, selection, contact_noise,
                            touch_tolerance, point_steps)  # fmt: skip
    by_shape = selection == "shape"
    labels, groups, singles = candidate_groups(
        given.points, given.labels, shape, contact_noise, min_points,
        split=by_shape and split_segments, merge=by_shape and merge_segments)  # fmt: skip
    fits = fit_groups(rng, groups, given.model, shape, min_points, n_restarts=n_restarts,
                      max_iterations=max_iterations, tolerance=tolerance,
                      initial_pose=initial_pose, start=start)  # fmt: skip
    if not fits:
        raise NoSegmentToFit(f"labels: no segment has at least {min_points} points")
    evidence = shape_evidence(fits, singles, selection, contact_noise, shape_threshold)
    reports = _reports(groups, fits, evidence)
    chosen = choose_segment(fits, evidence, selection, shape_threshold)
    fit = fits[chosen]
    touched = None if given.point_steps is None else given.point_steps[np.isin(labels, chosen)]
    scores = restart_scores(
        fit, given.fill, n_restarts, penetration, given.configs, given.config_rotation, touched,
        penetration_configs=penetration_configs, penetration_tolerance=penetration_tolerance,
        touch_tolerance=touch_tolerance)  # fmt: skip
    return _estimate(fit, chosen, labels, scores, reports)


def _estimate(fit: GroupFit, chosen: tuple[int, ...], labels: np.ndarray, scores: np.ndarray,
              reports: tuple[SegmentReport, ...]) -> TargetPoseEstimate:  # fmt: skip
    """The estimate at the chosen group's restart of least penetration ``scores`` (m), ties
    broken by the lowest ICP RMS."""
    # Exact ties are the common case (several restarts with no penetration at all); the small
    # absolute slack only absorbs summation round-off.
    tied = np.flatnonzero(scores <= scores.min() + 1e-12)
    best = tied[np.argmin(fit.result.rms[tied])]
    x, y, yaw = fit.result.poses[best]
    return TargetPoseEstimate(
        x=float(x),
        y=float(y),
        yaw=float(yaw),
        segment=max(chosen, key=lambda label: (int(np.sum(labels == label)), -label)),
        members=chosen,
        rms=float(fit.result.rms[best]),
        penetration=float(scores[best]),
        restarts=fit.result.poses.copy(),
        segments=tuple(r for r in reports if not r.merged_with),
        unions=tuple(r for r in reports if r.merged_with),
        labels=labels,
    )


@dataclasses.dataclass(frozen=True)
class _Inputs:
    """The estimator's checked inputs: ``points`` (n, 3) and ``labels`` (n,) as arrays, the
    ICP ``model`` outline and the cross-section ``fill`` (m, frame O), the ``configs`` (k, 3)
    in W (m) or None, ``config_rotation`` R_WE or None, ``point_steps`` (n,) or None."""

    points: np.ndarray
    labels: np.ndarray
    model: np.ndarray
    fill: np.ndarray
    configs: np.ndarray | None
    config_rotation: np.ndarray | None
    point_steps: np.ndarray | None


def _checked_inputs(points, labels, shape, spacing, fill_spacing, config_positions,
                    config_rotation, penetration, n_restarts, selection, contact_noise,
                    touch_tolerance, point_steps) -> _Inputs:  # fmt: skip
    """The arguments of :func:`estimate_target_pose` checked and converted, in its order;
    ValueError naming the first bad one."""
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
    if selection not in SELECTIONS:
        raise ValueError(f"selection: expected one of {SELECTIONS}, got {selection!r}")
    if not contact_noise > 0:
        raise ValueError(f"contact_noise: must be a positive distance (m), got {contact_noise!r}")
    if touch_tolerance is not None and not touch_tolerance >= 0:
        raise ValueError(f"touch_tolerance: must be a distance >= 0 (m), got {touch_tolerance!r}")
    if point_steps is not None:
        point_steps = np.asarray(point_steps)
        if point_steps.shape != (len(points),) or not np.issubdtype(point_steps.dtype, np.integer):
            raise ValueError(f"point_steps: expected {len(points)} integer config indices")
    return _Inputs(points, labels, model, fill, configs, config_rotation, point_steps)


def _reports(groups: dict, fits: dict[tuple, GroupFit],
             evidence: ShapeEvidence) -> tuple[SegmentReport, ...]:  # fmt: skip
    """One report per candidate group, in the groups' order (segments, then unions)."""
    return tuple(
        SegmentReport(members[0], len(groups[members]), np.nan, np.nan, merged_with=members[1:])
        if members not in fits
        else SegmentReport(
            members[0],
            len(groups[members]),
            fits[members].spread,
            float(fits[members].result.rms.min()),
            float(evidence.excess[members]),
            evidence.consistent[members],
            merged_with=members[1:],
        )
        for members in groups
    )
