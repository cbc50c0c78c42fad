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
from stucco_drake.core.outline_fit import pooled_noise_variance, shape_excess
from stucco_drake.core.pose_penetration import penetration_window, restart_penetration
from stucco_drake.core.target_pose import estimate_target_pose

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


def face_and_large_arc(rng, truth):
    """4 points on one long face of the box at ``truth``, 16 on a 1.6 rad arc of a 0.102 m can.

    The BC scene's failure: the target touched on one face only, a large can next to it touched
    along a long arc. Contact height 5 cm; 1 mm noise; labels 0 (can) and 3 (box).
    """
    hx, hy = BOX.half_extents[:2]
    # Spread over 70% of the face, longer than the short face (2 hx), so the yaw is determined.
    along = np.linspace(-0.7, 0.7, 4) * hy + rng.uniform(-0.1 * hy, 0.1 * hy, 4)
    face = np.column_stack([np.full(4, hx), along])
    target = transform(truth[None], face)[0] + rng.normal(0, NOISE, face.shape)
    distractor = arc_patch(rng, truth[:2] + np.array([0.0, 0.3]), 0.102, 1.6, 16)
    labels = np.r_[np.zeros(len(distractor), int), np.full(len(target), 3)]
    return lift(np.vstack([distractor, target])), labels


@pytest.mark.parametrize("scenario", range(4))
def test_shape_rule_rejects_a_large_can_arc_the_variance_rule_prefers(scenario):
    """The paper's variance rule takes the can: a box corner wraps the arc (ICP RMS ~5 mm) in
    fewer places than the box slides along its one touched face. A circle explains the arc to
    the noise, so the shape test sets it aside and the box's face is chosen."""
    rng = np.random.default_rng(100 + scenario)
    truth = np.array([0.2, -0.1, 0.4])
    points, labels = face_and_large_arc(rng, truth)
    paper = estimate_target_pose(np.random.default_rng(0), points, labels, BOX, selection="paper")
    estimate = estimate_target_pose(np.random.default_rng(0), points, labels, BOX)
    can, box = estimate.segments
    print(
        f"\nshape excess: can {can.shape_excess:.1f}, box {box.shape_excess:.1f};"
        f" variance m^2: can {can.position_variance:.1e}, box {box.position_variance:.1e}"
    )
    assert paper.segment == 0 and can.position_variance < box.position_variance
    assert estimate.segment == 3
    assert not can.consistent and can.shape_excess > 20.0
    assert box.consistent and box.shape_excess < 3.0
    # One face fixes the yaw (modulo the box's symmetry), not where along the face it lies.
    _, yaw = pose_errors(estimate.pose, truth)
    assert np.degrees(yaw) < 5.0


@pytest.mark.parametrize("seed", [200, 202, 203, 205])
def test_shape_rule_judges_a_noisy_arc_against_the_pooled_sensor_noise(seed):
    """As in scene BC: the can's 32 points scatter by 5 mm about their circle, the target's 8
    by 1 mm about its face. Judged against its own scatter the arc's evidence is weaker than
    judged against the noise pooled over both segments, which rejects it."""
    rng = np.random.default_rng(seed)
    truth = np.array([0.2, -0.1, 0.4])
    hx, hy = BOX.half_extents[:2]
    face = np.column_stack([np.full(8, hx), np.linspace(-0.7, 0.7, 8) * hy])
    target = transform(truth[None], face)[0] + rng.normal(0, NOISE, face.shape)
    angle = rng.uniform(0, 2 * np.pi) + rng.uniform(0, 1.4, 32)
    circle = 0.102 * np.column_stack([np.cos(angle), np.sin(angle)])
    arc = truth[:2] + np.array([0.0, 0.35]) + circle + rng.normal(0, 0.005, (32, 2))
    points = lift(np.vstack([arc, target]))
    labels = np.r_[np.zeros(32, int), np.full(8, 2)]
    paper = estimate_target_pose(np.random.default_rng(0), points, labels, BOX, selection="paper")
    estimate = estimate_target_pose(np.random.default_rng(0), points, labels, BOX)
    alone = estimate_target_pose(np.random.default_rng(0), points[:32], labels[:32], BOX)
    assert paper.segment == 0 and estimate.segment == 2
    can, box = estimate.segments
    assert not can.consistent and box.consistent
    assert can.shape_excess > 1.5 * alone.segments[0].shape_excess


