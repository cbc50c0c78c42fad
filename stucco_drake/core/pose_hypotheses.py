"""Weighted hypotheses of the target's planar pose from all the evidence a blind robot has.

A pose (x, y, yaw) of the target's frame O in the world W is scored by the negative
log-likelihood of three kinds of evidence, in the spirit of CHSEL (Zhong, Fazeli, Berenson,
RSS 2023: contact points lie on the object's surface, free-space points outside it):

- **Contact points.** Each tracked point either lies on the target's surface (cost
  ``d^2 / 2 sigma_i^2 + log(sigma_i / contact_noise)``, a Gaussian's negative log-density up
  to a constant, ``d`` its signed distance to the posed target) or on some other object, at a
  fixed cost ``other_object_cost`` plus the same quadratic for any depth inside the target
  (another object's surface cannot lie inside it). A point takes the cheaper; the target
  *explains* it when that is the surface. ``sigma_i`` adds the point's own uncertainty (its
  spread over the tracker's particles, or how far it was carried: see
  :mod:`~stucco_drake.core.motion_scale`) to the sensor's noise, so points the robot is
  unsure of count less, and explaining one costs more the less sure it is.
- **Free space.** Where the gripper was after the target was last touched, the target is not:
  the posed target's cross-section must not lie inside the robot (its own geometry, pxpen) at
  those configs: each action's end, and every few millimetres along each push that sensed
  nothing (:mod:`~stucco_drake.core.free_space`). Earlier configs do not count, since the
  target may have been pushed there since. Each cross-section point's deepest penetration
  beyond a tolerance over those configs costs ``depth / free_space_scale``.
- **Force.** With ``light_force`` set, a point sensed in an action whose peak force stayed
  below it lies on an object that gave way more easily than the target: it is never put on
  the target's surface, and costs ``other_object_cost`` under every pose.
- **Shape.** Only poses of the known outline are proposed: ICP of the outline on every segment
  of tracked points, on every part of a segment wider than the target, and on every union of
  two segments the target could span; each is then refitted on the points it explains.

The hypotheses' weights are ``exp(-cost / temperature)``, normalised. One grasp is made: the
one that closes on the target (the paper's criterion, :mod:`~stucco_drake.core.grasp_choice`)
under the most weight, at a hypothesis or at the weighted mean of those it closes on. That
weight is the confidence: the posterior probability that the grasp closes on the target (0 when
the hypothesis grasped explains fewer than ``min_explained`` points: the target was barely
touched). Units: m, rad; world frame W.
"""

from __future__ import annotations

import dataclasses
import itertools

import numpy as np
from scipy.spatial import cKDTree

from stucco_drake.core.contact_location import location_costs_of
from stucco_drake.core.free_space import FreeSpace, free_space_costs, swept_slice
from stucco_drake.core.grasp_choice import choose_grasp
from stucco_drake.core.hypothesis_params import HypothesisParams
from stucco_drake.core.hypothesis_weights import cost_weights, tempered_confidence
from stucco_drake.core.icp import (
    cross_section_sdf,
    icp_2d,
    sample_outline,
    to_pose_frames,
    transform,
)
from stucco_drake.core.pose_penetration import sample_cross_section
from stucco_drake.core.segment_extent import outline_extent, split_wider_segments, xy_extent
from stucco_drake.core.shapes import BoxSdf, CylinderSdf
from stucco_drake.core.validation import as_finite_array


