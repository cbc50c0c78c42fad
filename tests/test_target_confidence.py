"""The filter's point spread and the estimator's pose hypotheses and target confidence, in a
Diagram fed the synthetic key case (two 10 cm boxes, each pushed on one face by a 2 cm disc)."""

import numpy as np
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder

from stucco_drake.core import BoxSdf, SoftTracker
from stucco_drake.core.hypothesis_params import HypothesisParams
from stucco_drake.core.synthetic import separation_scenario
from stucco_drake.systems.soft_tracking_filter import SoftTrackingFilter
from stucco_drake.systems.target_pose_estimator import TargetPoseEstimator
from tests.test_soft_tracking_filter import ACTION_PERIOD, ScriptedActions


def _run(disc_penetration, connect_spread: bool, n_actions: int | None = None,
         light_box: int | None = None):
    """The scenario in a Diagram; with ``light_box``, each action that touched that box met
    2 N, any other 12 N, and the estimator sets ``light_force`` 4.9 N."""
    world, actions = separation_scenario()
    observations = list(actions)[:n_actions]
    forces, params = None, None
    if light_box is not None:
        forces = [2.0 if np.any(obs.contact_objects == light_box) else 12.0
                  for obs in observations]  # fmt: skip
        params = HypothesisParams(light_force=4.9)
    builder = DiagramBuilder()
    source = builder.AddSystem(ScriptedActions(observations, forces))
    tracking = builder.AddSystem(
        SoftTrackingFilter(SoftTracker(disc_penetration), 0, ACTION_PERIOD / 4))
    box = BoxSdf((0.05, 0.05, 1.0))
    estimator = builder.AddSystem(TargetPoseEstimator(box, disc_penetration, 0, ACTION_PERIOD / 4,
                                                      hypothesis_params=params))  # fmt: skip
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


def test_points_of_actions_that_met_little_force_are_never_put_on_the_target(disc_penetration):
    """Each box in turn gave way under 2 N (the other met 12 N): the points the chosen
    hypothesis puts on the target are then the other box's only, and it lies at that box."""
    world, actions = separation_scenario()
    touched = np.concatenate([obs.contact_objects for obs in actions])
    for light in (0, 1):
        *_, estimator, context = _run(disc_penetration, True, light_box=light)
        state = estimator.estimator_state(context)
        hypotheses = estimator.GetOutputPort("pose_hypotheses").Eval(context)
        n = hypotheses.explained.shape[1]
        assert np.array_equal(state.point_forces[:n] < 4.9, touched[:n] == light)
        explained = touched[:n][hypotheses.explained[hypotheses.chosen]]
        assert len(explained) and np.all(explained == 1 - light), (light, explained)
        # Within 3 cm of the heavy box's centre, as the unforced test's bound.
        gap = np.linalg.norm(world.box_centers[1 - light] - hypotheses.pose[:2])
        assert gap <= 0.03, (light, gap)
