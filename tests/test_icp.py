"""Planar ICP and the target-pose selection rule on synthetic contact patches with known poses."""

import numpy as np
import pytest

from stucco_drake.core import BoxSdf, CylinderSdf
from stucco_drake.core.icp import (
    cross_section_sdf,
    icp_2d,
    rotations,
    sample_box_outline,
    sample_outline,
    transform,
)
from stucco_drake.core.target_pose import estimate_target_pose, restart_penetration

#: The paper's cracker box (half extents, m) and a 1.2x tomato can (radius, m).
BOX = BoxSdf((0.0308, 0.0788, 0.1035))
CAN = CylinderSdf(0.039, 0.061)
NOISE = 0.001  # contact-point noise (m)


def box_corner_patch(rng, pose, n_long=15, n_short=10):
    """(n, 2) world points on the box's +x long side and +y short side, with 1 mm noise."""
    hx, hy = BOX.half_extents[:2]
    long_side = np.column_stack([np.full(n_long, hx), rng.uniform(-hy, hy, n_long)])
    short_side = np.column_stack([rng.uniform(-hx, hx, n_short), np.full(n_short, hy)])
    local = np.vstack([long_side, short_side])
    return transform(np.asarray(pose)[None], local)[0] + rng.normal(0, NOISE, local.shape)


def arc_patch(rng, center, radius, span, n):
    """(n, 2) points on a ``span``-radian arc of a circle, at a random heading, with noise."""
    angle = rng.uniform(0.0, 2.0 * np.pi) + rng.uniform(0.0, span, n)
    circle = np.column_stack([np.cos(angle), np.sin(angle)])
    return np.asarray(center) + radius * circle + rng.normal(0, NOISE, (n, 2))


def pose_errors(estimate, truth, symmetry=np.pi):
    """Position error (m) and yaw error (rad) modulo the shape's rotational ``symmetry``."""
    yaw = (estimate[2] - truth[2]) % symmetry
    return np.linalg.norm(estimate[:2] - truth[:2]), min(yaw, symmetry - yaw)


def lift(points_xy, height=0.05):
    return np.column_stack([points_xy, np.full(len(points_xy), height)])


def test_outline_lies_on_the_cross_section():
    model = sample_outline(BOX, 0.002)
    assert np.abs(cross_section_sdf(BOX)(model)).max() < 1e-12
    # Perimeter 0.438 m at <= 2 mm spacing, every corner included.
    assert len(model) >= 219
    assert np.any(np.all(np.isclose(model, BOX.half_extents[:2]), axis=1))
    can = sample_outline(CAN, 0.002)
    assert np.allclose(np.linalg.norm(can, axis=1), CAN.radius)


def test_box_pose_recovered_modulo_symmetry():
    """Two sides of the box, 1 mm noise, random poses: within 5 mm and 3 degrees every time."""
    rng = np.random.default_rng(7)
    model = sample_outline(BOX, 0.002)
    errors = []
    for trial in range(8):
        truth = np.array([*rng.uniform(-0.5, 0.5, 2), rng.uniform(-np.pi, np.pi)])
        points = box_corner_patch(rng, truth)
        result = icp_2d(np.random.default_rng(trial), points, model)
        errors.append(pose_errors(result.poses[np.argmin(result.rms)], truth))
    position, yaw = np.array(errors).T
    print(
        f"\nbox: position mm {np.round(position * 1e3, 2)}, yaw deg {np.round(np.degrees(yaw), 2)}"
    )
    assert position.max() < 0.005
    assert np.degrees(yaw).max() < 3.0


def test_can_position_recovered():
    """A 150-degree arc of the can: the centre within 5 mm (yaw is meaningless for a circle)."""
    rng = np.random.default_rng(11)
    model = sample_outline(CAN, 0.002)
    errors = []
    for trial in range(5):
        center = rng.uniform(-0.5, 0.5, 2)
        points = arc_patch(rng, center, CAN.radius, np.radians(150), 20)
        result = icp_2d(np.random.default_rng(trial), points, model)
        errors.append(np.linalg.norm(result.poses[np.argmin(result.rms), :2] - center))
    print(f"\ncan: position mm {np.round(np.array(errors) * 1e3, 2)}")
    assert max(errors) < 0.005


def test_same_seed_same_result():
    points = box_corner_patch(np.random.default_rng(3), [0.1, -0.2, 0.7])
    labels = np.zeros(len(points), dtype=int)
    first = estimate_target_pose(np.random.default_rng(5), lift(points), labels, BOX)
    again = estimate_target_pose(np.random.default_rng(5), lift(points), labels, BOX)
    other = estimate_target_pose(np.random.default_rng(6), lift(points), labels, BOX)
    assert np.array_equal(first.restarts, again.restarts) and np.array_equal(first.pose, again.pose)
    assert not np.array_equal(first.restarts, other.restarts)


