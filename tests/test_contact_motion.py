"""The contact-motion observation models: the paper's EE displacement and its normal part."""

from unittest.mock import ANY

import numpy as np
import pytest

from stucco_drake.core import BoxSdf
from stucco_drake.core.contact_motion import (
    CONE_FRICTION,
    clip_to_friction_cone,
    contact_motion,
    project_onto_normals,
    robot_surface_normals,
)
from stucco_drake.core.sdf import GridSdf
from stucco_drake.eval.replay import log_penetration, observed_dx, replay
from stucco_drake.eval.synthetic_episode import synthetic_episode


@pytest.fixture(scope="module")
def box_robot() -> GridSdf:
    """A 4 x 2 x 2 cm box end effector in its frame E, as a 1 mm grid."""
    return GridSdf.build(
        BoxSdf((0.02, 0.01, 0.01)), [-0.03, -0.02, -0.02], [0.03, 0.02, 0.02], 1e-3
    )


def test_projection_keeps_the_normal_part_with_its_sign():
    dx = np.array([[0.01, 0.02, 0.0], [-0.01, 0.02, 0.0], [0.0, 0.03, 0.0]])
    normals = np.array([[2.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 0.0]])  # not unit; unknown
    signed = project_onto_normals(dx, normals)
    # Sliding along the face (y) is dropped; a retreat moves the point back; unknown: unchanged.
    np.testing.assert_allclose(signed, [[0.01, 0, 0], [-0.01, 0, 0], [0, 0.03, 0]], atol=1e-15)
    pushes = project_onto_normals(dx, normals, signed=False)
    np.testing.assert_allclose(pushes, [[0.01, 0, 0], [0, 0, 0], [0, 0.03, 0]], atol=1e-15)
    with pytest.raises(ValueError, match="normals"):
        project_onto_normals(dx, normals[:2])


def test_friction_cone_keeps_a_sticking_push_and_clips_a_sliding_one():
    """Normal +x (not unit), coefficient 0.3: a push 1 cm in x may carry 3 mm sideways."""
    normals = np.array([[2.0, 0.0, 0.0]] * 4 + [[0.0, 0.0, 0.0]])
    dx = np.array([
        [0.01, 0.002, 0.0],  # inside the cone: sticks, moves whole
        [0.01, 0.02, 0.0],  # outside: the 2 cm sideways part is cut to 3 mm, direction kept
        [0.01, -0.012, 0.016],  # outside, tangent part (-0.012, 0.016) of 2 cm cut to 3 mm
        [-0.01, 0.02, 0.0],  # a retreat: only the (signed) normal part
        [0.0, 0.03, 0.0],  # unknown normal: unchanged
    ])
    np.testing.assert_allclose(
        clip_to_friction_cone(dx, normals, 0.3),
        [[0.01, 0.002, 0.0], [0.01, 0.003, 0.0], [0.01, -0.0018, 0.0024], [-0.01, 0.0, 0.0],
         [0.0, 0.03, 0.0]], atol=1e-15)  # fmt: skip
    # Coefficient 0 is the normal model; a huge one the end effector's displacement.
    np.testing.assert_allclose(clip_to_friction_cone(dx, normals, 0.0),
                               project_onto_normals(dx, normals), atol=1e-15)  # fmt: skip
    np.testing.assert_allclose(clip_to_friction_cone(dx[:3], normals[:3], 1e3), dx[:3])
    with pytest.raises(ValueError, match="friction"):
        clip_to_friction_cone(dx, normals, -0.1)
    with pytest.raises(ValueError, match="friction"):
        clip_to_friction_cone(dx, normals, float("nan"))


def test_normals_point_out_of_the_robot_in_the_world_frame(box_robot):
    """The robot is turned 90 degrees about z: its +x face (in E) faces world +y."""
    rotation = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    position = np.array([0.5, -0.2, 0.1])
    local = np.array([[0.02, 0.003, 0.002], [0.005, -0.01, -0.004]])  # +x face, -y face in E
    points = position + local @ rotation.T
    normals = robot_surface_normals(box_robot, points, position, rotation)
    np.testing.assert_allclose(normals, [[0, 1, 0], [1, 0, 0]], atol=1e-9)
    # Outside the grid the gradient is unknown: a zero row.
    far = robot_surface_normals(box_robot, position + np.array([1.0, 0.0, 0.0]), position, rotation)
    np.testing.assert_array_equal(far, 0.0)


