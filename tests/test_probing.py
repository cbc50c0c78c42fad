"""The guarded probes of the target's likeliest pose (core/probing.py), against geometry
computed by hand: face points on the box's surface, travel paths that stay out of it and are
as short as going round its corners, and touches where a box that is not at the believed pose
really is."""

import itertools

import numpy as np
import pytest

from stucco_drake.core.probe_params import ProbeParams
from stucco_drake.core.probe_paths import travel_waypoints
from stucco_drake.core.probing import FaceProbePolicy, plan_probes
from stucco_drake.core.shapes import BoxSdf, CylinderSdf

# A cracker box standing up: 6 cm across its long faces, 15.8 cm along them (m).
BOX = BoxSdf(half_extents=(0.03, 0.079, 0.105))
# A rectangular gripper footprint (m, W axes): 8 cm along x, 10 cm along y.
FOOTPRINT = np.array([[sx * 0.04, sy * 0.05] for sx in (-1, 1) for sy in (-1, 1)])


def box_distance(pose, xy) -> np.ndarray:
    """Signed distance (m) of planar points to BOX's outline at pose (x, y, yaw)."""
    c, s = np.cos(pose[2]), np.sin(pose[2])
    local = (np.atleast_2d(xy) - pose[:2]) @ np.array([[c, -s], [s, c]])
    return BOX(np.column_stack([local, np.zeros(len(local))]))


def test_probes_lie_on_the_faces_seen_from_the_gripper():
    pose = np.array([0.2, 0.0, np.radians(30)])
    probes = plan_probes(pose, BOX, gripper_xy=[0.0, 0.0], params=ProbeParams())
    assert len(probes) == 3
    for probe in probes:
        # On the surface (1e-12 m) with a unit outward normal: 1 cm out is 1 cm away.
        assert abs(box_distance(pose, probe.point)[0]) < 1e-12
        assert box_distance(pose, probe.point + 0.01 * probe.normal)[0] == pytest.approx(0.01)
    # The two long-face touches share the long face's normal, which faces the gripper, and lie
    # half a half-length either side of its centre (2 * 0.5 * 0.079 m apart).
    assert np.allclose(probes[0].normal, probes[1].normal)
    assert probes[0].normal @ (np.zeros(2) - pose[:2]) > 0
    assert np.linalg.norm(probes[0].point - probes[1].point) == pytest.approx(0.079)
    # The third is the centre of a short face: perpendicular normal, 0.079 m from the centre.
    assert abs(probes[2].normal @ probes[0].normal) < 1e-12
    assert np.linalg.norm(probes[2].point - pose[:2]) == pytest.approx(0.079)


def test_cylinder_probes_are_45_degrees_either_side_of_the_gripper():
    can = CylinderSdf(radius=0.05, half_height=0.07)
    probes = plan_probes([0.3, 0.1, 0.0], can, gripper_xy=[0.3, -0.2], params=ProbeParams())
    angles = sorted(np.degrees(np.arctan2(p.normal[1], p.normal[0])) for p in probes)
    assert angles == pytest.approx([-135.0, -45.0])
    for p in probes:
        assert np.linalg.norm(p.point - [0.3, 0.1]) == pytest.approx(0.05)


def test_travel_goes_round_the_box_by_the_shorter_way_and_never_through_it():
    centre, half = np.array([0.0, 0.0]), np.array([0.05, 0.1])
    start, goal = np.array([-0.2, 0.02]), np.array([0.2, 0.02])
    path = [start, *travel_waypoints(start, goal, centre, half, 0.0)]
    for a, b in itertools.pairwise(path):
        s = np.linspace(0, 1, 200)[:, None]
        points = a + s * (b - a)
        inside = np.all(np.abs(points - centre) < half - 1e-6, axis=1)
        assert not inside.any()
    # Round the two corners on the near side (y = +0.1, 1 mm out): start -> (-0.051, 0.101)
    # -> (0.051, 0.101) -> goal, by hand.
    corner = np.array([0.051, 0.101])
    expected = 2 * np.hypot(0.2 - corner[0], corner[1] - 0.02) + 2 * corner[0]
    length = sum(np.linalg.norm(b - a) for a, b in itertools.pairwise(path))
    assert length == pytest.approx(expected, abs=1e-9)
    # A segment clear of the box is one straight move.
    assert len(travel_waypoints([-0.2, 0.3], [0.2, 0.3], centre, half, 0.0)) == 1


