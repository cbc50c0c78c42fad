"""PolicyVisualizer: the push direction and the heaviest pose hypotheses it sets in Meshcat,
against the inputs it was given (poses, weights, a step)."""

from __future__ import annotations

import types

import numpy as np
from pydrake.math import RigidTransform, RotationMatrix
from test_visualizer import BOX, translation_at, unpack, visible

from stucco_drake.systems.policy_visualizer import PolicyVisualizer, standing_height

X_WE = RigidTransform([0.1, 0.2, 0.1])
HYPOTHESES = types.SimpleNamespace(
    poses=np.array([[0.30, 0.10, 0.2], [0.35, 0.12, 0.0], [0.32, 0.08, 1.0]]),
    weights=np.array([0.2, 0.7, 0.1]))


def rotation_at(viewer, path: str) -> np.ndarray:
    """The rotation Meshcat holds for ``path``."""
    matrix = unpack(viewer._GetPackedTransform(path))["matrix"]
    return np.asarray(matrix, dtype=float).reshape(4, 4).T[:3, :3]


def test_push_and_hypotheses_heaviest_first(meshcat):
    visualizer = PolicyVisualizer(meshcat, BOX, publish_period=0.1, count=4)
    context = visualizer.CreateDefaultContext()
    visualizer.GetInputPort("planar_step").FixValue(context, [0.0, 0.03])
    visualizer.GetInputPort("ee_pose").FixValue(context, X_WE)
    visualizer.GetInputPort("pose_hypotheses").FixValue(context, HYPOTHESES)
    visualizer.ForcedPublish(context)
    # The push starts at the gripper and points along the step (+y: a quarter turn).
    assert visible(meshcat, "/stucco/policy/push") is True
    np.testing.assert_allclose(translation_at(meshcat, "/stucco/policy/push"), [0.1, 0.2, 0.1])
    np.testing.assert_allclose(rotation_at(meshcat, "/stucco/policy/push"),
                               RotationMatrix.MakeZRotation(np.pi / 2).matrix(), atol=1e-12)
    # Weights 0.7, 0.2, 0.1: poses 1, 0, 2, each standing on the table (BOX is 6 cm tall).
    assert standing_height(BOX) == 0.03
    for k, index in enumerate([1, 0, 2]):
        path = f"/stucco/policy/hypotheses/{k}"
        x, y, yaw = HYPOTHESES.poses[index]
        assert visible(meshcat, path) is True
        np.testing.assert_allclose(translation_at(meshcat, path), [x, y, 0.03], atol=1e-12)
        np.testing.assert_allclose(rotation_at(meshcat, path),
                                   RotationMatrix.MakeZRotation(yaw).matrix(), atol=1e-12)
    assert visible(meshcat, "/stucco/policy/hypotheses/3") is False

    # Stopped (a zero step) and no hypotheses: nothing shows.
    context.SetTime(0.1)
    visualizer.GetInputPort("planar_step").FixValue(context, [0.0, 0.0])
    visualizer.GetInputPort("pose_hypotheses").FixValue(context, None)
    visualizer.ForcedPublish(context)
    assert visible(meshcat, "/stucco/policy/push") is False
    assert visible(meshcat, "/stucco/policy/hypotheses/0") is False
