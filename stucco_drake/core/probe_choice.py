"""Which probe tells the target's pose hypotheses apart: the touch whose outcome they disagree on.

A probe planned on the likeliest pose alone confirms it: if clutter stands where that pose puts
a face, the touch lands there and counts for it. A probe is informative when the hypotheses
predict different outcomes for it. Here each hypothesis predicts one outcome of a guarded
approach (:class:`~stucco_drake.core.probing.FaceProbePolicy`): how far along the approach the
gripper's footprint first meets the target posed there, or that the gripper bumps it on the
way to the stand-off point, or that it never meets it (the approach passes through where the
hypothesis is not). Outcomes within ``tolerance`` of each other count as one. The outcome is
a deterministic function of the hypothesis, so a probe's expected information gain about the
hypotheses is the entropy of its outcome's distribution under their weights; the probe of
most gain is made. A probe that passes through where a hypothesis puts the target and senses
nothing is the strongest evidence there is: free space (:mod:`~.free_space`) then rules that
pose out.

The estimator's weights are sharp (cost differences of a few units decide) while its model of
the contacts is rough, so the gain is judged on weights tempered by ``temperature``: a rival a
few units behind still gets probed. Everything is planar: points (x, y) in the world frame W
(m), yaw about world z (rad).
"""

from __future__ import annotations

import itertools

import numpy as np
from scipy.spatial import ConvexHull

from stucco_drake.core.coverage import waypoint_steps
from stucco_drake.core.hypothesis_weights import cost_weights
from stucco_drake.core.icp import (
    cross_section_sdf,
    rotations,
    sample_outline,
    to_pose_frames,
    transform,
)

#: Outcome of a hypothesis under which the gripper meets the target before the approach.
BUMP = -1.0


def footprint_outline(footprint, spacing: float = 0.003) -> tuple[np.ndarray, np.ndarray]:
    """The gripper's planar footprint (m, 2) as its convex hull: points along the hull's
    boundary every ``spacing`` (m) and the hull's half-planes ((h, 3): a x + b y + c <= 0
    inside)."""
    footprint = np.asarray(footprint, dtype=np.float64).reshape(-1, 2)
    hull = ConvexHull(footprint)
    corners = footprint[hull.vertices]
    return _along(np.concatenate([corners, corners[:1]]), spacing)[:-1], hull.equations


def _along(points, spacing: float) -> np.ndarray:
    """(q, 2) the polyline through ``points`` (k, 2) sampled every ``spacing`` (m) or less,
    its vertices and both ends included."""
    points = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    samples = []
    for a, b in itertools.pairwise(points):
        n = max(1, int(np.ceil(np.linalg.norm(b - a) / spacing)))
        samples.append(a + np.linspace(0.0, 1.0, n, endpoint=False)[:, None] * (b - a))
    return np.concatenate([*samples, points[-1:]])


def footprint_meets(positions, outline, half_planes, poses, shape) -> np.ndarray:
    """(P, S) whether the footprint at each of ``positions`` (S, 2) overlaps the target's
    cross-section posed at each of ``poses`` (P, 3): a boundary point of the footprint inside
    the target, or a point of the target's outline inside the footprint."""
    positions = np.asarray(positions, dtype=np.float64).reshape(-1, 2)
    poses = np.asarray(poses, dtype=np.float64).reshape(-1, 3)
    distance = cross_section_sdf(shape)
    # The footprint's boundary at each position (S, m, 2), in each target frame (P, S m, 2).
    posed = positions[:, None, :] + outline[None, :, :]
    local = to_pose_frames(poses, posed.reshape(-1, 2))
    inside = distance(local).reshape(len(poses), *posed.shape[:2]) < 0.0
    meets = inside.any(axis=2)
    # The target's outline in the footprint's frame: (P, S, k, 2).
    target = sample_outline(shape, 0.005)
    world = transform(poses, target)
    rel = world[:, None, :, :] - positions[None, :, None, :]
    within = np.all(rel @ half_planes[:, :2].T + half_planes[:, 2] <= 0.0, axis=-1)
    return meets | within.any(axis=2)