@dataclasses.dataclass(frozen=True)
class PoseHypotheses:
    """Distinct target poses with their weights, cheapest first.

    Attributes:
        poses: (k, 3) (x, y, yaw) in W (m, m, rad).
        costs: (k,) negative log-likelihoods (dimensionless, relative: only differences count).
        weights: (k,) posterior weights, summing to 1.
        explained: (k, n) whether each hypothesis puts each contact point on the target.
        confidence: posterior probability that the grasp at ``pose`` closes on the target
            (0 to 1; 0 when the hypothesis nearest it explains fewer than ``min_explained``
            points).
        chosen: index of the hypothesis nearest ``pose``.
        pose: (3,) the target pose (x, y, yaw) to grasp at (see
            :func:`~stucco_drake.core.grasp_choice.choose_grasp`).
        motion_scales: (k,) each hypothesis's motion scale (see
            :mod:`~stucco_drake.core.motion_scale`); None when the points were taken as
            tracked.
        felt: (n, 2) every contact point the hypotheses were made from, placed as the chosen
            hypothesis places them (at its motion scale): where something was felt, whatever
            it is (None: not given).
    """

    poses: np.ndarray
    costs: np.ndarray
    weights: np.ndarray
    explained: np.ndarray
    confidence: float
    chosen: int
    pose: np.ndarray
    motion_scales: np.ndarray | None = None
    felt: np.ndarray | None = None

    def unexplained_points(self, sensed, tracked) -> np.ndarray:
        """(m, 3) the contact points the chosen hypothesis does not put on the target (the
        clutter a grasp keeps clear of), in W (m): each placed at that hypothesis's motion
        scale between where it was ``sensed`` and where it is ``tracked`` ((n, 3) each, the
        first n the hypotheses were made from)."""
        n = self.explained.shape[1]
        sensed = np.asarray(sensed, dtype=np.float64)[:n]
        tracked = np.asarray(tracked, dtype=np.float64)[:n]
        scale = 1.0 if self.motion_scales is None else self.motion_scales[self.chosen]
        placed = sensed + scale * (tracked - sensed)
        return placed[~self.explained[self.chosen]]


def point_spread(particle_points, log_weights) -> np.ndarray:
    """(n,) each contact point's weighted RMS distance (m) from its mean over the particles
    (``particle_points`` (P, n, 3) m, ``log_weights`` (P,))."""
    weights = np.exp(np.asarray(log_weights, dtype=np.float64) - np.max(log_weights))
    weights /= weights.sum()
    points = np.asarray(particle_points, dtype=np.float64)
    mean = np.einsum("p,pni->ni", weights, points)
    return np.sqrt(np.einsum("p,pn->n", weights, np.sum((points - mean) ** 2, axis=-1)))


def tracker_spread(tracker) -> np.ndarray | None:
    """:func:`point_spread` of a tracker that holds particles (``points`` (P, n, 3) and
    ``log_weights`` (P,), as :class:`~stucco_drake.core.soft_tracker.SoftTracker`); None for
    one that does not (the clustering baselines) or holds no point."""
    if not (hasattr(tracker, "points") and hasattr(tracker, "log_weights")):
        return None
    if tracker.n_contacts == 0:
        return None
    return point_spread(tracker.points, tracker.log_weights)


def contact_costs(poses, points, sigma, shape, params: HypothesisParams, light=None):
    """(B,) contact cost of each pose and (B, n) which points it explains (see the module);
    ``light`` (n,) bool: points that cannot lie on the target (None: none)."""
    d = cross_section_sdf(shape)(to_pose_frames(poses, points[:, :2]))
    on_surface = d**2 / (2.0 * sigma**2) + np.log(sigma / params.contact_noise)
    if light is not None:
        on_surface = np.where(light, np.inf, on_surface)
    elsewhere = params.other_object_cost + np.minimum(d, 0.0) ** 2 / (2.0 * sigma**2)
    explained = on_surface < elsewhere
    return np.minimum(on_surface, elsewhere).sum(axis=1), explained


