"""The contact-tracking chain on a second robot: the SCARA probe arm pushing three boxes.

The robot (``models/scara_probe``) is checked against its own written dimensions (uniform-solid
inertias, closed-form planar kinematics); its end effector's samples and pxpen grid against the
exact sphere. Then one run of ``examples/second_robot.py`` (seed 0, 34 actions, 2 ms steps) is
scored against the plant's own contact results (``stucco_drake.second_robot`` defines every
figure). Each tolerance says where it comes from; the measured values are in the comments.
"""

from __future__ import annotations

import numpy as np
import pytest
from pydrake.math import RigidTransform, RollPitchYaw, RotationMatrix

from stucco_drake.core.shapes import SphereSdf
from stucco_drake.robot.scara_probe import (
    PROBE_FRAME,
    probe_grid_sdf,
    probe_penetration,
    probe_radius,
    probe_surface_samples,
    scara_robot_plant,
)
from stucco_drake.scenes.probe_station import PUSH_ACTIONS, free_space_statistics
from stucco_drake.second_robot import GRAZE_FORCE, run_second_robot
from stucco_drake.systems.contact_detector import DEFAULT_FLOOR_STD, default_threshold
from stucco_drake.systems.contact_truth import TRUTH_STRONGEST

# The model's dimensions as its README gives them (m, kg/m^3).
L1, L2, Z_PROBE, RADIUS = 0.225, 0.175, 0.2 + 0.05 - 0.21, 0.025
ALUMINIUM, STEEL = 2700.0, 7850.0
SPACING = 0.004  # the CPF's default surface sample spacing (m)
#: The actions that push a box, by the scene's design (PUSH_ACTIONS' comments).
PUSHES = {0, 1, 10, 19, 20, 31, 32}


def _box(mass, x, y, z):
    return mass, np.diag([y * y + z * z, x * x + z * z, x * x + y * y]) * mass / 12


def _rod(mass, r, length):
    side = mass * (3 * r * r + length * length) / 12
    return mass, np.diag([side, side, mass * r * r / 2])


def test_masses_and_inertias_are_the_solids_the_model_draws():
    plant = scara_robot_plant()
    sphere = ALUMINIUM * 4 / 3 * np.pi * RADIUS**3
    expected = {
        "arm1": _box(ALUMINIUM * 0.225 * 0.08 * 0.05, 0.225, 0.08, 0.05),
        "arm2": _box(ALUMINIUM * 0.175 * 0.06 * 0.04, 0.175, 0.06, 0.04),
        "quill": _rod(STEEL * np.pi * 0.008**2 * 0.2, 0.008, 0.2),
        "probe": (sphere, np.eye(3) * 0.4 * sphere * RADIUS**2),
    }
    for name, (mass, inertia) in expected.items():
        M = plant.GetBodyByName(name).default_spatial_inertia()
        about_com = M.Shift(M.get_com()).CalcRotationalInertia().CopyToFullMatrix3()
        # The file rounds to 7 significant digits.
        assert M.get_mass() == pytest.approx(mass, rel=1e-6), name
        np.testing.assert_allclose(about_com, inertia, rtol=1e-5, atol=1e-12, err_msg=name)


def test_forward_kinematics_is_the_planar_scara():
    plant = scara_robot_plant()
    context = plant.CreateDefaultContext()
    for q in np.random.default_rng(0).uniform(-2.0, 2.0, (5, 3)):
        plant.SetPositions(context, q)
        X = plant.GetFrameByName(PROBE_FRAME).CalcPoseInWorld(context)
        c1, s1, c12, s12 = np.cos(q[0]), np.sin(q[0]), np.cos(q[0] + q[1]), np.sin(q[0] + q[1])
        p = [L1 * c1 + L2 * c12, L1 * s1 + L2 * s12, Z_PROBE]
        R = RotationMatrix(RollPitchYaw(0, 0, q.sum())) @ RotationMatrix.MakeXRotation(np.pi)
        np.testing.assert_allclose(X.translation(), p, atol=1e-12)
        np.testing.assert_allclose(X.rotation().matrix(), R.matrix(), atol=1e-12)


def test_probe_samples_grid_and_pxpen_are_the_sphere():
    assert probe_radius() == RADIUS
    points, normals = probe_surface_samples(np.random.default_rng(0), SPACING)
    np.testing.assert_allclose(np.linalg.norm(points, axis=1), RADIUS, atol=1e-12)
    np.testing.assert_allclose(normals, points / RADIUS, atol=1e-12)
    # One sample per spacing^2 of area (the helper's rule): 4 pi r^2 / s^2 = 491.
    assert len(points) == pytest.approx(4 * np.pi * RADIUS**2 / SPACING**2, rel=0.01)
    grid = probe_grid_sdf()
    queries = np.random.default_rng(1).uniform(-0.03, 0.03, (2000, 3))
    # Trilinear interpolation of |p| - r at 1 mm: error <= 3 h^2 / (8 |p|) < 0.1 mm here.
    near = np.linalg.norm(queries, axis=1) > 0.005
    np.testing.assert_allclose(grid(queries[near]), SphereSdf(RADIUS)(queries[near]), atol=1e-4)
    pxpen = probe_penetration()
    X = RigidTransform(RollPitchYaw(0.3, -0.2, 1.0), [0.3, 0.1, 0.04])
    inside = X.multiply([0.0, RADIUS - 0.005, 0.0])
    outside = X.multiply([0.0, 0.0, RADIUS + 0.002])
    depth = pxpen(X.translation(), np.array([inside, outside]), X.rotation().matrix())
    np.testing.assert_allclose(depth, [0.005, 0.0], atol=1e-4)


