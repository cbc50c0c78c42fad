"""The closing yaw for round targets: keep the open fingers off the clutter the robot felt."""

import numpy as np
import pytest

from stucco_drake.core.grasp_yaw import (
    OPEN_FINGER_OFFSET,
    cylinder_grasp_yaw,
    cylinder_grasp_yaws,
)


def finger_clearance(centre, yaw, points):
    axis = np.array([np.cos(yaw), np.sin(yaw)])
    fingers = np.array(centre) + OPEN_FINGER_OFFSET * np.array([axis, -axis])
    return np.linalg.norm(fingers[:, None] - np.asarray(points)[None, :, :2], axis=-1).min()


def test_no_clutter_or_clear_keeps_the_current_yaw():
    assert cylinder_grasp_yaw((0.2, 0.0), np.zeros((0, 3)), 1.0) == 1.0
    far = np.array([[0.2, 0.5, 0.1]])  # 0.5 m away along y, the closing axis at yaw pi/2
    assert cylinder_grasp_yaw((0.2, 0.0), far, np.pi / 2) == np.pi / 2


def test_clutter_where_a_finger_would_land_turns_the_grasp():
    """A can felt 10 cm along +y of the target: closing along y would put the +y finger 1.25 cm
    from it; the chosen yaw closes along x, where both fingers clear it by 12.7 cm."""
    centre, clutter = (0.2, 0.0), np.array([[0.2, 0.1, 0.1], [0.21, 0.1, 0.1]])
    yaw = cylinder_grasp_yaw(centre, clutter, np.pi / 2)
    assert finger_clearance(centre, np.pi / 2, clutter) == pytest.approx(0.0125, abs=1e-3)
    assert np.cos(yaw) ** 2 == pytest.approx(1.0, abs=1e-9)  # along x, either way round
    assert finger_clearance(centre, yaw, clutter) == pytest.approx(0.1265, abs=1e-3)


def test_retry_yaws_are_the_other_axes_clearest_first():
    """Three axes 60 deg apart: the chosen one first, then of the two others the one whose
    fingers are farther from the felt points. A point felt at 150 deg from the centre, one
    finger's offset away, lies under a finger at yaw 150 deg and 60 deg round from the nearer
    finger at 90 or 210 deg (8.75 cm), so 210 deg comes before 150 deg."""
    centre = (0.2, 0.0)
    clutter = np.array([centre]) + OPEN_FINGER_OFFSET * np.array(
        [[np.cos(np.radians(150)), np.sin(np.radians(150))]])
    yaws = cylinder_grasp_yaws(centre, clutter, np.pi / 2)
    assert yaws[0] == cylinder_grasp_yaw(centre, clutter, np.pi / 2) == np.pi / 2
    np.testing.assert_allclose(np.degrees(yaws), [90.0, 210.0, 150.0], atol=1e-9)
    assert finger_clearance(centre, yaws[1], clutter) == pytest.approx(0.0875, abs=1e-3)
    assert finger_clearance(centre, yaws[2], clutter) == pytest.approx(0.0, abs=1e-9)
    # Without felt points the axes come counter-clockwise.
    np.testing.assert_allclose(np.degrees(cylinder_grasp_yaws(centre, np.zeros((0, 3)), 0.0,
                                                              n_axes=4)), [0, 45, 90, 135])


def test_bad_input_is_named():
    with pytest.raises(ValueError, match="obstacle_points"):
        cylinder_grasp_yaw((0.0, 0.0), np.array([[np.nan, 0.0]]), 0.0)
    with pytest.raises(ValueError, match="centre_xy"):
        cylinder_grasp_yaw((0.0, 0.0, 0.0), np.zeros((1, 2)), 0.0)