def grid_candidates(points, sigma, shape, params: HypothesisParams, swept=None,
                    point_steps=None, fill=None, fill_weight: float = 1.0,
                    light=None) -> np.ndarray:  # fmt: skip
    """The ``n_candidates`` poses of lowest contact and free-space cost on a grid
    (``grid_spacing``, ``grid_yaw``) of every placement whose outline could reach a tracked
    point: the search that ICP's local fits on segments can miss (a segment holding clutter
    pulls them off). Free space (None: none) is judged on the cross-section points ``fill``,
    its cost times ``fill_weight``; ``light`` as :func:`contact_costs`'s."""
    reach = outline_extent(shape) / 2.0
    lower, upper = points[:, :2].min(axis=0) - reach, points[:, :2].max(axis=0) + reach
    axes = [np.arange(lo, hi + 1e-12, params.grid_spacing)
            for lo, hi in zip(lower, upper, strict=True)]
    if isinstance(shape, CylinderSdf) and np.allclose(shape.center[:2], 0.0):
        yaws = np.zeros(1)  # a centred cylinder looks the same at every yaw
    else:
        # A centred box repeats after a half turn.
        period = np.pi if np.allclose(shape.center[:2], 0.0) else 2.0 * np.pi
        yaws = np.arange(0.0, period, params.grid_yaw)
    centres = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 2)
    # A placement can explain a point only if the point lies within the outline's reach of
    # its centre; one that cannot explain enough points to pin a pose is not searched.
    nearby = cKDTree(points[:, :2]).query_ball_point(centres, reach + params.contact_noise,
                                                     return_length=True)  # fmt: skip
    centres = centres[nearby >= params.min_explained]
    grid = np.column_stack([np.repeat(centres, len(yaws), axis=0),
                            np.tile(yaws, len(centres))])  # fmt: skip
    if len(grid) == 0:
        return grid
    block = max(1, (1 << 21) // len(points))  # bounded memory: poses x points per block
    costs = np.empty(len(grid))
    for k in range(0, len(grid), block):
        contact, explained = contact_costs(grid[k:k + block], points, sigma, shape, params,
                                           light)  # fmt: skip
        costs[k:k + block] = contact + fill_weight * free_space_costs(
            grid[k:k + block], explained, swept, point_steps, fill, params)
    keep = min(params.n_candidates, len(grid))
    return grid[np.argsort(costs, kind="stable")[:keep]]


def _polish(rng, poses, points, sigma, shape, outline, params: HypothesisParams, light=None):
    """Each pose refitted by ICP on the points it explains, explained again, up to
    ``polish_iterations`` times (an EM of point assignment and pose)."""
    polished = []
    for pose in poses:
        for _ in range(params.polish_iterations):
            _, explained = contact_costs(pose[None], points, sigma, shape, params, light)
            if explained[0].sum() < params.min_explained:
                break
            fitted = icp_2d(rng, points[explained[0], :2], outline, 1, initial_pose=pose)
            if np.allclose(fitted.poses[0], pose, rtol=0.0, atol=1e-6):
                break
            pose = fitted.poses[0]
        polished.append(pose)
    return np.array(polished).reshape(-1, 3)


def _proposal_groups(points, labels, reach: float, min_points: int) -> list[np.ndarray]:
    """Index arrays of the points ICP fits: each segment (split where wider than ``reach``)
    and each union of two whose points span at most ``reach``."""
    labels = split_wider_segments(points, labels, reach)
    singles = [np.flatnonzero(labels == label) for label in np.unique(labels[labels >= 0])]
    groups = [g for g in singles if len(g) >= min_points]
    for first, second in itertools.combinations(singles, 2):
        union = np.concatenate([first, second])
        if len(union) >= min_points and xy_extent(points[union]) <= reach:
            groups.append(union)
    return groups


def _outline_gaps(distance, outline, poses_a, poses_b) -> np.ndarray:
    """(P,) largest distance (m) from the outline posed at each ``poses_b`` to the
    cross-section posed at the matching ``poses_a`` (``distance`` its 2-D signed distance in its
    own frame): for two poses of one shape, their outlines' Hausdorff distance up to the
    outline's sampling when taken both ways."""
    posed = transform(poses_b, outline)
    return np.abs(distance(to_pose_frames(poses_a, posed))).max(axis=1)


def _agreement(distance, outline, poses_a, poses_b) -> np.ndarray:
    """(P,) symmetric outline distance (m) of matching pose pairs (see :func:`_outline_gaps`)."""
    return np.maximum(_outline_gaps(distance, outline, poses_a, poses_b),
                      _outline_gaps(distance, outline, poses_b, poses_a))  # fmt: skip


def _distinct(poses, shape, outline, resolution: float) -> np.ndarray:
    """``poses`` without near-duplicates: a pose whose outline lies within ``resolution`` (m)
    of an earlier kept one's (:func:`_outline_gap`) is dropped (a box turned by pi, a cylinder
    at any yaw). Only poses whose outline centroids lie within ``resolution`` are compared."""
    distance = cross_section_sdf(shape)
    centres = transform(poses, outline).mean(axis=1)
    kept: list[int] = []
    for b in range(len(poses)):
        near = [kept[k] for k in np.flatnonzero(
            np.hypot(*(centres[kept] - centres[b]).T) <= resolution)] if kept else []
        if not near or _agreement(distance, outline, poses[near],
                                  np.repeat(poses[b:b + 1], len(near), axis=0)).min() > resolution:
            kept.append(b)
    return poses[kept]


def pose_hypotheses(rng: np.random.Generator, points, labels, shape: BoxSdf | CylinderSdf,
                    *, spread=None, free_space: FreeSpace | None = None,
                    params: HypothesisParams | None = None, point_forces=None,
                    ) -> PoseHypotheses | None:  # fmt: skip
    """Weighted target-pose hypotheses from tracked contact points (see the module).

    Args:
        rng: caller-seeded generator for the ICP starts.
        points: (n, 3) tracked contact points in W (m), e.g. the MAP particle's.
        labels: (n,) their segment labels (negative: noise, proposing nothing).
        shape: the target's known geometry in its frame O.
        spread: (n,) each point's spread over the tracker's particles (m; see
            :func:`point_spread`); None for none.
        free_space: where the robot has been (None: contact evidence only).
        params: the settings (None: the defaults).
        point_forces: (n,) the peak force (N) of the action that sensed each point (NaN:
            unknown), judged against ``params.light_force``; None for none.

    Returns:
        The hypotheses, or None when no placement of the target can touch ``min_explained``
        points (a segment's points lie farther apart than the target could span).

    Raises:
        ValueError: naming the argument, e.g. no segment with ``min_explained`` points.
    """
    params = params or HypothesisParams()
    found = search_hypotheses(rng, points, labels, shape, spread=spread, free_space=free_space,
                              params=params, point_forces=point_forces)  # fmt: skip
    if found is None:
        return None
    return dataclasses.replace(weigh_hypotheses(*found, shape, params),
                               felt=np.asarray(points, dtype=np.float64)[:, :2].copy())


def search_hypotheses(rng: np.random.Generator, points, labels, shape: BoxSdf | CylinderSdf,
                      *, spread=None, free_space: FreeSpace | None = None,
                      params: HypothesisParams | None = None, carried=None,
                      height: float | None = None, point_forces=None):  # fmt: skip
    """The poses :func:`pose_hypotheses` weighs, with their costs and the points each explains
    ((k, 3), (k,), (k, n)), before any is left out; None when no placement can touch
    ``min_explained`` points. Arguments and errors as :func:`pose_hypotheses`'s; ``carried``
    (n, 3): how far each point was moved from where it was sensed (None: not at all), which
    the gripper that met it is moved by too when its contact location is scored; ``height``:
    of the horizontal slice (m, W) on which free space is judged (None: the points' mean)."""
    params = params or HypothesisParams()
    points = as_finite_array(points, "points", (None, 3))
    labels = np.asarray(labels)
    if labels.shape != (len(points),) or not np.issubdtype(labels.dtype, np.integer):
        raise ValueError(f"labels: expected {len(points)} integer labels, got {labels.shape}")
    spread = np.zeros(len(points)) if spread is None else as_finite_array(
        spread, "spread", (len(points),))  # fmt: skip
    sigma = np.sqrt(params.contact_noise**2 + spread**2)
    reach = outline_extent(shape) + 3.0 * params.contact_noise
    if np.bincount(labels[labels >= 0], minlength=1).max() < params.min_explained:
        raise ValueError(f"labels: no segment has at least {params.min_explained} points")
    light = light_points(point_forces, len(points), params)
    groups = _proposal_groups(points, labels, reach, params.min_explained)
    outline = sample_outline(shape, params.outline_spacing)
    # Hypotheses are compared on a coarser outline, and count as one within its spacing.
    coarse = sample_outline(shape, params.fill_spacing)
    fill = sample_cross_section(shape, params.fill_spacing)
    height = float(points[:, 2].mean()) if height is None else float(height)
    swept = swept_slice(free_space, height, params)
    steps = None if free_space is None else np.asarray(free_space.point_steps)

    located = location_costs_of(free_space, fill, points, carried, params.contact_location_noise)

    def scored(poses):
        poses = _distinct(poses, shape, coarse, params.fill_spacing)
        contact, explained = contact_costs(poses, points, sigma, shape, params, light)
        costs = contact + free_space_costs(poses, explained, swept, steps, fill, params)
        return poses, costs + (0.0 if located is None else located(poses, explained)), explained

    fits = [icp_2d(rng, points[g, :2], outline, params.n_restarts).poses for g in groups]
    # The grid only ranks placements 1 cm apart: its free space is judged on a fill twice as
    # sparse, each point counting for the points it stands for.
    sparse = sample_cross_section(shape, 2.0 * params.fill_spacing)
    grid = grid_candidates(points, sigma, shape, params, swept, steps, sparse,
                           len(fill) / len(sparse), light)  # fmt: skip
    candidates = np.concatenate([*fits, grid])
    if len(candidates) == 0:
        return None
    poses, costs, _ = scored(candidates)
    best = poses[np.argsort(costs, kind="stable")[:params.n_polish]]
    poses, costs, explained = scored(np.concatenate(
        [poses, _polish(rng, best, points, sigma, shape, outline, params, light)]))
    return poses, costs, explained


def light_points(point_forces, n: int, params: HypothesisParams) -> np.ndarray | None:
    """(n,) whether each point was sensed in an action whose peak force (``point_forces``
    (n,), N; NaN: unknown, never light) stayed below ``params.light_force``; None when either
    is None. ValueError naming ``point_forces`` unless it holds n values."""
    if point_forces is None or params.light_force is None:
        return None
    forces = np.asarray(point_forces, dtype=np.float64)
    if forces.shape != (n,):
        raise ValueError(f"point_forces: expected ({n},) peak forces, got {forces.shape}")
    return forces < params.light_force  # NaN compares False


def weigh_hypotheses(poses, costs, explained, shape: BoxSdf | CylinderSdf,
                     params: HypothesisParams, motion_scales=None) -> PoseHypotheses:  # fmt: skip
    """The :class:`PoseHypotheses` of scored poses ((k, 3), costs (k,), explained (k, n)):
    those within ``15 temperature`` of the cheapest that explain ``min_explained`` points,
    cheapest first, weighed, with the grasp chosen across them (``motion_scales`` (k,): each
    pose's, kept alongside)."""
    margin = 15.0 * params.temperature  # weights below e^-15 of the best's count as none
    # Hypotheses weighing under e^-15 of the best, or explaining too few points to pin a
    # pose, carry no information: left out.
    pinned = explained.sum(axis=1) >= params.min_explained
    rivals = (poses[pinned], costs[pinned])  # what a tempered confidence is formed over
    keep = (costs <= costs.min() + margin) & pinned
    keep |= costs == costs.min()
    order = np.flatnonzero(keep)[np.argsort(costs[keep], kind="stable")]
    poses, costs, explained = poses[order].copy(), costs[order], explained[order]
    weights = cost_weights(costs, params.temperature)
    # One grasp is made: where it closes on the target under the most weight (the cheapest
    # among equals). Its probability of closing on the target is the confidence.
    choice = choose_grasp(poses, weights, shape, margin=params.grasp_margin,
                          angle_margin=params.grasp_angle_margin)  # fmt: skip
    chosen = _nearest(poses, choice.target_pose)
    confidence = choice.probability
    if params.confidence_temperature is not None and len(rivals[0]):
        confidence = tempered_confidence(choice.grasp, *rivals, shape, params)
    if explained[chosen].sum() < params.min_explained:
        confidence = 0.0
    poses[:, 2] = (poses[:, 2] + np.pi) % (2.0 * np.pi) - np.pi
    target = choice.target_pose.copy()
    target[2] = (target[2] + np.pi) % (2.0 * np.pi) - np.pi
    scales = None if motion_scales is None else np.asarray(motion_scales)[order]
    return PoseHypotheses(poses, costs, weights, explained, confidence, chosen, target, scales)


def _nearest(poses, pose) -> int:
    """Index of the hypothesis nearest ``pose`` (position; the first among equals)."""
    return int(np.argmin(np.hypot(*(poses[:, :2] - pose[:2]).T)))
