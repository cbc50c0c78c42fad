"""Where the gripper can be touched: surface samples a ball can reach (no Drake simulation)."""

import numpy as np
import pytest

from stucco_drake.robot.gripper_samples import reachable_samples, sample_gripper_surface


def two_plates(gap: float):
    """Two 2 x 8 x 8 cm plates facing each other across ``gap`` (m) along x."""
    shapes = []
    for side in (-1.0, 1.0):
        X = np.eye(4)
        X[0, 3] = side * (gap / 2 + 0.01)
        shapes.append(("box", np.array([0.02, 0.08, 0.08]), X))
    return shapes


@pytest.mark.parametrize("gap, inner_reachable", [(0.01, False), (0.06, True)])
def test_reachable_samples_drop_faces_a_ball_cannot_touch(gap, inner_reachable):
    """A 2 cm ball fits into a 6 cm gap but not into a 1 cm one; outer faces are always
    reachable."""
    rng = np.random.default_rng(0)
    shapes = two_plates(gap)
    points, normals = sample_gripper_surface(rng, 0.004, shapes=shapes)
    dense, _ = sample_gripper_surface(rng, 0.002, shapes=shapes)
    keep = reachable_samples(points, normals, 0.02, dense)
    inner = np.abs(np.abs(points[:, 0]) - gap / 2) < 1e-6
    outer = np.abs(np.abs(points[:, 0]) - (gap / 2 + 0.02)) < 1e-6
    assert inner.sum() > 100 and outer.sum() > 100
    assert np.all(keep[outer])
    # Inner faces: all kept with the wide gap; with the narrow one, none but a rim of 1-2 cm
    # where the ball reaches past the plates' edges.
    if inner_reachable:
        assert np.all(keep[inner])
    else:
        central = inner & (np.abs(points[:, 1]) < 0.02) & (np.abs(points[:, 2]) < 0.02)
        assert central.sum() > 20 and not keep[central].any()
