"""Hypotheses over poses and motion scales, on synthetic scenes whose truth is known exactly:
a 16 x 8 cm box that never moved while the tracker carried its points inward, and a box
pushed 3 cm that the tracker followed."""

from __future__ import annotations

import numpy as np
import pytest

from stucco_drake.core.free_space import FreeSpace
from stucco_drake.core.hypothesis_params import HypothesisParams
from stucco_drake.core.icp import rotations
from stucco_drake.core.motion_scale import (
    GRAVITY,
    MOTION_SCALES,
    check_light_force,
    motion_scaled_hypotheses,
    scales_under_push_limit,
)
from stucco_drake.core.pose_hypotheses import pose_hypotheses
from stucco_drake.core.shapes import BoxSdf

BOX = BoxSdf((0.08, 0.04, 0.05))
TRUE_POSE = np.array([0.5, 0.1, 0.3])
HEIGHT = 0.05
NOISE = 0.0015  # m, below the estimator's 4 mm contact noise


def _world(local_xy, pose, rng) -> np.ndarray:
    world = local_xy @ rotations(pose[2]).T + pose[:2] + rng.normal(0.0, NOISE, local_xy.shape)
    return np.column_stack([world, np.full(len(world), HEIGHT)])


def _two_faces() -> np.ndarray:
    """Points on the box's long face (y = -4 cm) and short face (x = 8 cm), box frame."""
    long_face = np.column_stack([np.linspace(-0.06, 0.06, 9), np.full(9, -0.04)])
    short_face = np.column_stack([np.full(5, 0.08), np.linspace(-0.03, 0.03, 5)])
    return np.vstack([long_face, short_face])


def _error(pose) -> tuple[float, float]:
    turn = (pose[2] - TRUE_POSE[2] + np.pi / 2) % np.pi - np.pi / 2
    return float(np.hypot(*(pose[:2] - TRUE_POSE[:2]))), abs(float(turn))


def test_a_box_that_never_moved_is_found_where_its_points_were_sensed():
    """The tracker moved each point by the gripper's travel after it was sensed, up to 2 cm
    along the slide and 1.5 cm into the box for the first (as a gripper sliding along a
    heavy box makes it): the tracked points fit no box well, nor the truth; the scale 0
    (never moved) explains the sensed points exactly."""
    rng = np.random.default_rng(0)
    sensed = _world(_two_faces(), TRUE_POSE, rng)
    later = np.linspace(1.0, 0.0, len(sensed))[:, None]  # share of the travel still to come
    drift = later * (np.array([0.02, 0.015]) @ rotations(TRUE_POSE[2]).T)  # box -> world
    tracked = sensed + np.column_stack([drift, np.zeros(len(sensed))])
    labels = np.zeros(len(sensed), dtype=np.int64)
    as_tracked = pose_hypotheses(np.random.default_rng(1), tracked, labels, BOX)
    assert _error(as_tracked.pose)[0] > 0.005  # fitted where the tracker put the points
    found = motion_scaled_hypotheses(np.random.default_rng(1), sensed, tracked, labels, BOX)
    position, yaw = _error(found.pose)
    # Fourteen points at 1.5 mm noise on two faces: a few millimetres and a couple of degrees.
    assert position < 0.004 and yaw < np.radians(2.0), (position, np.degrees(yaw))
    assert found.motion_scales[found.chosen] == 0.0
    # A quarter of the drift (5 mm at most) is within the estimator's 4 mm noise, so the
    # scales near 0 share the weight; the most goes to 0 and little to the tracked places.
    by_scale = {a: found.weights[found.motion_scales == a].sum() for a in (0, 0.25, 0.5, 1)}
    assert max(by_scale, key=by_scale.get) == 0 and by_scale[1] < 0.05, by_scale
    assert found.weights.sum() == pytest.approx(1.0)


def test_a_pushed_box_is_found_where_the_tracker_followed_it():
    """Sensed at its start, pushed 3 cm along its short axis, tracked to the truth: the scale
    1 (moved as tracked) wins; the sensed places fit the start pose, which free space does
    not rule out here, so the contact evidence alone must decide."""
    rng = np.random.default_rng(2)
    push = np.array([0.0, 0.03]) @ rotations(TRUE_POSE[2]).T
    start = TRUE_POSE - np.append(push, 0.0)
    local = _two_faces()
    sensed = _world(local, start, rng)
    tracked = _world(local, TRUE_POSE, rng)
    # Half the points were sensed after the push (where they are tracked): only a box that
    # moved explains both halves on one outline.
    sensed[::2] = tracked[::2]
    labels = np.zeros(len(sensed), dtype=np.int64)
    found = motion_scaled_hypotheses(np.random.default_rng(3), sensed, tracked, labels, BOX)
    position, yaw = _error(found.pose)
    assert position < 0.004 and yaw < np.radians(2.0), (position, np.degrees(yaw))
    assert found.motion_scales[found.chosen] == 1.0


