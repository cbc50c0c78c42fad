"""Target-pose hypotheses from contact and free-space evidence, on synthetic scenes whose true
pose is known exactly (a 16 x 8 cm box, a 5 cm can, a 2 cm disc gripper)."""

from __future__ import annotations

import numpy as np
import pytest

from stucco_drake.core.free_space import FreeSpace
from stucco_drake.core.hypothesis_params import HypothesisParams
from stucco_drake.core.icp import rotations
from stucco_drake.core.pose_hypotheses import (
    PoseHypotheses,
    point_spread,
    pose_hypotheses,
    weigh_hypotheses,
)
from stucco_drake.core.shapes import BoxSdf, CylinderSdf

BOX = BoxSdf((0.08, 0.04, 0.05))
TRUE_POSE = np.array([0.5, 0.1, 0.3])
HEIGHT = 0.05
NOISE = 0.0015  # m: contact noise of the synthetic points, below the estimator's 4 mm


def _on_box(local_xy, rng) -> np.ndarray:
    """Points given in the box frame, posed at TRUE_POSE with NOISE, at contact height."""
    world = local_xy @ rotations(TRUE_POSE[2]).T + TRUE_POSE[:2]
    world += rng.normal(0.0, NOISE, world.shape)
    return np.column_stack([world, np.full(len(world), HEIGHT)])


def _pose_error(pose) -> tuple[float, float]:
    """Position error (m) and yaw error modulo the box's half-turn symmetry (rad)."""
    turn = (pose[2] - TRUE_POSE[2] + np.pi / 2) % np.pi - np.pi / 2
    return float(np.hypot(*(pose[:2] - TRUE_POSE[:2]))), abs(float(turn))


def _two_faces_and_a_can(rng):
    long_face = np.column_stack([np.linspace(-0.06, 0.06, 9), np.full(9, -0.04)])
    short_face = np.column_stack([np.full(5, 0.08), np.linspace(-0.03, 0.03, 5)])
    box = _on_box(np.vstack([long_face, short_face]), rng)
    angles = np.linspace(0.0, 1.5, 8)  # a can of radius 5 cm, 25 cm away, touched on an arc
    can = np.column_stack([0.25 + 0.05 * np.cos(angles), 0.35 + 0.05 * np.sin(angles),
                           np.full(8, HEIGHT)])  # fmt: skip
    labels = np.array([0] * len(box) + [1] * len(can))
    return np.vstack([box, can]), labels


def test_two_touched_faces_pin_the_box_among_clutter():
    points, labels = _two_faces_and_a_can(np.random.default_rng(0))
    result = pose_hypotheses(np.random.default_rng(1), points, labels, BOX)
    position, yaw = _pose_error(result.pose)
    # Fourteen points at 1.5 mm noise on two faces: the fit is good to a few millimetres and
    # a degree or two; the can's points lie 20 cm away, outside the posed box.
    assert position < 0.004 and yaw < np.radians(2.0), (position, np.degrees(yaw))
    assert result.explained[0].tolist() == (labels == 0).tolist()
    assert result.confidence > 0.95
    assert result.weights.sum() == pytest.approx(1.0)
    assert np.all(np.diff(result.costs) >= 0.0)