def felt_meets(positions, felt, half_planes, margin: float) -> np.ndarray:
    """(S,) whether the footprint at each of ``positions`` (S, 2) holds a point of ``felt``
    ((o, 2) W) more than ``margin`` (m) inside it: the gripper there would meet what was felt
    (its half-planes ``half_planes`` as :func:`footprint_outline`'s)."""
    positions = np.asarray(positions, dtype=np.float64).reshape(-1, 2)
    felt = np.asarray(felt, dtype=np.float64).reshape(-1, 2)
    if len(felt) == 0 or len(positions) == 0:
        return np.zeros(len(positions), dtype=bool)
    rel = felt[None, :, :] - positions[:, None, :]  # (S, o, 2)
    depth = rel @ half_planes[:, :2].T + half_planes[:, 2]  # (S, o, h), <= 0 inside
    return np.any(np.all(depth <= -margin, axis=-1), axis=1)


def probe_outcomes(path, approach_start, normal, travel: float, poses, shape, outline,
                   half_planes, spacing: float = 0.0025, felt=None,
                   felt_margin: float = 0.005) -> np.ndarray:  # fmt: skip
    """(P,) each posed hypothesis's outcome of one probe: :data:`BUMP` when the footprint meets
    it on the ``path`` ((q, 2) W, sampled travel to the stand-off point), else the distance (m)
    along the approach (from ``approach_start`` along ``-normal``, ``travel`` long) at which it
    first meets it, inf when it never does.

    ``felt`` ((o, 2) W, None: none): points where something was felt. Whatever the target's
    pose, the gripper meets what stands there (:func:`felt_meets`, ``felt_margin`` inside the
    footprint), so a travel through one bumps under every hypothesis and an approach ends
    there at the latest: a probe whose outcome is known already gains nothing."""
    steps = np.arange(0.0, travel + 1e-9, spacing)
    approach = np.asarray(approach_start)[None] - steps[:, None] * np.asarray(normal)[None]
    outcomes = np.full(len(poses), np.inf)
    if len(path):
        bumped = footprint_meets(path, outline, half_planes, poses, shape).any(axis=1)
    else:
        bumped = np.zeros(len(poses), dtype=bool)
    met = footprint_meets(approach, outline, half_planes, poses, shape)
    first = np.argmax(met, axis=1)
    hit = met.any(axis=1)
    outcomes[hit] = steps[first[hit]]
    if felt is not None:
        if felt_meets(path, felt, half_planes, felt_margin).any():
            bumped[:] = True
        blocked = felt_meets(approach, felt, half_planes, felt_margin)
        if blocked.any():
            outcomes = np.minimum(outcomes, steps[np.argmax(blocked)])
    outcomes[bumped] = BUMP
    return outcomes


def outcome_entropy(outcomes, weights, tolerance: float) -> float:
    """Entropy (nats) of the outcome under the hypotheses' ``weights``, outcomes within
    ``tolerance`` (m) of their neighbour in sorted order counting as one (a bump and no
    contact each one outcome): the probe's expected information gain."""
    outcomes = np.asarray(outcomes, dtype=np.float64)
    weights = np.asarray(weights, dtype=np.float64) / np.sum(weights)
    order = np.argsort(outcomes, kind="stable")
    sorted_outcomes = outcomes[order]
    finite = np.isfinite(sorted_outcomes) & (sorted_outcomes != BUMP)
    # A new group wherever the outcome jumps by more than the tolerance, or its kind changes.
    jumps = np.ones(len(order), dtype=bool)
    jumps[1:] = ~(finite[1:] & finite[:-1]
                  & (np.diff(np.where(finite, sorted_outcomes, 0.0)) <= tolerance))
    jumps[1:] &= ~(~finite[1:] & ~finite[:-1]
                   & (sorted_outcomes[1:] == sorted_outcomes[:-1]))
    group = np.cumsum(jumps) - 1
    mass = np.bincount(group, weights=weights[order])
    mass = mass[mass > 0]
    return float(-(mass * np.log(mass)).sum())