#: Scene BC, seed 0, final tracked points (m, world): label 1 an L-shaped patch on the tomato
#: can, label 2 the target cracker box's face (true pose (0.259, 0.052, 1.492)).
BC_TOMATO_AND_TARGET = np.array(
    [
        [0.1638, 0.1902, 0.1088], [0.1781, 0.1789, 0.1158], [0.1636, 0.1907, 0.1088],
        [0.1617, 0.1924, 0.1137], [0.1616, 0.1907, 0.1087], [0.1616, 0.1866, 0.1087],
        [0.1602, 0.2004, 0.1326], [0.1621, 0.2180, 0.1361], [0.1638, 0.1902, 0.1088],
        [0.1782, 0.1756, 0.1158], [0.1677, 0.2139, 0.1396], [0.2568, 0.0138, 0.1486],
        [0.2568, 0.0138, 0.1486], [0.2567, 0.0143, 0.1487], [0.2608, 0.0198, 0.1888],
        [0.2357, 0.0214, 0.1728], [0.2376, 0.0218, 0.1920], [0.2109, 0.0239, 0.1842],
        [0.2117, 0.0235, 0.1835],
    ]
)  # fmt: skip


def paper_and_shape_rules(seed, points, labels, shape):
    """The estimates of the paper's segment rule and of ours, from equally seeded generators."""
    paper = estimate_target_pose(
        np.random.default_rng(seed), points, labels, shape, selection="paper"
    )
    return paper, estimate_target_pose(np.random.default_rng(seed), points, labels, shape)


@pytest.mark.parametrize("seed", [2, 4, 5, 6])
def test_shape_evidence_breaks_a_variance_tie_on_real_points(seed):
    """A box fits the tomato can's patch no better than a circle does (excess ~0) but the
    target's points clearly better (excess ~-6): with near-equal spreads the paper's rule
    takes the can for these seeds, the log-score combination the target."""
    labels = np.r_[np.ones(11, int), np.full(8, 2)]
    box = BoxSdf((0.0329, 0.079, 0.1037))
    paper, estimate = paper_and_shape_rules(seed, BC_TOMATO_AND_TARGET, labels, box)
    can, target = estimate.segments
    assert paper.segment == 1 and estimate.segment == 2
    assert can.consistent and target.consistent
    assert target.shape_excess < can.shape_excess - 4.0
    assert can.position_variance < 1.3 * target.position_variance


#: Scene TC, seed 0, final tracked points (m, world): label 0 a cloud of points on the large
#: master chef can that no circle or line fits, label 1 the target tomato can's -x side (true
#: centre (0.2225, 0.0649)).
TC_CLOUD_AND_TARGET = np.array(
    [
        [0.1426, -0.0947, 0.1815], [0.1584, -0.1118, 0.1143], [0.1376, -0.1136, 0.1143],
        [0.1358, -0.1138, 0.1252], [0.1426, -0.0947, 0.1815], [0.1564, -0.1154, 0.1827],
        [0.1257, -0.1344, 0.1085], [0.1267, -0.1348, 0.1086], [0.1104, -0.1548, 0.1132],
        [0.1369, -0.1533, 0.1131], [0.1928, -0.1138, 0.1796], [0.1934, -0.1137, 0.1803],
        [0.1838, 0.0622, 0.0692], [0.1864, 0.0577, 0.1157], [0.1860, 0.0477, 0.0877],
        [0.1880, 0.0601, 0.0997], [0.1849, 0.0685, 0.0982], [0.1838, 0.0622, 0.0692],
        [0.1847, 0.0697, 0.1199],
    ]
)  # fmt: skip


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_outline_fit_rejects_a_cloud_the_spread_and_shape_test_accept(seed):
    """The cloud pins a small circle better than the target's 7 points do (lower spread) and,
    with the noise pooled over both segments, passes the shape test; the tomato can's outline
    misses it by 8.5 mm RMS against 1.4 mm on the target, which decides."""
    labels = np.r_[np.zeros(12, int), np.ones(7, int)]
    can = CylinderSdf(0.0384, 0.06)
    paper, estimate = paper_and_shape_rules(seed, TC_CLOUD_AND_TARGET, labels, can)
    cloud, target = estimate.segments
    assert paper.segment == 0 and estimate.segment == 1
    assert cloud.consistent and target.consistent
    assert cloud.position_variance < 0.6 * target.position_variance
    assert cloud.best_rms > 0.008 and target.best_rms < 0.002
    # Without configs the side is not pinned: the centre is 3.84 cm (the radius) from the
    # face's points, in front of them or behind.
    distance = np.linalg.norm(TC_CLOUD_AND_TARGET[12:, :2] - estimate.pose[:2], axis=1)
    assert abs(np.median(distance) - 0.0384) < 0.003