def footprint_gap(xy, pose) -> float:
    """Least signed distance (m) from the rectangular footprint at xy to BOX at pose (the
    footprint sampled on a 2 mm grid)."""
    gx, gy = np.meshgrid(np.arange(-0.04, 0.0401, 0.002), np.arange(-0.05, 0.0501, 0.002))
    cells = np.column_stack([gx.ravel(), gy.ravel()]) + xy
    return float(box_distance(pose, cells).min())


def guarded_move(xy, step, pose):
    """(where, touched): the footprint moved by ``step`` in 1/30 increments, stopped at the
    first that would overlap BOX at ``pose`` (x, y, yaw), or at any of several poses (k, 3)."""
    poses = np.atleast_2d(pose)
    for fraction in np.linspace(0, 1, 31)[1:]:
        if min(footprint_gap(xy + fraction * step, p) for p in poses) <= 0:
            return xy + (fraction - 1 / 30) * step, True
    return xy + step, False


def test_policy_touches_a_box_that_is_not_where_it_is_believed():
    """A kinematic gripper that moves by exactly each step, stopped at the face it touches;
    the box is 1.5 cm and 10 degrees off the believed pose. All three probes touch, and each
    touch is within one approach step of the true face."""
    believed = np.array([0.2, 0.0, np.radians(90)])
    true = believed + np.array([0.015, -0.01, np.radians(10)])
    params = ProbeParams(direct_only=False, max_bumps=2)
    policy = FaceProbePolicy(BOX, FOOTPRINT, max_step=0.03, params=params)
    xy, in_contact, gaps = np.array([0.2, -0.2]), False, []
    for _ in range(params.max_actions):
        step = policy.next_step(xy, in_contact, believed)
        if step is None:
            break
        xy, in_contact = guarded_move(xy, step, true)
        if in_contact and policy._last_phase == "approach":
            gaps.append(footprint_gap(xy, true))
    assert policy.touches == 3 and policy.probes_done == 3
    # Stopped at most one increment (1/30 of a step of at most 3 cm) short of the true face.
    assert len(gaps) == 3 and max(gaps) <= 0.03 / 30 + 1e-9


def test_a_contact_while_travelling_is_backed_off_from_and_the_probe_planned_again():
    """The gripper starts on the far side of the box; its first travel step is reported in
    contact (something in the way): the next step goes straight back by ``back_off``, and the
    probe after it is planned again, not skipped."""
    pose = np.array([0.2, 0.0, 0.0])
    params = ProbeParams(direct_only=False)
    policy = FaceProbePolicy(BOX, FOOTPRINT, max_step=0.03, params=params)
    xy = np.array([0.2, -0.25])
    first = policy.next_step(xy, False, pose)
    back = policy.next_step(xy + first, True, pose)
    assert np.linalg.norm(back) == pytest.approx(params.back_off)
    assert back @ first == pytest.approx(-np.linalg.norm(first) * params.back_off)
    assert policy.bumps == 1 and policy.probes_done == 0
    again = policy.next_step(xy + first + back, False, pose)
    assert again is not None and policy.probes_done == 0


def test_travel_from_the_boxs_edge_leaves_it_first_and_never_crosses_it():
    """A start on the box's boundary (where a retreat can leave the gripper) is taken out
    through the nearest side, then round the corners: no point of the path is inside."""
    centre, half = np.array([0.0, 0.0]), np.array([0.05, 0.1])
    goal = np.array([-0.2, 0.0])
    R = np.array([[np.cos(np.radians(20)), -np.sin(np.radians(20))],
                  [np.sin(np.radians(20)), np.cos(np.radians(20))]])
    start = centre + R @ [0.02, -0.1]
    path = [start, *travel_waypoints(start, goal, centre, half, np.radians(20))]
    for a, b in itertools.pairwise(path):
        points = a + np.linspace(0, 1, 400)[:, None] * (b - a)
        local = points @ R  # rows R^T p
        assert not np.all(np.abs(local) < half - 1e-6, axis=1).any()
    assert np.allclose(path[-1], goal)


