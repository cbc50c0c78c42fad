"""The closing yaw for round targets: keep the open fingers off the clutter the robot felt."""

import numpy as np
import pytest

from stucco_drake.core.grasp_yaw import OPEN_FINGER_OFFSET, cylinder_grasp_yaw


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


def test_bad_input_is_named():
    with pytest.raises(ValueError, match="obstacle_points"):
        cylinder_grasp_yaw((0.0, 0.0), np.array([[np.nan, 0.0]]), 0.0)
    with pytest.raises(ValueError, match="centre_xy"):
        cylinder_grasp_yaw((0.0, 0.0, 0.0), np.zeros((1, 2)), 0.0)