def test_a_point_bridging_a_gap_gets_the_hull_normal():
    """Two 2 x 4 x 2 cm fingers 2 cm apart along x (a gap at |x| < 1 cm). A contact isolated
    in the gap's mouth, on the hull's +y face, is where an object touching both fingers' +y
    faces has its centre of pressure: its normal is +y. The SDF's own gradient there points
    at the nearer finger's side instead."""
    left, right = BoxSdf((0.01, 0.02, 0.01)), BoxSdf((0.01, 0.02, 0.01))

    def fingers(p):
        return np.minimum(left(p - [-0.02, 0.0, 0.0]), right(p - [0.02, 0.0, 0.0]))

    robot = GridSdf.build(fingers, [-0.04, -0.03, -0.02], [0.04, 0.03, 0.02], 1e-3)
    mouth = np.array([[0.004, 0.02, 0.0], [-0.004, 0.015, 0.0]])  # on and 5 mm inside the hull
    hull = robot_surface_normals(robot, mouth, np.zeros(3))
    np.testing.assert_allclose(hull, [[0, 1, 0], [0, 1, 0]], atol=1e-9)
    sdf_only = robot_surface_normals(robot, mouth, np.zeros(3), bridge_distance=None)
    assert np.all(np.abs(sdf_only[:, 0]) > 0.9)  # sideways, at the nearer finger
    # On a finger's real surface the SDF decides: its +y face, and its inner side face.
    real = np.array([[0.02, 0.02, 0.0], [0.01, 0.0, 0.0]])
    np.testing.assert_allclose(robot_surface_normals(robot, real, np.zeros(3)),
                               [[0, 1, 0], [-1, 0, 0]], atol=1e-9)  # fmt: skip


def test_contact_motion_models(box_robot):
    """Pushing diagonally on the robot's +x face moves the point by the push's x part only."""
    points = np.array([[0.02, 0.0, 0.0]])
    dx = np.array([[0.01, 0.02, 0.005]])
    np.testing.assert_array_equal(contact_motion("ee", dx), dx)
    normal = contact_motion("normal", dx, points, box_robot, np.zeros(3))
    np.testing.assert_allclose(normal, [[0.01, 0.0, 0.0]], atol=1e-9)
    # The cone lets the push carry CONE_FRICTION x 1 cm sideways, along the tangent part (y, z).
    cone = contact_motion("cone", dx, points, box_robot, np.zeros(3))
    side = CONE_FRICTION * 0.01 * np.array([0.02, 0.005]) / np.hypot(0.02, 0.005)
    np.testing.assert_allclose(cone, [[0.01, side[0], side[1]]], atol=1e-9)
    for model in ("normal", "cone"):
        with pytest.raises(ValueError, match=f"'{model}' needs"):
            contact_motion(model, dx)
    with pytest.raises(ValueError, match="model"):
        contact_motion("tangent", dx)


def test_replay_moves_points_by_the_chosen_model():
    """On a synthetic episode (a disc pushing boxes): "ee" is the default; "normal" keeps each
    contact's motion along the disc's radius, which is all of a firm push's motion."""
    log = synthetic_episode("SYN2", 0)
    penetration = log_penetration(log)
    normal = observed_dx(log, "normal", penetration)
    np.testing.assert_array_equal(observed_dx(log, "ee", None), log.contact_dx)
    steps = np.repeat(np.arange(log.n_actions), np.diff(log.contact_offsets))
    radial = log.contact_points[:, :2] - log.ee_position[steps, :2]
    # The projected motion is along the radius (within the 1 mm grid's gradient error, 1.4
    # degrees here) and no longer than the EE's.
    cross = radial[:, 0] * normal[:, 1] - radial[:, 1] * normal[:, 0]
    sine = cross / np.linalg.norm(radial, axis=1) / np.linalg.norm(normal[:, :2], axis=1)
    assert np.degrees(np.abs(np.arcsin(sine))).max() < 2.0
    assert np.all(np.linalg.norm(normal, axis=1) <= np.linalg.norm(log.contact_dx, axis=1) + 1e-12)
    # The cone model keeps that normal part and at most CONE_FRICTION times it sideways.
    cone = observed_dx(log, "cone", penetration)
    unit = normal / np.maximum(np.linalg.norm(normal, axis=1, keepdims=True), 1e-12)
    along = np.sum(cone * unit, axis=1)
    np.testing.assert_allclose(along[:, None] * unit, normal, atol=1e-12)
    sideways = np.linalg.norm(cone - normal, axis=1)
    assert np.all(sideways <= CONE_FRICTION * np.maximum(along, 0.0) + 1e-12)
    assert sideways.max() > 1e-4  # the disc's pushes do carry the boxes sideways
    assert replay(log, "dbscan") == {**replay(log, "dbscan", dx_model="ee"), "wall_time_s": ANY}
    row = replay(log, "stucco", dx_model="normal")
    assert row["n_contacts"] == log.n_contacts and row["ce_cm"] < 0.1
    with pytest.raises(ValueError, match="dx_model"):
        replay(log, "stucco", dx_model="tangent")