def test_shape_rule_keeps_a_genuine_target_and_falls_back_when_all_fail():
    """A box corner fits better than any circle (negative excess); with only can arcs, every
    segment fails the test and the variance rule decides among them all, as the paper's."""
    rng = np.random.default_rng(41)
    points = lift(box_corner_patch(rng, [0.1, 0.2, -0.3]))
    estimate = estimate_target_pose(
        np.random.default_rng(0), points, np.zeros(len(points), int), BOX
    )
    assert estimate.segments[0].consistent and estimate.segments[0].shape_excess < 0.0
    arcs = np.vstack(
        [arc_patch(rng, [0.0, 0.0], 0.102, 1.6, 16), arc_patch(rng, [0.4, 0.0], 0.102, 1.6, 16)]
    )
    labels = np.repeat([0, 1], 16)
    shape = estimate_target_pose(np.random.default_rng(0), lift(arcs), labels, BOX)
    paper = estimate_target_pose(
        np.random.default_rng(0), lift(arcs), labels, BOX, selection="paper"
    )
    assert not any(report.consistent for report in shape.segments)
    assert shape.segment == paper.segment and np.array_equal(shape.pose, paper.pose)


def _one_long_side():
    """(truth pose, 20 noisy contacts on one long side of BOX, hx, their positions along it)."""
    rng = np.random.default_rng(31)
    truth = np.array([-0.1, 0.25, 2.0])
    hx, hy = BOX.half_extents[:2]
    along = np.linspace(-hy, hy, 20)
    face = transform(truth[None], np.column_stack([np.full(20, hx), along]))[0]
    return truth, lift(face + rng.normal(0, NOISE, face.shape)), hx, along


def test_penetration_picks_the_side_the_robot_was_not_on(disc_penetration):
    """One long side touched from outside: the box fits on either side of the points.

    The end effector (a 2 cm disc) slid along the outside of the face, so every pose with the
    box on the robot's side penetrates it and the least-penetration rule rejects it.
    """
    truth, points, hx, along = _one_long_side()
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


def test_since_touch_ignores_configs_from_before_the_target_was_pushed(disc_penetration):
    """The robot first swept the area where the box now lies (the box was pushed there later),
    then slid along its face. Every config counted, the true pose penetrates the early sweep
    and loses; counting only the configs since the segment was last touched, it wins."""
    truth, points, hx, along = _one_long_side()
    inside = np.stack(np.meshgrid([-0.015, 0.0, 0.015], np.linspace(-0.06, 0.06, 13)), -1)
    sweep = transform(truth[None], inside.reshape(-1, 2))[0]
    slide = transform(truth[None], np.column_stack([np.full(20, hx + 0.021), along]))[0]
    configs = lift(np.concatenate([sweep, slide]))
    steps = len(sweep) + np.arange(20)  # point i was sensed at config len(sweep) + i
    labels = np.zeros(20, dtype=int)
    results = {}
    for rule in ("all", "since_touch"):
        estimate = estimate_target_pose(
            np.random.default_rng(1), points, labels, BOX, disc_penetration, configs,
            penetration_configs=rule, point_steps=steps,
        )  # fmt: skip
        results[rule] = pose_errors(estimate.pose, truth)
    assert results["all"][0] > 0.03
    position, yaw = results["since_touch"]
    assert position < 0.01 and np.degrees(yaw) < 3.0


