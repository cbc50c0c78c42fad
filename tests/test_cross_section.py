"""The 2-D geometry every pose estimate rests on: a shape's cross-section distance and points
taken into and out of pose frames, against hand-worked values and the 3-D shapes."""

import numpy as np

from stucco_drake.core import BoxSdf, CylinderSdf
from stucco_drake.core.icp import cross_section_sdf, rotations, to_pose_frames, transform


def test_cross_section_distance_in_closed_form():
    # Off-centre shapes at any height: the distance depends on x-y alone (extruded in z).
    box = BoxSdf((0.03, 0.08, 0.1), center=(0.01, -0.02, 0.1))
    points = np.array([[0.01, -0.02],     # centre: the nearest side 3 cm away
                       [0.06, -0.02],     # 2 cm beyond the +x side
                       [0.05, 0.07],      # 1 cm beyond the +x and +y corner on each axis
                       [0.035, 0.05]])    # inside, 0.5 cm from the +x side, 1 cm from +y
    assert np.allclose(cross_section_sdf(box)(points),
                       [-0.03, 0.02, np.sqrt(2.0) * 0.01, -0.005], atol=1e-15)
    can = CylinderSdf(0.04, 0.06, center=(0.1, 0.0, 0.06))
    assert np.allclose(cross_section_sdf(can)(np.array([[0.1, 0.0], [0.1, 0.05], [0.13, 0.04]])),
                       [-0.04, 0.01, 0.01], atol=1e-15)
    # The 3-D shape's own function agrees at its mid-height, where no cap is nearer.
    grid = np.random.default_rng(0).uniform(-0.2, 0.2, (500, 2))
    for shape in (box, can):
        mid = np.column_stack([grid, np.full(len(grid), shape.center[2])])
        inside_caps = shape(mid) > -0.05  # within 5 cm of a side, farther from the caps
        assert np.allclose(cross_section_sdf(shape)(grid)[inside_caps], shape(mid)[inside_caps],
                           atol=1e-15)


def test_pose_frames_invert_the_transform():
    rng = np.random.default_rng(1)
    poses = rng.uniform([-0.3, -0.3, -np.pi], [0.3, 0.3, np.pi], (7, 3))
    local = rng.uniform(-0.1, 0.1, (11, 2))
    world = transform(poses, local)
    assert np.allclose(to_pose_frames(poses, world), local, atol=1e-15)  # one set per pose
    # Shared points: each pose's frame, R(yaw)^T (p - t) worked out with explicit matrices.
    shared = to_pose_frames(poses, local)
    for pose, frame in zip(poses, shared, strict=True):
        assert np.allclose(frame, (local - pose[:2]) @ rotations(pose[2]), atol=1e-15)
