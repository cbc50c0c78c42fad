"""PolicyVisualizer: the rummaging policy's chosen push and the target-pose hypotheses in
Meshcat, as the episode goes.

Paths (under ``prefix``, default ``/stucco/policy``): ``push`` a line of ``length`` from the
gripper in the direction of the step of the action under way, hidden while the step is zero
(a fixed line moved by its transform, so that a Meshcat recording replays it);
``hypotheses/{k}`` the outlines of the ``count`` heaviest pose hypotheses, heaviest first,
brighter the more weight they carry, each standing on the table (z = 0) at its planar pose.
Positions in the world frame (m).
"""

from __future__ import annotations

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.geometry import Rgba
from pydrake.math import RigidTransform, RotationMatrix
from pydrake.systems.framework import BasicVector, LeafSystem

from stucco_drake.core.shapes import BoxSdf, CylinderSdf
from stucco_drake.systems.contact_tracking_visualizer import shape_outline

PUSH_COLOR = Rgba(0.0, 0.6, 1.0)


def standing_height(shape: BoxSdf | CylinderSdf) -> float:
    """Height (m) of the shape's frame when its lowest point rests on z = 0."""
    half = shape.half_extents[2] if isinstance(shape, BoxSdf) else shape.half_height
    return float(half - np.asarray(shape.center, dtype=float)[2])


class PolicyVisualizer(LeafSystem):
    """Draws the policy's push and the pose hypotheses (see the module docstring).

    Input ports (each optional: an unconnected port is not drawn):
        planar_step: (dx, dy) of the action under way (m, world).
        ee_pose: RigidTransform X_WE of the gripper frame (m, world).
        pose_hypotheses: the target-pose estimator's hypotheses (``poses`` (n, 3) x, y, yaw;
            ``weights`` (n,)), or None. Evaluating it computes them at every action.

    Args:
        meshcat: the Meshcat instance to draw to.
        target_shape: the target's geometry in its own frame.
        publish_period: seconds between draws (> 0).
        count: how many hypotheses are drawn.
        length: the push line's length (m).
        prefix: the Meshcat path everything is drawn under.
    """

    def __init__(self, meshcat, target_shape: BoxSdf | CylinderSdf, publish_period: float, *,
                 count: int = 5, length: float = 0.09, prefix: str = "/stucco/policy"):  # fmt: skip
        super().__init__()
        if not publish_period > 0:
            raise ValueError(f"publish_period: must be > 0 s, got {publish_period!r}")
        self._meshcat, self._prefix = meshcat, prefix.rstrip("/")
        self._outline, self._z = shape_outline(target_shape), standing_height(target_shape)
        self._count, self._length = int(count), float(length)
        self._step = self.DeclareVectorInputPort("planar_step", BasicVector(2))
        self._ee = self.DeclareAbstractInputPort("ee_pose", AbstractValue.Make(RigidTransform()))
        self._hypotheses = self.DeclareAbstractInputPort(
            "pose_hypotheses", AbstractValue.Make(None))
        self.DeclareInitializationPublishEvent(self._on_initialize)
        self.DeclarePeriodicPublishEvent(publish_period, 0.0, self._draw)
        self.DeclareForcedPublishEvent(self._draw)

    @property
    def prefix(self) -> str:
        """The Meshcat path everything is drawn under (no trailing slash)."""
        return self._prefix

    def _on_initialize(self, context):
        self._meshcat.Delete(self._prefix)
        line = np.array([[0.0, self._length], [0.0, 0.0], [0.0, 0.0]])
        self._meshcat.SetLine(f"{self._prefix}/push", line, 4.0, PUSH_COLOR)
        self._meshcat.SetProperty(f"{self._prefix}/push", "visible", False, 0.0)
        start, end = self._outline
        for k in range(self._count):
            path = f"{self._prefix}/hypotheses/{k}"
            # Dimmer the lighter: the k-th heaviest at 1 - k / count of full brightness.
            shade = 1.0 - k / self._count
            self._meshcat.SetLineSegments(path, start, end, 1.5, Rgba(1.0, 0.55 * shade, 0.0))
            self._meshcat.SetProperty(path, "visible", False, 0.0)
        return self._draw(context)

    def _draw(self, context):
        time = context.get_time()
        if self._step.HasValue(context) and self._ee.HasValue(context):
            self._draw_push(self._step.Eval(context), self._ee.Eval(context), time)
        if self._hypotheses.HasValue(context):
            self._draw_hypotheses(self._hypotheses.Eval(context), time)
        return None

    def _draw_push(self, step, X_WE: RigidTransform, time: float) -> None:
        path = f"{self._prefix}/push"
        step = np.asarray(step, dtype=float)
        shown = bool(np.any(step != 0))
        if shown:
            yaw = float(np.arctan2(step[1], step[0]))
            self._meshcat.SetTransform(path, RigidTransform(
                RotationMatrix.MakeZRotation(yaw), X_WE.translation()), time)
        self._meshcat.SetProperty(path, "visible", shown, time)

    def _draw_hypotheses(self, hypotheses, time: float) -> None:
        order = [] if hypotheses is None else np.argsort(-np.asarray(hypotheses.weights))
        for k in range(self._count):
            path = f"{self._prefix}/hypotheses/{k}"
            if k < len(order):
                x, y, yaw = np.asarray(hypotheses.poses)[order[k]]
                X_WO = RigidTransform(RotationMatrix.MakeZRotation(yaw), [x, y, self._z])
                self._meshcat.SetTransform(path, X_WO, time)
            self._meshcat.SetProperty(path, "visible", k < len(order), time)