def test_configs_that_touched_the_target_count_with_a_tolerance(disc_penetration):
    """The robot slid along one long side of the box, then touched its far end last, from
    beyond it. Counting only the configs since that last touch, the box mirrored through the
    touched face onto the robot's side penetrates nothing and fits as well, and is taken; the
    slide's configs, where the robot touched the box, still rule it out at 1 cm tolerance."""
    truth, points, hx, along = _one_long_side()
    hy = BOX.half_extents[1]
    slide = transform(truth[None], np.column_stack([np.full(20, hx + 0.021), along]))[0]
    beyond_end = transform(truth[None], np.array([[0.0, hy + 0.021]]))[0]
    configs = lift(np.concatenate([slide, beyond_end]))
    steps = np.append(np.arange(19), 20)  # the face's far-end point was sensed from beyond it
    labels = np.zeros(20, dtype=int)
    offsets = {}
    for tolerance in (None, 0.01):
        estimate = estimate_target_pose(
            np.random.default_rng(1), points, labels, BOX, disc_penetration, configs,
            penetration_configs="since_touch", point_steps=steps, touch_tolerance=tolerance,
        )  # fmt: skip
        # The box centre's offset from the truth along the face normal: 2 hx when mirrored.
        offsets[tolerance] = ((estimate.pose[:2] - truth[:2]) @ rotations(truth[2]))[0]
        assert np.degrees(pose_errors(estimate.pose, truth)[1]) < 3.0
    print(f"\nnormal offset: window alone {offsets[None] * 1e3:.1f} mm, "
          f"touched configs {offsets[0.01] * 1e3:.1f} mm")
    assert offsets[None] > 1.9 * hx
    assert abs(offsets[0.01]) < 0.003


def test_penetration_window():
    assert penetration_window(10, "all") == slice(0, 10)
    assert penetration_window(10, "latest") == slice(9, 10)
    assert penetration_window(10, 3) == slice(7, 10)
    assert penetration_window(10, "since_touch", np.array([2, 6, 4])) == slice(6, 10)
    # A point sensed after the last config passed still leaves x_t to check.
    assert penetration_window(10, "since_touch", np.array([12])) == slice(9, 10)
    with pytest.raises(ValueError, match="needs point_steps"):
        penetration_window(10, "since_touch")
    for bad in (0, "first", True):
        with pytest.raises(ValueError, match="penetration_configs"):
            penetration_window(10, bad)


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
    with pytest.raises(ValueError, match=r"^selection: expected"):
        estimate_target_pose(rng, points, labels, BOX, selection="rms")
    with pytest.raises(ValueError, match=r"^contact_noise: must be"):
        estimate_target_pose(rng, points, labels, BOX, contact_noise=0.0)
    with pytest.raises(ValueError, match=r"^touch_tolerance: must be"):
        estimate_target_pose(rng, points, labels, BOX, touch_tolerance=-0.01)
    with pytest.raises(ValueError, match=r"^config_positions: expected shape"):
        estimate_target_pose(rng, points, labels, BOX, None, np.zeros((4, 2)))
    with pytest.raises(ValueError, match=r"^points_xy: no contact points"):
        icp_2d(rng, np.zeros((0, 2)), sample_outline(BOX, 0.002))
    with pytest.raises(ValueError, match=r"^spacing: must be a positive"):
        sample_box_outline([0.03, 0.08], 0.0)
    with pytest.raises(ValueError, match=r"^start: expected"):
        icp_2d(rng, points[:, :2], sample_outline(BOX, 0.002), start="origin")


def test_pooled_noise_is_the_median_residual_variance_floored():
    # Residual variances of the better model: 4e-5 / 4, 1e-6 / 2 and 8e-4 / 10 (m^2).
    fits = [(4e-5, 6e-5, 7), (1e-6, 2e-6, 5), (9e-4, 8e-4, 13)]
    assert pooled_noise_variance(fits, 0.002) == pytest.approx(1e-5)
    assert pooled_noise_variance(fits, 0.004) == pytest.approx(1.6e-5)
    excess = shape_excess(fits, 0.002)
    assert excess == pytest.approx([-2.0, -0.1, 10.0])
    assert shape_excess(fits, 0.002, 2e-5) == pytest.approx(excess / 2)