def test_by_default_only_probes_reached_in_a_straight_line_are_made():
    """From straight in front of the long face (gripper 20 cm off it along its normal), both
    long-face stand-offs are in sight and the end face is not (the box is in the way):
    two probes are made, the end face is skipped."""
    pose = np.array([0.2, 0.0, np.radians(90)])  # long faces' normals along world y
    policy = FaceProbePolicy(BOX, FOOTPRINT, max_step=0.03)
    xy, in_contact, touched_at = np.array([0.2, -0.25]), False, []
    for _ in range(policy.params.max_actions):
        step = policy.next_step(xy, in_contact, pose)
        if step is None:
            break
        xy, in_contact = guarded_move(xy, step, pose)
        if in_contact:
            touched_at.append(xy.copy())
    assert policy.probes_done == 3 and policy.touches == 2 and policy.bumps == 0
    # Both touches on the long face (y = -0.03), at x = 0.2 -+ 0.0395 (half a half-length).
    # (the guarded move stops within one 1 mm increment; the approach is along y only)
    assert sorted(p[0] for p in touched_at) == pytest.approx([0.2 - 0.0395, 0.2 + 0.0395],
                                                             abs=1e-3)


def test_end_face_first_touches_the_short_face_before_the_long_one():
    pose = np.array([0.2, 0.0, np.radians(30)])
    default = plan_probes(pose, BOX, gripper_xy=[0.0, 0.0], params=ProbeParams())
    first = plan_probes(pose, BOX, gripper_xy=[0.0, 0.0],
                        params=ProbeParams(end_face_first=True))  # fmt: skip
    # The same three touches, the short face's (0.079 m from the centre) moved to the front.
    assert np.linalg.norm(first[0].point - pose[:2]) == pytest.approx(0.079)
    for a, b in zip([default[2], default[0], default[1]], first, strict=True):
        assert np.array_equal(a.point, b.point) and np.array_equal(a.normal, b.normal)


@pytest.mark.parametrize("yaw_deg", [90.0, 30.0])
def test_extent_margin_keeps_the_footprint_clearance_off_the_box_and_starts_nearer(yaw_deg):
    """With ``extent_margin`` the gripper's origin keeps out of the box grown by the
    footprint's extent along the box's axes (plus ``clearance``), not by its radius (6.4 cm).
    The footprint (8 x 10 cm) then never comes nearer the box than ``clearance`` while
    travelling, though nearer than the radius would allow (the extent is the tighter margin),
    and all three probes touch. At yaw 90 degrees the approach to the long face (normal -y)
    starts 5 + 3 + 2 = 10 cm off it (half the footprint's 10 cm along y, clearance,
    standoff), against 6.4 + 3 + 2 = 11.4 cm with the radius."""
    pose = np.array([0.2, 0.0, np.radians(yaw_deg)])
    params = ProbeParams(extent_margin=True, direct_only=False, discriminate=False,
                         max_actions=60)  # fmt: skip
    policy = FaceProbePolicy(BOX, FOOTPRINT, max_step=0.03, params=params)
    xy, in_contact, travel_gaps, starts = np.array([0.2, -0.25]), False, [], []
    for _ in range(params.max_actions):
        phase_before = policy._phase
        step = policy.next_step(xy, in_contact, pose)
        if step is None:
            break
        if policy._last_phase == "approach" and phase_before == "travel":
            starts.append(xy.copy())
        xy, in_contact = guarded_move(xy, step, pose)
        if policy._last_phase == "travel":
            travel_gaps.append(footprint_gap(xy, pose))
    assert policy.touches == 3 and policy.bumps == 0
    # The actions by phase add up to them; one retreat after each touch.
    assert sum(policy.phase_actions.values()) == policy.actions
    assert policy.phase_actions["retreat"] == 3 and policy.phase_actions["travel"] > 0
    # Corners are rounded 1 mm out; the footprint is sampled on a 2 mm grid (exact at its edges).
    assert min(travel_gaps) >= params.clearance - 1e-6
    if yaw_deg == 90.0:
        # Along the long face the radius would keep the footprint 6.4 - 5 + 3 = 4.4 cm off.
        assert min(travel_gaps) < 0.044 - 0.005
        # The first approach starts where the travel ended: 10 cm below the face y = -0.03.
        assert starts[0][1] == pytest.approx(-0.03 - 0.10, abs=params.arrive_tolerance)
