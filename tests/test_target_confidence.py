"""The filter's point spread and the estimator's pose hypotheses and target confidence, in a
Diagram fed the synthetic key case (two 10 cm boxes, each pushed on one face by a 2 cm disc)."""

import numpy as np
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder

from stucco_drake.core import BoxSdf, SoftTracker
from stucco_drake.core.synthetic import separation_scenario
from stucco_drake.systems.soft_tracking_filter import SoftTrackingFilter
from stucco_drake.systems.target_pose_estimator import TargetPoseEstimator
from tests.test_soft_tracking_filter import ACTION_PERIOD, ScriptedActions


def _run(disc_penetration, connect_spread: bool, n_actions: int | None = None):
    world, actions = separation_scenario()
    observations = list(actions)[:n_actions]
    builder = DiagramBuilder()
    source = builder.AddSystem(ScriptedActions(observations))
    tracking = builder.AddSystem(
        SoftTrackingFilter(SoftTracker(disc_penetration), 0, ACTION_PERIOD / 4))
    box = BoxSdf((0.05, 0.05, 1.0))
    estimator = builder.AddSystem(TargetPoseEstimator(box, disc_penetration, 0, ACTION_PERIOD / 4))
    for name in ("ee_pose", "action_contacts"):
        builder.Connect(source.GetOutputPort(name), tracking.GetInputPort(name))
    builder.Connect(source.GetOutputPort("ee_pose"), estimator.GetInputPort("ee_pose"))
    names = ["map_points", "segment_labels", "tracked_action"]
    for name in names + (["point_spread"] if connect_spread else []):
        builder.Connect(tracking.GetOutputPort(name), estimator.GetInputPort(name))
    simulator = Simulator(builder.Build())
    simulator.AdvanceTo((len(observations) + 1) * ACTION_PERIOD + ACTION_PERIOD / 2)
    root = simulator.get_context()
    return (world, tracking, tracking.GetMyContextFromRoot(root), estimator,
            estimator.GetMyContextFromRoot(root))  # fmt: skip


def test_hypotheses_find_a_box_but_one_touched_face_is_not_confident(disc_penetration):
    world, tracking, tracking_context, estimator, context = _run(disc_penetration, True)
    spread = tracking.GetOutputPort("point_spread").Eval(tracking_context)
    points = tracking.GetOutputPort("map_points").Eval(tracking_context)
    assert spread.shape == (len(points),) and np.all(spread >= 0.0)
    hypotheses = estimator.GetOutputPort("pose_hypotheses").Eval(context)
    confidence = estimator.GetOutputPort("target_confidence").Eval(context)[0]
    assert confidence == hypotheses.confidence
    # The chosen pose lies at one of the two boxes (within 3 cm: the MAP points of each
    # face are partly merged, as in the rules' test) ...
    gap = np.min(np.linalg.norm(world.box_centers - hypotheses.pose[:2], axis=1))
    assert gap <= 0.03, gap
    # ... but each box was pushed on one face only, along which a 10 cm box can slide by
    # centimetres without meeting a contact or the disc's swept space: no pose is confident.
    assert confidence < 0.5, confidence


def test_no_tracked_points_means_no_hypotheses_and_zero_confidence(disc_penetration):
    _, _, _, estimator, context = _run(disc_penetration, False, n_actions=1)
    assert estimator.GetOutputPort("pose_hypotheses").Eval(context) is None
    assert estimator.GetOutputPort("target_confidence").Eval(context)[0] == 0.0