@pytest.fixture(scope="module")
def stats():
    return free_space_statistics()


def test_free_space_wrench_is_zero_for_an_exact_model(stats):
    # The discrete observer is exact for Drake's discrete plant (tests/test_observed_robot.py:
    # 3e-14 N m), and the robot model is the simulated arm: only round-off remains, so the
    # fit is its floor alone (measured: |mean| < 1e-12).
    assert np.abs(stats.mean).max() < 1e-6
    np.testing.assert_allclose(stats.covariance, np.diag(np.square(DEFAULT_FLOOR_STD)),
                               atol=1e-9)  # fmt: skip


@pytest.fixture(scope="module")
def run(stats):
    return run_second_robot(0, stats=stats)


def test_the_scene_pushes_the_boxes_it_says_it_pushes(run):
    # Independent of the chain: the plant's contact results agree with the scene's design.
    assert set(np.flatnonzero(run.truth_actions)) == PUSHES
    force = run.steps["truth"][:, TRUTH_STRONGEST]
    action = np.round(run.steps["action"][:, 0]).astype(int)
    # Every push peaks above 10x the force the detector resolves at the default threshold
    # (floor std 0.3 N times sqrt(33.1): 1.7 N); measured peaks 24-50 N.
    level = DEFAULT_FLOOR_STD[3] * np.sqrt(default_threshold())
    for k in PUSHES:
        assert force[action == k].max() > 10 * level, k
    # Grazes are only the back-offs that follow a push (measured: actions 2, 11, 21, 33).
    grazes = set(np.flatnonzero(run.graze_actions))
    assert grazes <= {k + 1 for k in PUSHES}
    assert len(PUSH_ACTIONS) - len(PUSHES) - len(grazes) >= 20
    free = ~run.truth_actions & ~run.graze_actions
    assert all(force[action == k].max() < GRAZE_FORCE for k in np.flatnonzero(free))


def test_detection_precision_and_recall(run):
    # Exact: free actions carry < 0.1 N against a 1.7 N detection level with a free-space
    # residual of round-off, so no false alarm can happen; every push is 10x over the level.
    assert run.precision == 1.0
    assert run.recall == 1.0


def test_isolation_error(run):
    # The CPF answers with a surface sample, 4 mm apart; the hydroelastic centroid lies within
    # the penetration (< 1 mm) of the probe's surface; a single contact on a sphere has one
    # admissible entry of its line of action. So the median error is at most one spacing and
    # every point within two (measured over seeds 0-3: median 0.02-0.03 cm, max 0.04-0.1 cm;
    # per step median 0.03-0.04 cm, p95 0.14-0.15 cm).
    assert np.median(run.isolation_errors) <= SPACING
    assert run.isolation_errors.max() <= 2 * SPACING
    assert len(run.step_isolation_errors) > 500  # ~10 pushes' worth of steps
    assert np.median(run.step_isolation_errors) <= SPACING
    assert np.percentile(run.step_isolation_errors, 95) <= 2 * SPACING


def test_tracking_contact_error_and_segmentation(run):
    assert len(run.points) >= len(PUSHES)
    assert set(run.truth_names) == {"box_a", "box_b", "box_c"}
    # CE: each point received within 2 spacings of its box (above) and moved with it; 0.5 cm
    # is one spacing plus the 1 mm the cone motion may leave (measured 0.05-0.09 cm).
    assert run.ce <= 0.005
    # FMI: where the boxes end, their carried true contacts are more than STUCCO's
    # segmentation radius (0.135 m at l = 0.02) apart, and within a box less, so a tracker
    # within a few mm of them segments perfectly (measured 1.0).
    carried, names = run.carried_truth, run.truth_names
    gaps = np.linalg.norm(carried[:, None] - carried[None], axis=2)
    other = names[:, None] != names[None]
    assert gaps[other].min() > 0.135 and gaps[~other].max() < 0.135
    assert run.fmi == 1.0


def test_tracked_points_follow_the_pushed_boxes(run):
    errors = run.tracking_errors()
    moved = np.linalg.norm(run.received - run.carried_truth, axis=1)
    # Points whose box moved after their contact (box_a's first two by its second push, each
    # box's first by the rest of its push; measured 2.3-3.7 cm): a tracker that left them
    # where it received them would be off by all of that (ratio 1). STUCCO's soft moves
    # follow: measured ratio 0.13 (seed 0), 0.33 at worst over seeds 0-3 (in seed 3, box_a's
    # first point misses its sideways push); half is clearly better than standing still.
    followed = moved > 0.02
    assert followed.sum() >= 4
    assert errors[followed].sum() < 0.5 * moved[followed].sum()
    # Median over all points: one sample spacing (measured 0.09-0.27 cm over seeds 0-3; in
    # seed 0 box_a's +y-face point is dragged 3 cm along +x by box_b's push 0.16 m away).
    assert np.median(errors) <= SPACING


def test_the_example_line_reports_these_figures(run):
    # examples/second_robot.py prints exactly this line for seed 0.
    line = run.line()
    assert line.startswith("second robot (SCARA probe, 3 boxes): detection precision 1.00 "
                           "recall 1.00 (7 contact, ")  # fmt: skip
    assert f"tracking CE {100 * run.ce:.2f} cm, FMI 1.000" in line
    assert f"isolation median {100 * np.median(run.isolation_errors):.2f} cm" in line