def test_free_space_is_judged_where_the_points_were_sensed_once_for_every_scale(
        disc_penetration):  # fmt: skip
    """The tracker carried the points 3 cm up as well as along (a contact-motion model's
    vertical part; objects slide on the table): every scale is judged on one slice of the free
    space, at the sensed points' mean height, built once."""
    rng = np.random.default_rng(2)
    sensed = _world(_two_faces(), TRUE_POSE, rng)
    tracked = sensed + np.array([0.01, 0.0, 0.03])
    labels = np.zeros(len(sensed), dtype=np.int64)
    configs = np.array([[0.3, -0.1, HEIGHT], [0.3, 0.3, HEIGHT]])
    free = FreeSpace(disc_penetration, configs, None, np.zeros(len(sensed), dtype=np.int64))
    found = motion_scaled_hypotheses(np.random.default_rng(3), sensed, tracked, labels, BOX,
                                     free_space=free)  # fmt: skip
    assert set(found.motion_scales) == {0.0, 0.25, 0.5, 0.75, 1.0}
    assert len(free.slices) == 1
    (height, *_), = free.slices
    assert height == pytest.approx(HEIGHT, abs=1e-12)  # not HEIGHT + 0.03 x scale


def test_a_carry_that_fits_as_well_as_no_motion_costs_the_log_of_its_spread():
    """Noise-free points on two faces, carried rigidly 3 cm along the long face: the sensed and
    the carried points fit the outline exactly, so the only difference between the best
    hypotheses at scales 0 and 1 is each explained point's Gaussian normaliser,
    log(sqrt(noise^2 + (transport_noise * 3 cm)^2) / noise): 14 * 0.409 = 5.73 at the
    defaults (4 mm, 0.15). ICP on a 2 mm outline leaves a fraction of a millimetre: 0.1 of
    tolerance on the cost. The smaller motion is the one chosen."""
    params = HypothesisParams()
    sensed = np.column_stack([_two_faces() @ rotations(TRUE_POSE[2]).T + TRUE_POSE[:2],
                              np.full(14, HEIGHT)])  # fmt: skip
    carry = np.append(np.array([0.03, 0.0]) @ rotations(TRUE_POSE[2]).T, 0.0)
    tracked = sensed + carry
    labels = np.zeros(len(sensed), dtype=np.int64)
    best = {scale: motion_scaled_hypotheses(np.random.default_rng(4), sensed, tracked, labels,
                                            BOX, scales=(scale,)).costs[0]
            for scale in (0.0, 1.0)}  # fmt: skip
    spread = np.hypot(params.contact_noise, params.transport_noise * 0.03)
    expected = len(sensed) * np.log(spread / params.contact_noise)
    assert best[1.0] - best[0.0] == pytest.approx(expected, abs=0.1)
    found = motion_scaled_hypotheses(np.random.default_rng(4), sensed, tracked, labels, BOX)
    assert found.motion_scales[found.chosen] == 0.0
    assert _error(found.pose)[0] < 0.002


def test_bad_scales_or_shapes_are_one_line_errors():
    points = np.zeros((4, 3))
    labels = np.zeros(4, dtype=np.int64)
    with pytest.raises(ValueError, match="scales"):
        motion_scaled_hypotheses(np.random.default_rng(0), points, points, labels, BOX,
                                 scales=(0.0, 1.5))  # fmt: skip
    with pytest.raises(ValueError, match="tracked"):
        motion_scaled_hypotheses(np.random.default_rng(0), points, points[:3], labels, BOX)


def test_a_target_the_push_limit_cannot_slide_is_searched_where_sensed():
    # Sliding needs mu m g: 0.5 * 10 kg * 9.81 m/s^2 = 49 N against a 30 N push (the paper's
    # cap): only scale 0. A 2 kg can needs 9.8 N: every scale. So does any target unlimited.
    assert scales_under_push_limit(10.0, 0.5, 30.0) == (0.0,)
    assert scales_under_push_limit(2.0, 0.5, 30.0) == MOTION_SCALES
    assert scales_under_push_limit(10.0, 0.5, None) == MOTION_SCALES
    # The boundary: 30 N slides exactly 30 / (0.5 * 9.81) = 6.116 kg; 1 g either side.
    limit = 30.0 / (0.5 * GRAVITY)
    assert scales_under_push_limit(limit + 1e-3, 0.5, 30.0) == (0.0,)
    assert scales_under_push_limit(limit - 1e-3, 0.5, 30.0) == MOTION_SCALES
    with pytest.raises(ValueError, match="mass"):
        scales_under_push_limit(0.0, 0.5, 30.0)


def test_a_light_force_above_half_the_targets_sliding_force_is_refused():
    # A 2 kg can at friction 0.5 slides under 9.81 N: half is 4.905 N. The 10 kg box's half,
    # 24.5 N, leaves room for any light_force below it.
    check_light_force(4.9, 2.0, 0.5)
    check_light_force(None, 0.1, 0.5)
    check_light_force(24.5, 10.0, 0.5)
    with pytest.raises(ValueError, match=r"light_force: 4.91 N is more than half .* \(4.91 N"):
        check_light_force(4.91, 2.0, 0.5)