def face_probe_points(centre, half, yaw: float, footprint, step: float,
                      min_overlap: float = 0.01) -> tuple[np.ndarray, np.ndarray]:
    """Candidate touches of every face of a box (``centre`` (2,) W, ``half`` extents (2,)
    along its axes at ``yaw``) as (points (k, 2), outward normals (k, 2)), W: the gripper's
    origin every ``step`` (m) along each face's line, from the face's middle out to where
    the footprint ((m, 2) about its origin) still overlaps the face by ``min_overlap`` (m).
    A touch off a face's middle is what tells a box from a turned one: the gripper, wider
    than the box's end face, passes beside it where the turned box's long face stands."""
    footprint = np.asarray(footprint, dtype=np.float64).reshape(-1, 2)
    R = rotations(float(yaw))
    points, normals = [], []
    for axis, sign in ((0, 1.0), (0, -1.0), (1, 1.0), (1, -1.0)):
        normal, tangent = np.zeros(2), np.zeros(2)
        normal[axis], tangent[1 - axis] = sign, 1.0
        normal, tangent = R @ normal, R @ tangent
        length = half[1 - axis]
        reach_up = length + float(np.max(footprint @ -tangent)) - min_overlap
        reach_down = length + float(np.max(footprint @ tangent)) - min_overlap
        offsets = np.concatenate([-np.arange(0.0, reach_down, step)[::-1][:-1],
                                  np.arange(0.0, reach_up, step)])  # fmt: skip
        face = np.asarray(centre) + normal * half[axis]
        points.extend(face + offsets[:, None] * tangent)
        normals.extend(np.repeat(normal[None], len(offsets), axis=0))
    return np.array(points), np.array(normals)


def most_informative(candidates, poses, costs, shape, footprint, *,
                     temperature: float, tolerance: float, overshoot: float,
                     start, felt=None, steps=None,
                     least_gain: float = 0.0) -> tuple[float, object, list] | None:  # fmt: skip
    """The candidate probe of most expected information gain about the hypotheses (``poses``
    (P, 3) W with ``costs`` (P,), tempered by ``temperature``) and its travel, as (gain,
    probe, waypoints); None without candidates. With ``steps``, the probe of most gain per
    action it takes.

    Args:
        candidates: (probe, approach start (2,), travel waypoints ending there) of each probe
            the gripper can make (``probe.point`` and outward ``probe.normal`` (2,) W), in
            order of preference (the first of equal gains is taken).
        shape: the target's geometry; footprint: (m, 2) the gripper's about its origin (W axes).
        tolerance: approach distances (m) counting as one outcome.
        overshoot: how far (m) past the probed face the approach goes.
        start: (2,) where the gripper is (W).
        felt: (o, 2) points where something was felt (W; None: none), met by the gripper
            under every hypothesis (:func:`probe_outcomes`).
        steps: (travel, approach) longest step per action (m): the probe's actions are its
            travel's legs cut at the travel step per axis (as the gripper plays them) and
            its approach cut at the approach step, plus the retreat. None: the gain alone.
        least_gain: a probe gaining less (nats) is not chosen (None when none gains as much).
    """
    outline, half_planes = footprint_outline(footprint)
    weights = cost_weights(costs, temperature)
    best = None
    for probe, far, waypoints in candidates:
        # The travel's first centimetre is where the gripper backs off from a touch: a pose a
        # few millimetres off the touched face would count as bumped there.
        path = _along([start, *waypoints], 0.005)
        path = path[np.linalg.norm(path - start, axis=1) >= 0.01]
        support = float(np.max(np.asarray(footprint) @ -np.asarray(probe.normal)))
        travel = float((far - probe.point) @ probe.normal) - support + overshoot
        outcomes = probe_outcomes(path, far, probe.normal, travel, poses, shape, outline,
                                  half_planes, felt=felt)  # fmt: skip
        gain = outcome_entropy(outcomes, weights, tolerance)
        if gain < least_gain:
            continue
        score = gain
        if steps is not None:
            actions = len(waypoint_steps(start, waypoints, steps[0]))
            score = gain / (actions + np.ceil(travel / steps[1] - 1e-9) + 1)
        if best is None or score > best[3] + 1e-9:
            best = (gain, probe, waypoints, score)
    return None if best is None else best[:3]


__all__ = ["BUMP", "face_probe_points", "felt_meets", "footprint_meets", "footprint_outline",
           "most_informative", "outcome_entropy", "probe_outcomes"]