def test_variance_rule_picks_the_box_over_a_can():
    """A box corner pins the box's pose; a can's arc fits a box model in many places.

    The distractor (a 5 cm-radius can, 150 degrees of its side touched) has more points near
    one another than the target but the restarts scatter on it, so its position variance is
    several times the box's and the box segment is chosen, by variance alone (no configs).
    """
    rng = np.random.default_rng(21)
    truth = np.array([0.2, -0.1, 0.4])
    target = box_corner_patch(rng, truth)
    distractor = arc_patch(rng, truth[:2] + np.array([0.0, 0.3]), 0.05, np.radians(150), 20)
    points = lift(np.vstack([distractor, target]))
    labels = np.r_[np.zeros(len(distractor), int), np.full(len(target), 3)]
    estimate = estimate_target_pose(np.random.default_rng(0), points, labels, BOX)
    can, box = estimate.segments
    print(f"\nvariance m^2: box {box.position_variance:.2e}, can {can.position_variance:.2e}")
    assert (can.label, can.n_points, box.label, box.n_points) == (0, 20, 3, 25)
    assert estimate.segment == 3
    assert can.position_variance > 2.0 * box.position_variance
    position, yaw = pose_errors(estimate.pose, truth)
    assert position < 0.005 and np.degrees(yaw) < 3.0


def test_penetration_picks_the_side_the_robot_was_not_on(disc_penetration):
    """One long side touched from outside: the box fits on either side of the points.

    The end effector (a 2 cm disc) slid along the outside of the face, so every pose with the
    box on the robot's side penetrates it and the least-penetration rule rejects it.
    """
    rng = np.random.default_rng(31)
    truth = np.array([-0.1, 0.25, 2.0])
    hx, hy = BOX.half_extents[:2]
    along = np.linspace(-hy, hy, 20)
    face = transform(truth[None], np.column_stack([np.full(20, hx), along]))[0]
    points = lift(face + rng.normal(0, NOISE, face.shape))
    configs = lift(transform(truth[None], np.column_stack([np.full(20, hx + 0.021), along]))[0])
    labels = np.zeros(20, dtype=int)
    estimate = estimate_target_pose(
        np.random.default_rng(1), points, labels, BOX, disc_penetration, configs
    )
    # Restarts landed on both sides: the box centre's offset from the truth along the face normal
    # is 0 on the right side and 2 hx when mirrored through the face onto the robot's side.
    side = ((estimate.restarts[:, :2] - truth[:2]) @ rotations(truth[2]))[:, 0]
    assert np.any(side > 1.5 * hx) and np.any(np.abs(side) < 0.005)
    assert estimate.penetration == 0.0
    position, yaw = pose_errors(estimate.pose, truth)
    print(f"\none side + configs: position {position * 1e3:.2f} mm, yaw {np.degrees(yaw):.2f} deg")
    assert position < 0.01 and np.degrees(yaw) < 3.0
    wrong = estimate.restarts[np.argmax(side)]
    assert (
        restart_penetration(
            disc_penetration, wrong[None], sample_outline(BOX, 0.005), 0.05, configs
        )[0]
        > 0.0
    )


def test_bad_input_names_the_argument():
    rng = np.random.default_rng(0)
    points = lift(box_corner_patch(rng, [0.0, 0.0, 0.0]))
    labels = np.zeros(len(points), dtype=int)
    with pytest.raises(ValueError, match=r"^points: no contact points"):
        estimate_target_pose(rng, np.zeros((0, 3)), np.zeros(0, int), BOX)
    with pytest.raises(ValueError, match=r"^points: contains NaN"):
        estimate_target_pose(rng, np.full((3, 3), np.nan), np.zeros(3, int), BOX)
    with pytest.raises(ValueError, match=r"^labels: no segment"):
        estimate_target_pose(rng, points, np.full(len(points), -1), BOX)
    with pytest.raises(ValueError, match=r"^labels: expected"):
        estimate_target_pose(rng, points, labels[:-1], BOX)
    with pytest.raises(ValueError, match=r"^shape: expected"):
        estimate_target_pose(rng, points, labels, "box")
    with pytest.raises(ValueError, match=r"^config_positions: expected shape"):
        estimate_target_pose(rng, points, labels, BOX, None, np.zeros((4, 2)))
    with pytest.raises(ValueError, match=r"^points_xy: no contact points"):
        icp_2d(rng, np.zeros((0, 2)), sample_outline(BOX, 0.002))
    with pytest.raises(ValueError, match=r"^spacing: must be a positive"):
        sample_box_outline([0.03, 0.08], 0.0)
    with pytest.raises(ValueError, match=r"^start: expected"):
        icp_2d(rng, points[:, :2], sample_outline(BOX, 0.002), start="origin")