def test_one_touched_face_leaves_the_box_unpinned_until_free_space_says_which_side(
        disc_penetration):  # fmt: skip
    """Nine points on the long face alone: the box may lie on either side of that face and
    slide along it, so without free space no pose is confident. The gripper pushed from the
    face's outer side (y < -4 cm in the box frame) and stayed there: the mirrored box, which
    would lie where the gripper was, is ruled out."""
    rng = np.random.default_rng(2)
    face = _on_box(np.column_stack([np.linspace(-0.03, 0.03, 9), np.full(9, -0.04)]), rng)
    labels = np.zeros(len(face), dtype=np.int64)
    blind = pose_hypotheses(np.random.default_rng(3), face, labels, BOX)
    assert blind.confidence < 0.6
    # Gripper (2 cm disc) centres 2.5 cm outside the face, along it: where it sensed the points.
    along = np.column_stack([np.linspace(-0.03, 0.03, 5), np.full(5, -0.065)])
    configs = _on_box(along, np.random.default_rng(4))
    configs[:, 2] = HEIGHT
    free = FreeSpace(disc_penetration, configs, None, np.arange(9) * 4 // 9)
    seen = pose_hypotheses(np.random.default_rng(3), face, labels, BOX, free_space=free)
    # The mirrored box, its centre 8 cm on the gripper's side of the true one (box frame y),
    # carried weight blind; where the gripper was, it weighs nothing.
    def mirrored_weight(result):
        centre_y = ((result.poses[:, :2] - TRUE_POSE[:2]) @ rotations(TRUE_POSE[2]))[:, 1]
        return result.weights[centre_y < -0.06].sum()

    assert mirrored_weight(blind) > 0.05, mirrored_weight(blind)
    assert mirrored_weight(seen) < 1e-3, mirrored_weight(seen)


def test_point_spread_is_the_weighted_rms_about_the_mean():
    # Two particles, weights 3:1, a point at x = 0 and x = 4 mm: the mean is at 1 mm, the RMS
    # distance sqrt(0.75 * 1^2 + 0.25 * 3^2) mm = sqrt(3) mm.
    particles = np.array([[[0.0, 0.0, 0.0]], [[0.004, 0.0, 0.0]]])
    spread = point_spread(particles, np.log([0.75, 0.25]))
    assert spread == pytest.approx([np.sqrt(3.0) * 1e-3], rel=1e-12)


def test_the_same_seed_gives_the_same_hypotheses():
    points, labels = _two_faces_and_a_can(np.random.default_rng(0))
    a = pose_hypotheses(np.random.default_rng(5), points, labels, BOX)
    b = pose_hypotheses(np.random.default_rng(5), points, labels, BOX)
    np.testing.assert_array_equal(a.poses, b.poses)
    np.testing.assert_array_equal(a.weights, b.weights)


def test_no_group_to_fit_is_a_one_line_error():
    points = np.array([[0.0, 0.0, HEIGHT], [0.01, 0.0, HEIGHT]])
    with pytest.raises(ValueError, match="no segment has at least 3 points"):
        pose_hypotheses(np.random.default_rng(0), points, np.array([0, 0]), BOX)


def test_a_segment_no_placement_can_touch_gives_no_hypotheses():
    # Three points of one segment, 40 cm apart: wider than the box (18 cm across its
    # diagonal), so no piece or placement holds three of them.
    points = np.array([[0.0, 0.0, HEIGHT], [0.4, 0.0, HEIGHT], [0.8, 0.0, HEIGHT]])
    assert pose_hypotheses(np.random.default_rng(0), points, np.zeros(3, dtype=int), BOX) is None


def test_outline_error_is_zero_for_symmetric_turns_and_the_shift_otherwise():
    from stucco_drake.core.shapes import CylinderSdf
    from stucco_drake.eval.target_estimates import outline_error

    pose = np.array([0.4, -0.2, 0.5])
    # A box turned by pi and a cylinder turned by anything cover the same outline; the 2.5 mm
    # tolerance is half the 5 mm outline sampling (samples need not map onto samples).
    assert outline_error(BOX, pose, pose + np.array([0.0, 0.0, np.pi])) < 0.0025
    assert outline_error(CylinderSdf(0.04, 0.06), pose, pose + np.array([0.0, 0.0, 1.0])) < 0.0025
    # Shifted by 3 cm, every outline point is 3 cm from its old place and at least
    # 3 cm minus a half sample from the nearest old outline point on the leading faces.
    shifted = pose + np.array([0.03, 0.0, 0.0])
    assert outline_error(BOX, pose, shifted) == pytest.approx(0.03, abs=0.0025)
    # A quarter turn of a 16 x 8 cm box moves its far corners by (8 - 4) cm along each axis.
    quarter = pose + np.array([0.0, 0.0, np.pi / 2])
    assert outline_error(BOX, pose, quarter) == pytest.approx(0.04, abs=0.0025)


def test_unexplained_points_are_the_clutter_placed_at_the_chosen_motion_scale():
    """The points the chosen hypothesis leaves off the target, each at that hypothesis's
    motion scale between sensed and tracked: here halfway, so (0, 0) -> (0.2, 0) gives 0.1."""
    found = PoseHypotheses(
        poses=np.zeros((2, 3)), costs=np.zeros(2), weights=np.full(2, 0.5),
        explained=np.array([[True, False, True], [False, False, False]]), confidence=0.5,
        chosen=0, pose=np.zeros(3), motion_scales=np.array([0.5, 1.0]))  # fmt: skip
    sensed = np.array([[0.0, 0.0, 0.05], [0.0, 0.0, 0.05], [1.0, 1.0, 0.05]])
    tracked = sensed + np.array([[0.0, 0.0, 0.0], [0.2, 0.0, 0.0], [0.0, 0.0, 0.0]])
    clutter = found.unexplained_points(sensed, tracked)
    np.testing.assert_allclose(clutter, [[0.1, 0.0, 0.05]], atol=1e-12)


def test_a_tempered_confidence_counts_rivals_the_weights_leave_out():
    """Three poses of the box 30 cm apart (a grasp at one closes on no other), each explaining
    all three points, at costs 0, 4 and 30. The weights (temperature 1) keep the first two;
    the grasp is made at the cheapest, and its confidence is its weight, 1 / (1 + e^-4). With
    ``confidence_temperature`` 10 the confidence is formed over all three:
    1 / (1 + e^-0.4 + e^-3), by hand; the grasp, the hypotheses and their weights are those
    at temperature 1."""
    poses = np.array([[0.5, 0.1, 0.3], [0.8, 0.1, 0.3], [0.5, 0.4, 0.3]])
    costs = np.array([0.0, 4.0, 30.0])
    explained = np.ones((3, 3), dtype=bool)
    plain = weigh_hypotheses(poses, costs, explained, BOX, HypothesisParams())
    assert len(plain.poses) == 2
    assert plain.confidence == pytest.approx(1.0 / (1.0 + np.exp(-4.0)), abs=1e-12)
    tempered = weigh_hypotheses(poses, costs, explained, BOX,
                                HypothesisParams(confidence_temperature=10.0))  # fmt: skip
    assert tempered.confidence == pytest.approx(
        1.0 / (1.0 + np.exp(-0.4) + np.exp(-3.0)), abs=1e-12)
    assert np.array_equal(tempered.pose, plain.pose)
    assert np.array_equal(tempered.weights, plain.weights)


def test_variants_of_one_rival_count_once_in_the_tempered_confidence():
    """The cheapest pose (cost 0) and five variants of a rival 30 cm away (cost 4, each
    within 4 mm and 1 degree of the first of them): tempered at 10, the rival counts once,
    1 / (1 + e^-0.4) by hand, not 1 / (1 + 5 e^-0.4)."""
    rival = np.array([0.8, 0.1, 0.3])
    variants = rival + np.array([[0.0, 0.0, 0.0], [0.004, 0.0, 0.0], [0.0, 0.004, 0.0],
                                 [-0.003, 0.0, 0.01], [0.0, -0.003, -0.01]])  # fmt: skip
    poses = np.vstack([[0.5, 0.1, 0.3], variants])
    costs = np.array([0.0, 4.0, 4.0, 4.0, 4.0, 4.0])
    explained = np.ones((6, 3), dtype=bool)
    found = weigh_hypotheses(poses, costs, explained, BOX,
                             HypothesisParams(confidence_temperature=10.0))  # fmt: skip
    assert found.confidence == pytest.approx(1.0 / (1.0 + np.exp(-0.4)), abs=1e-12)


def test_points_felt_under_the_light_force_move_the_estimate_off_a_big_can_onto_the_target():
    """A 3.8 cm can touched on 4 points of its arc, and 20 cm away a 10.2 cm can touched on 8
    points of a 0.5 rad (5 cm) arc, all of which the small outline explains within the
    estimator's 4 mm contact noise. Counting points, the big can wins. The big can slid under
    2.5 N, the target met 12 N: with ``light_force`` 4.9 N, the big can's points cannot lie on
    the target, and the estimate is the target's true centre."""
    rng = np.random.default_rng(5)
    target, big = np.array([0.30, 0.10]), np.array([0.30, 0.40])
    small_arc = np.linspace(-2.2, -1.0, 4)  # the target's side facing -y
    big_arc = np.linspace(1.0, 1.5, 8)  # the big can's far side, away from the target
    points = np.vstack([
        target + 0.038 * np.column_stack([np.cos(small_arc), np.sin(small_arc)]),
        big + 0.102 * np.column_stack([np.cos(big_arc), np.sin(big_arc)]),
    ]) + rng.normal(0.0, NOISE, (12, 2))  # fmt: skip
    points = np.column_stack([points, np.full(12, HEIGHT)])
    labels = np.array([0] * 4 + [1] * 8)
    forces = np.array([12.0] * 4 + [2.5] * 8)
    can = CylinderSdf(0.038, 0.06)
    counted = pose_hypotheses(np.random.default_rng(6), points, labels, can,
                              point_forces=forces)  # no light_force: the forces are not used
    assert np.hypot(*(counted.pose[:2] - target)) > 0.2  # on the big can, explaining its 8
    assert counted.explained[counted.chosen].tolist() == [False] * 4 + [True] * 8
    params = HypothesisParams(light_force=4.9)
    weighed = pose_hypotheses(np.random.default_rng(6), points, labels, can, params=params,
                              point_forces=forces)  # fmt: skip
    # Four points at 1.5 mm noise on a third of the outline: the centre to within 5 mm.
    assert np.hypot(*(weighed.pose[:2] - target)) < 0.005
    assert weighed.explained[weighed.chosen].tolist() == [True] * 4 + [False] * 8
    # An unknown force (NaN) is never light: the same points without forces are counted.
    unknown = pose_hypotheses(np.random.default_rng(6), points, labels, can, params=params,
                              point_forces=np.full(12, np.nan))  # fmt: skip
    assert np.allclose(unknown.pose, counted.pose)


def test_light_force_settings_are_checked():
    with pytest.raises(ValueError, match="light_force"):
        HypothesisParams(light_force=0.0)
    points = np.column_stack([np.linspace(0.0, 0.05, 4), np.zeros(4), np.full(4, HEIGHT)])
    with pytest.raises(ValueError, match=r"point_forces: expected \(4,\)"):
        pose_hypotheses(np.random.default_rng(0), points, np.zeros(4, dtype=np.int64), BOX,
                        params=HypothesisParams(light_force=4.9), point_forces=np.ones(3))
