"""Where a box's grasp descends: beyond an end, along its long axis, away from felt clutter."""

import numpy as np
import pytest

from stucco_drake.core.box_approach import aside_shifts, box_approach_offsets
from stucco_drake.core.grasp_choice import PAD_HALF_WIDTH
from stucco_drake.core.hypothesis_params import HypothesisParams
from stucco_drake.core.settings import settings_with

# The cracker box's half sizes (m): 6.58 x 15.8 x 20.74 cm, long horizontal axis along its y.
HALF = (0.0329, 0.079, 0.1037)
# Half length + a pad's half width (4 cm) + the 1 cm margin.
REACH = 0.079 + PAD_HALF_WIDTH + 0.01


def test_offsets_run_along_the_long_axis_past_an_end_then_straight_down_then_the_other():
    """The box turned 90 deg: its long axis along world x. The gripper at -x of it: the -x
    end first (no clutter felt), 12.9 cm from the centre, then (0, 0), then the +x end."""
    offsets = box_approach_offsets((0.2, 0.0, np.pi / 2), HALF, np.zeros((0, 3)), (0.0, 0.05))
    np.testing.assert_allclose(offsets, [[-REACH, 0.0], [0.0, 0.0], [REACH, 0.0]], atol=1e-12)


def test_long_axis_follows_the_yaw_and_which_half_extent_is_longer():
    yaw = np.radians(30.0)
    offsets = box_approach_offsets((0.0, 0.0, yaw), HALF, [], (1.0, 1.0))
    axis = np.array([-np.sin(yaw), np.cos(yaw)])  # the box's y axis in the world
    assert offsets[0] @ axis == pytest.approx(REACH)  # the end nearer (1, 1) first
    assert abs(offsets[0] @ np.array([np.cos(yaw), np.sin(yaw)])) < 1e-12
    # A box whose long side is its x: the offsets run along its x axis.
    offsets = box_approach_offsets((0.0, 0.0, 0.0), (0.079, 0.0329, 0.1), [], (-1.0, 0.0))
    np.testing.assert_allclose(offsets[0], [-REACH, 0.0], atol=1e-12)


def test_clutter_felt_beside_the_near_end_puts_the_far_end_first():
    """A can felt 1 cm past the -x end's descent point, 9 cm to its side: a finger going down
    there (8.75 cm across the axis) would land 1.0 cm from it; the +x end's are 25 cm away."""
    pose, gripper = (0.2, 0.0, np.pi / 2), (0.0, 0.05)
    can = np.array([[0.2 - REACH + 0.01, 0.09, 0.1]])
    offsets = box_approach_offsets(pose, HALF, can, gripper)
    np.testing.assert_allclose(offsets[0], [REACH, 0.0], atol=1e-12)
    # Clutter clear of both ends (30 cm past the +x end's descent point): the near end first.
    far = np.array([[0.2 + REACH + 0.3, 0.0, 0.1]])
    np.testing.assert_allclose(box_approach_offsets(pose, HALF, far, gripper)[0],
                               [-REACH, 0.0], atol=1e-12)


def test_an_end_descent_is_shifted_sideways_off_a_can_beyond_it():
    """The box's long axis along world x, the -x end's descent at x = 0.2 - REACH. A can felt
    2 cm beyond that point and 9 cm to its +y side: the +y finger (8.75 cm across) would go
    down 2.0 cm from it; shifted 2.5 cm to -y, 3.4 cm; 5 cm, 5.6 cm: -5 cm is chosen. Shifted
    5 cm to +y that finger would be 5.2 cm from it too, but beyond it: moving back in line
    would shove the can towards the box, so shifts go away from the nearest point only. The
    straight descent is never shifted, and without clutter nothing is."""
    pose, gripper = (0.2, 0.0, np.pi / 2), (0.0, 0.05)
    can = np.array([[0.2 - REACH - 0.02, 0.09, 0.1]])
    offsets = box_approach_offsets(pose, HALF, np.zeros((0, 3)), gripper)
    shifts = aside_shifts(pose, HALF, offsets, can)
    np.testing.assert_allclose(shifts, [[0.0, -0.05], [0.0, 0.0], [0.0, 0.0]], atol=1e-12)
    np.testing.assert_allclose(aside_shifts(pose, HALF, offsets, np.zeros((0, 3))), 0.0)


def test_no_shift_crosses_the_nearest_point():
    """A point 2 cm beyond the -x end's descent and 6 cm to its +y side, inside the +y
    finger (8.75 cm): shifted 5 cm to +y that finger would go down 8.0 cm from it, beyond
    it, and moving back in line would shove it inwards; shifted to -y the room shrinks (3.0
    cm against 3.4): no shift."""
    pose = (0.2, 0.0, np.pi / 2)
    offsets = box_approach_offsets(pose, HALF, np.zeros((0, 3)), (0.0, 0.05))
    inside = np.array([[0.2 - REACH - 0.02, 0.06, 0.1]])
    np.testing.assert_allclose(aside_shifts(pose, HALF, offsets, inside), 0.0, atol=1e-12)


def test_a_shift_is_made_only_where_it_gains_room():
    """Clutter 30 cm from both ends' fingers, beyond ``clearance`` (8 cm) whatever the
    shift: the tie goes to no shift."""
    pose = (0.2, 0.0, np.pi / 2)
    offsets = box_approach_offsets(pose, HALF, np.zeros((0, 3)), (0.0, 0.05))
    far = np.array([[0.2, 0.5, 0.1]])
    np.testing.assert_allclose(aside_shifts(pose, HALF, offsets, far), 0.0)


def test_bad_input_is_refused():
    with pytest.raises(ValueError, match="pose"):
        box_approach_offsets((0.0, np.nan, 0.0), HALF, [], (0.0, 0.0))
    with pytest.raises(ValueError, match="gripper_xy"):
        box_approach_offsets((0.0, 0.0, 0.0), HALF, [], (0.0,))
    with pytest.raises(ValueError, match="pose"):
        aside_shifts((0.0, np.inf, 0.0), HALF, [[0.1, 0.0]], [])


def test_an_unknown_box_approach_is_refused_in_one_line():
    refused = r"^box_approach: expected one of top, end, end_aside, got 'side'$"
    with pytest.raises(ValueError, match=refused):
        HypothesisParams(box_approach="side")
    with pytest.raises(ValueError, match="box_approach"):
        settings_with(HypothesisParams(), {"box_approach": 1}, "--hypothesis-params ")
    assert settings_with(HypothesisParams(), {"box_approach": "end"}).box_approach == "end"
