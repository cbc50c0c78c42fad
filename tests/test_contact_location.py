"""Where across a push the gripper meets a box (``core/contact_location.py``), against the
geometry worked out by hand: a 15.8 x 6.6 cm box (the cracker box's footprint) pushed along
+x by a gripper 10 cm wide, on its end face or, turned by 90 degrees, on its long face."""

import numpy as np

from stucco_drake.core.contact_location import (
    contact_location_costs,
    lateral_offsets,
    push_frames,
)
from stucco_drake.core.pose_penetration import sample_cross_section
from stucco_drake.core.shapes import BoxSdf

BOX = BoxSdf((0.079, 0.033, 0.1))
FILL = sample_cross_section(BOX, 0.0025)
#: The gripper's footprint about its origin: 8 cm deep, from y = -5 to +5 cm.
FOOTPRINT = np.array([[x, y] for x in (-0.04, 0.0, 0.04) for y in (-0.05, 0.0, 0.05)])
#: The face the push meets lies at x = 0.1 in both readings.
END_ON = np.array([0.1 + 0.079, 0.0, 0.0])  # long axis along x: the end face, y in +-3.3 cm
TURNED = np.array([0.1 + 0.033, 0.03, np.pi / 2])  # long face, y in 3 +- 7.9 cm


def test_the_end_face_is_met_over_part_of_the_front_and_a_long_face_over_all_of_it():
    gripper = np.array([[0.06, 0.03]])  # its front 4 cm ahead, at the face
    direction = np.array([[1.0, 0.0]])
    # End face: it covers y in [-3.3, 3.3] cm, the front [-2, 8] cm: the overlap [-2, 3.3]
    # has its middle at 0.65 cm, 2.35 cm right of the gripper's centre line. The long face
    # covers the whole front: its middle is the centre line.
    sensed = np.array([[0.1, 0.0065, 0.05]])
    offsets = lateral_offsets(np.array([END_ON, TURNED]), FILL, sensed, gripper, direction,
                              FOOTPRINT)  # fmt: skip
    # Within the fill's spacing (2.5 mm) of the hand-worked middles.
    np.testing.assert_allclose(offsets[:, 0], [0.0, 0.0065 - 0.03], atol=0.0025)
    costs = contact_location_costs(np.array([END_ON, TURNED]), np.ones((2, 1), bool), FILL,
                                   sensed, gripper, direction, FOOTPRINT, noise=0.015)  # fmt: skip
    assert costs[0] < 0.02 and abs(costs[1] - 0.0235**2 / (2 * 0.015**2)) < 0.3
    # A point the pose does not explain costs nothing; a pose nothing of which lies ahead
    # within the gripper's width costs the cap.
    assert contact_location_costs(np.array([TURNED]), np.zeros((1, 1), bool), FILL, sensed,
                                  gripper, direction, FOOTPRINT, noise=0.015)[0] == 0.0
    aside = np.array([[0.06, 0.3]])
    assert contact_location_costs(np.array([END_ON]), np.ones((1, 1), bool), FILL, sensed,
                                  aside, direction, FOOTPRINT, noise=0.015)[0] == 4.5


def test_only_points_ahead_of_a_push_count_as_met_by_it():
    """Actions' ends at x = 0, 0.03 (pushed +x), 0.01 (backed off), 0.01 (held still): a point
    ahead of the push counts, with direction +x; the same point sensed while backing off,
    while still, or in the first action (no motion known) does not."""
    positions = np.array([[0.0, 0.0, 0.1], [0.03, 0.0, 0.1], [0.01, 0.0, 0.1],
                          [0.01, 0.0, 0.1]])  # fmt: skip
    point = [0.07, 0.0, 0.1]
    pushed, directions = push_frames(positions, [1, 2, 3, 0], np.array([point] * 4))
    assert pushed.tolist() == [True, False, False, False]
    np.testing.assert_allclose(directions[0], [1.0, 0.0])
