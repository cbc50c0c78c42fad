"""Metrics against definitions computed the slow way."""

import itertools

import numpy as np
import pytest

from stucco_drake.core import (
    BoxSdf,
    CylinderSdf,
    ambiguity,
    contact_error,
    fowlkes_mallows,
    paired_median_gap,
    target_pose_error,
)


def brute_force_fmi(truth, pred):
    pairs = list(itertools.combinations(range(len(truth)), 2))
    same_true = np.array([truth[i] == truth[j] for i, j in pairs])
    same_pred = np.array([pred[i] == pred[j] for i, j in pairs])
    both = np.sum(same_true & same_pred)
    if both == 0:
        return 0.0
    return both / np.sqrt(same_true.sum() * same_pred.sum())


def test_fowlkes_mallows_equals_brute_force_pair_count_on_random_labelings():
    rng = np.random.default_rng(7)
    for _ in range(200):
        n = int(rng.integers(2, 30))
        truth = rng.integers(0, rng.integers(1, 6), n)
        pred = rng.integers(0, rng.integers(1, 6), n) * 7 - 3  # arbitrary label values
        assert fowlkes_mallows(truth, pred) == pytest.approx(
            brute_force_fmi(truth, pred), abs=1e-12
        )


def test_fowlkes_mallows_extremes_and_errors():
    assert fowlkes_mallows([0, 0, 1, 1], [5, 5, 2, 2]) == 1.0
    assert fowlkes_mallows([0, 1, 2], [0, 1, 2]) == 0.0  # no pairs at all: sklearn's convention
    with pytest.raises(ValueError, match="equal length"):
        fowlkes_mallows([0, 1], [0])


def test_contact_error_is_mean_distance_to_nearest_surface():
    boxes = [BoxSdf((0.05, 0.05, 0.05), (0.0, 0.0, 0.0)), BoxSdf((0.05, 0.05, 0.05), (1.0, 0, 0))]
    points = [[0.06, 0.0, 0.0], [0.0, 0.0, 0.03], [0.93, 0.0, 0.0]]  # 1 cm out, 2 cm in, 2 cm out
    assert contact_error(points, boxes) == pytest.approx((0.01 + 0.02 + 0.02) / 3, abs=1e-12)
    with pytest.raises(ValueError, match="no tracked points"):
        contact_error(np.zeros((0, 3)), boxes)
    with pytest.raises(ValueError, match="points"):
        contact_error([[np.nan, 0.0, 0.0]], boxes)


def test_ambiguity_is_mean_closeness_of_the_second_object_over_contact_steps():
    # Distances (m) from the robot to each of 3 touched objects at 4 steps; contact at 0, 1, 3.
    distances = [[0.0, 0.10, 0.5], [0.0, 0.30, 0.5], [0.2, 0.2, 0.2], [0.0, 0.01, 0.14]]
    in_contact = [True, True, False, True]
    # Second-closest: 0.10, 0.30, -, 0.01 -> per step (0.15 - d2)/0.15 floored at 0.
    expected = (0.05 / 0.15 + 0.0 + 0.14 / 0.15) / 3
    assert ambiguity(distances, in_contact) == pytest.approx(expected, abs=1e-12)
    assert ambiguity(distances, [False] * 4) == 0.0
    with pytest.raises(ValueError, match="in_contact"):
        ambiguity(distances, [True])


def test_paired_median_gap_tells_a_shift_from_noise():
    rng = np.random.default_rng(1)
    reference = rng.lognormal(1.0, 0.6, size=120)  # heavy-tailed like a training set's CE
    # Every trial 0.5 cm worse: the gap is 0.5 exactly and the interval excludes 0.
    shifted = paired_median_gap(reference + 0.5, reference, np.random.default_rng(0))
    assert shifted["gap"] == pytest.approx(0.5, abs=1e-12)
    assert 0.0 < shifted["low"] <= 0.5 + 1e-12 <= shifted["high"] + 1e-12
    assert shifted["n"] == 120 and shifted["n_lower"] == 0
    # Each trial's value re-drawn from the same law: the interval holds 0.
    noisy = paired_median_gap(reference[rng.permutation(120)], reference,
                              np.random.default_rng(0))
    assert noisy["low"] < 0.0 < noisy["high"] and 30 < noisy["n_lower"] < 90
    # Non-finite trials are dropped in pairs; the same generator seed, the same interval.
    a, b = reference + 0.5, reference.copy()
    a[3], b[7] = np.nan, np.inf
    again = paired_median_gap(a, b, np.random.default_rng(0))
    assert again["n"] == 118
    assert again == paired_median_gap(a, b, np.random.default_rng(0))
    with pytest.raises(ValueError, match="3 values against 2"):
        paired_median_gap([1, 2, 3], [1, 2], np.random.default_rng(0))
    with pytest.raises(ValueError, match="no trial with both values finite"):
        paired_median_gap([np.nan], [1.0], np.random.default_rng(0))


def placed_sdf(shape, pose):
    """The signed distance of ``shape`` placed at planar pose (x, y, yaw), on world points."""
    x, y, yaw = pose
    c, s = np.cos(yaw), np.sin(yaw)
    R = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    return lambda points: shape((np.asarray(points) - [x, y, 0.0]) @ R)


def test_target_pose_error_is_zero_for_a_pose_the_shape_cannot_tell_apart():
    # A box off its frame's origin, turned half a turn about its own centre: the same box.
    box = BoxSdf((0.03, 0.08, 0.1), center=(0.02, -0.01, 0.1))
    truth = np.array([0.2, 0.1, 0.3])
    c, s = np.cos(truth[2]), np.sin(truth[2])
    centre = truth[:2] + np.array([[c, -s], [s, c]]) @ [0.02, -0.01]
    turned = np.array([*(2 * centre - truth[:2]), truth[2] + np.pi])  # origin mirrored
    points = np.random.default_rng(0).uniform([0.0, -0.1, 0.0], [0.4, 0.3, 0.2], (500, 3))
    np.testing.assert_allclose(placed_sdf(box, turned)(points), placed_sdf(box, truth)(points),
                               atol=1e-12)  # the independent check that it is the same box
    assert target_pose_error(turned, truth, box) == pytest.approx((0.0, 0.0), abs=1e-12)


def test_target_pose_error_measures_offsets_and_turns_modulo_the_symmetry():
    box = BoxSdf((0.03, 0.08, 0.1))
    # 3-4-5 cm offset; 170 deg is 10 deg from a box's half turn.
    error = target_pose_error([0.03, 0.04, np.radians(170)], [0.0, 0.0, 0.0], box)
    assert error == pytest.approx((0.05, np.radians(10)), abs=1e-12)
    assert target_pose_error([0, 0, np.radians(-75)], [0, 0, np.radians(80)], box)[1] == \
        pytest.approx(np.radians(25), abs=1e-12)  # -155 deg: 25 from -180
    square = BoxSdf((0.05, 0.05, 0.1))
    assert target_pose_error([0, 0, np.radians(100)], [0, 0, 0], square)[1] == \
        pytest.approx(np.radians(10), abs=1e-12)
    distance, yaw = target_pose_error([0.1, 0.0, 2.0], [0.1, 0.02, 0.0], CylinderSdf(0.04, 0.06))
    assert distance == pytest.approx(0.02, abs=1e-12) and np.isnan(yaw)
