"""Grasp choice across pose hypotheses, against the criterion's analytic boundaries.

The truth here is geometry worked by hand from the paper's criterion (RA-L 2022 Sec. V-C) with
the cracker box (half extents 0.0329 x 0.079 m across/along its long faces) and the tomato can
(radius 0.0335 m); pads 0.04 m half wide, 15 degrees, 2 cm edge margin.
"""

import numpy as np
import pytest

import stucco_drake  # noqa: F401  (pins the numeric kernels before numpy loads)
from stucco_drake.core.grasp_choice import (
    EDGE_MARGIN,
    MAX_AXIS_ERROR,
    PAD_HALF_WIDTH,
    choose_grasp,
    grasp_at,
    grasp_closes,
)
from stucco_drake.core.shapes import BoxSdf, CylinderSdf

BOX = BoxSdf(half_extents=(0.0329, 0.079, 0.1037))
CAN = CylinderSdf(radius=0.0335, half_height=0.051)
LONG_LIMIT = 0.079 - EDGE_MARGIN  # centre offset along the long side at which pads reach the margin


def _closes(grasp, pose, shape) -> bool:
    return bool(grasp_closes(np.asarray(grasp, float), np.asarray(pose, float), shape)[0, 0])


def test_box_boundaries_in_its_own_frame_and_turned():
    pose = np.array([0.3, -0.1, 0.7])
    # The grasp closes across the short (x) side: at the pose's yaw.
    grasp = grasp_at(pose, BOX)[0]
    assert grasp == pytest.approx(pose)

    def at(short, long_, turn=0.0):
        c, s = np.cos(pose[2]), np.sin(pose[2])
        xy = pose[:2] + np.array([c * short - s * long_, s * short + c * long_])
        return [xy[0], xy[1], pose[2] + turn]

    assert _closes(at(0.0, 0.0), pose, BOX)
    assert _closes(at(0.0, 0.0, np.pi), pose, BOX)  # the same closing axis, reversed
    # Along the long side up to the edge margin (1 mm either side of the boundary).
    assert _closes(at(0.0, LONG_LIMIT - 0.001), pose, BOX)
    assert not _closes(at(0.0, LONG_LIMIT + 0.001), pose, BOX)
    # Across: the centre must lie between the long faces.
    assert _closes(at(0.032, 0.0), pose, BOX) and not _closes(at(0.034, 0.0), pose, BOX)
    # Turned: 15 degrees is the limit; off centre the turned pads reach the edge sooner,
    # |long| + a tan(angle) <= b - margin.
    small, large = MAX_AXIS_ERROR - np.radians(0.5), MAX_AXIS_ERROR + np.radians(0.5)
    assert _closes(at(0.0, 0.0, small), pose, BOX) and not _closes(at(0.0, 0.0, large), pose, BOX)
    edge = LONG_LIMIT - 0.0329 * np.tan(small)
    assert _closes(at(0.0, edge - 0.001, small), pose, BOX)
    assert not _closes(at(0.0, edge + 0.001, small), pose, BOX)


def test_a_box_longer_along_x_closes_across_y():
    turned = BoxSdf(half_extents=(0.079, 0.0329, 0.1037))
    grasp = grasp_at([0.0, 0.0, 0.2], turned)[0]
    assert grasp[2] == pytest.approx(0.2 + np.pi / 2)
    assert _closes(grasp, [0.0, 0.0, 0.2], turned)
    assert not _closes([0.0, 0.0, 0.2], [0.0, 0.0, 0.2], turned)


def test_can_boundaries():
    # Closing along x: the axis must lie between the pads (|s| < r) and the pads must cover
    # more than half the diameter across (d < w for pads wider than the radius).
    assert PAD_HALF_WIDTH > CAN.radius
    assert _closes([0.0, 0.0, 0.0], [0.0, 0.0, 1.3], CAN)  # any yaw of the can
    assert _closes([-0.033, 0.0, 0.0], [0.0, 0.0, 0.0], CAN)
    assert not _closes([-0.034, 0.0, 0.0], [0.0, 0.0, 0.0], CAN)
    assert _closes([0.0, -0.039, 0.0], [0.0, 0.0, 0.0], CAN)
    assert not _closes([0.0, -0.041, 0.0], [0.0, 0.0, 0.0], CAN)


def test_choice_covers_hypotheses_along_the_long_side():
    # Three hypotheses along the box's long side, the likeliest at one end: a grasp there
    # reaches the middle one (5 cm < 5.9 cm) but not the far one (10 cm); the grasp at the
    # middle reaches both ends.
    poses = np.array([[0.0, -0.05, 0.0], [0.0, 0.0, 0.0], [0.0, 0.05, 0.0]])
    choice = choose_grasp(poses, [0.4, 0.3, 0.3], BOX)
    assert choice.target_pose == pytest.approx(poses[1])
    assert choice.probability == pytest.approx(1.0)


def test_choice_between_two_apart_hypotheses_is_their_mean():
    # 11 cm apart along the long side: no hypothesis's grasp reaches the other; their mean's
    # reaches both (5.5 cm each way).
    poses = np.array([[0.0, -0.055, 0.0], [0.0, 0.055, np.pi]])
    choice = choose_grasp(poses, [0.5, 0.5], BOX)
    assert choice.target_pose[:2] == pytest.approx([0.0, 0.0], abs=1e-12)
    assert choice.probability == pytest.approx(1.0)


def test_choice_keeps_the_likeliest_when_others_add_nothing():
    # Two far-apart hypotheses: the likelier wins with its own weight.
    poses = np.array([[0.2, 0.0, 0.0], [0.0, 0.0, 0.0]])
    choice = choose_grasp(poses, [0.6, 0.4], BOX)
    assert choice.target_pose == pytest.approx(poses[0])
    assert choice.probability == pytest.approx(0.6)
    with pytest.raises(ValueError, match="non-negative"):
        choose_grasp(poses, [0.0, 0.0], BOX)
