"""The flank touch's plan (core/flank.py), checked against the box's own outline: the
forward move keeps the footprint clear of the box, and the sideways push from there meets the
face beside the one touched, near the touched corner."""

import numpy as np
import pytest
from test_probing import FOOTPRINT, box_distance, footprint_gap, guarded_move

from stucco_drake.core.flank import plan_flank

REACH = 0.079  # BOX's largest half extent (m)
SETTINGS = {"depth": 0.03, "margin": 0.01, "back_off": 0.02}


def first_touch(start, end, pose):
    """(where the footprint moving from ``start`` to ``end`` stops at BOX at ``pose``, whether
    it touched, the move's resolution: a 1/30 of it)."""
    where, touched = guarded_move(np.asarray(start), np.asarray(end) - start, pose)
    return where, touched, np.linalg.norm(np.subtract(end, start)) / 30


def clear_along(start, end, pose) -> float:
    """The least footprint gap (m) to BOX over the straight move start -> end (1 mm steps)."""
    n = int(np.ceil(np.linalg.norm(np.subtract(end, start)) / 1e-3)) + 1
    return min(footprint_gap(p, pose) for p in np.linspace(start, end, n))


def test_an_off_centre_touch_is_flanked_on_the_other_side_and_meets_the_long_face():
    """The box turned 90 degrees spans x 0.221..0.379, y 0.14..0.20. The gripper (y 0.10,
    front 0.05..0.15) touched it at x 0.181: the overlap is y 0.14..0.15, its middle 0.145,
    4.5 cm left of the centre line. The flank goes right (-y), its left edge 1 cm clear of the
    edge (y 0.14) estimated from the contact, forward until the front is 3 cm past the face,
    and the push back (+y) meets the box's -y long face within those 3 cm of the corner."""
    pose = np.array([0.3, 0.17, np.radians(90)])
    gripper, contact = np.array([0.181, 0.10]), np.array([0.221, 0.145])
    flank = plan_flank(gripper, contact, [1.0, 0.0], FOOTPRINT, REACH, **SETTINGS)
    assert flank.side == pytest.approx([0.161, 0.08])
    assert flank.past == pytest.approx([0.211, 0.08])
    assert clear_along(gripper - [0.02, 0.0], flank.side, pose) > 0.005
    assert clear_along(flank.side, flank.past, pose) >= 0.01 - 1e-9
    where, touched, resolution = first_touch(flank.past, flank.push_end, pose)
    assert touched
    # The footprint's +y side (y + 0.05) is at the long face (y 0.14), to the move's resolution.
    assert where[1] + 0.05 == pytest.approx(0.14, abs=resolution)
    # Along x, the footprint overlaps the face only between the corner (0.221) and 3 cm past.
    assert where[0] + 0.04 == pytest.approx(0.251)


def test_a_centred_touch_clears_the_target_reach_and_meets_the_end_face():
    """The box unturned spans x 0.27..0.33, y 0.021..0.179: the gripper at y 0.10 meets its
    long face across its whole front (contact centred). Nothing tells how far the box reaches,
    so the flank clears the target's largest half extent (7.9 cm) and 1 cm, on the left (+y)
    first, and the push back meets the +y end face (y 0.179). With the left out of the
    workspace it goes right and meets the -y end face (y 0.021)."""
    pose = np.array([0.30, 0.10, 0.0])
    gripper, contact = np.array([0.23, 0.10]), np.array([0.27, 0.10])
    for allowed, face in ((lambda xy: True, 0.179), (lambda xy: xy[1] < 0.2, 0.021)):
        flank = plan_flank(gripper, contact, [1.0, 0.0], FOOTPRINT, REACH,
                           in_workspace=allowed, **SETTINGS)
        assert clear_along(flank.side, flank.past, pose) >= 0.01 - 1e-9
        where, touched, resolution = first_touch(flank.past, flank.push_end, pose)
        assert touched
        near_side = where[1] - 0.05 if face > 0.1 else where[1] + 0.05
        assert near_side == pytest.approx(face, abs=resolution)
        # The touch lies on that end face, within its 6 cm (x 0.27..0.33).
        assert abs(box_distance(pose, [[where[0] + 0.04, face]])[0]) < 1e-9


def test_no_side_in_the_workspace_means_no_flank():
    gripper, contact = np.array([0.23, 0.10]), np.array([0.27, 0.10])
    assert plan_flank(gripper, contact, [1.0, 0.0], FOOTPRINT, REACH,
                      in_workspace=lambda xy: abs(xy[1] - 0.1) < 0.05, **SETTINGS) is None


def outline_touched(where, pose) -> np.ndarray:
    """The mean of BOX's outline points (1 mm apart) within 2 mm of the nearest one to the
    footprint at where (the footprint stops short of the box by up to a move's resolution)."""
    t = np.arange(-1.0, 1.0, 0.001)
    hx, hy = 0.03, 0.079
    local = np.vstack([np.column_stack([hx * np.ones_like(t), hy * t]),
                       np.column_stack([-hx * np.ones_like(t), hy * t]),
                       np.column_stack([hx * t, hy * np.ones_like(t)]),
                       np.column_stack([hx * t, -hy * np.ones_like(t)])])  # fmt: skip
    c, s = np.cos(pose[2]), np.sin(pose[2])
    outline = local @ np.array([[c, s], [-s, c]]) + pose[:2]
    gap = np.linalg.norm(np.maximum(np.abs(outline - where) - [0.04, 0.05], 0.0), axis=1)
    return outline[gap <= gap.min() + 0.002].mean(axis=0)


@pytest.mark.parametrize(("ahead", "past_corner"), [(0.0, (0.0, 0.005)), (0.05, (0.015, 0.04))])
def test_retries_that_also_go_ahead_reach_past_a_slanted_end_face(ahead, past_corner):
    """The box 28.5 degrees from end-on, its 6 cm end face slanting away to the left (its far
    corner 2.9 cm further along x than its near one): the gripper's push along +x meets the
    end face's near corner, and the flank's first forward move (left, +y) meets the end face
    again, further along. Going only further out on the retry (``ahead`` 0), the gripper's
    side spans the far corner and the sideways push back meets the box there, where the end
    face and the long face explain a touch alike; going 5 cm further ahead too, the gripper's
    rear end passes the corner and the push meets the long face 1.5-4 cm past it (distances
    along the long face, against the box's outline)."""
    pose = np.array([0.262, 0.055, np.radians(61.5)])
    start = np.array([0.0, 0.104])
    gripper, touched, _ = first_touch(start, np.array([0.3, 0.104]), pose)
    assert touched
    flank = plan_flank(gripper, outline_touched(gripper, pose), [1.0, 0.0], FOOTPRINT, REACH,
                       depth=0.08, margin=0.01, back_off=0.02)  # fmt: skip
    retries = 0
    while True:
        where, touched, _ = first_touch(flank.side, flank.past, pose)
        if not touched or retries == 2:
            break
        flank, retries = flank.further(0.03, ahead), retries + 1
    assert (touched, retries) == (False, 1)
    where, touched, _ = first_touch(flank.past, flank.push_end, pose)
    assert touched
    c, s = np.cos(pose[2]), np.sin(pose[2])
    local = (outline_touched(where, pose) - pose[:2]) @ np.array([[c, -s], [s, c]])
    # On the +x long face (local x 0.03), its distance from the far corner (local y 0.079).
    assert local[0] == pytest.approx(0.03, abs=0.003)
    assert past_corner[0] <= 0.079 - local[1] <= past_corner[1]
