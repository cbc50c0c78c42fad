"""SoftTrackingFilter in a Drake diagram: same results as the bare tracker, cloneable state."""

import numpy as np
import pytest
from pydrake.common.value import AbstractValue
from pydrake.math import RigidTransform
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder, LeafSystem

from stucco_drake.core import SoftTracker
from stucco_drake.core.baselines import make_tracker
from stucco_drake.core.observation import ActionContacts
from stucco_drake.core.synthetic import separation_scenario
from stucco_drake.systems.soft_tracking_filter import SoftTrackingFilter

ACTION_PERIOD = 0.1  # s per action in the scripted clock


class ScriptedActions(LeafSystem):
    """Plays recorded observations: action k completes at t = (k + 1) * period."""

    def __init__(self, observations):
        super().__init__()
        self._observations = observations
        self.DeclareAbstractOutputPort(
            "ee_pose", lambda: AbstractValue.Make(RigidTransform()), self._pose
        )
        self.DeclareAbstractOutputPort(
            "action_contacts", lambda: AbstractValue.Make(ActionContacts()), self._contacts
        )

    def _completed(self, context) -> int:
        return min(int(context.get_time() / ACTION_PERIOD + 1e-9), len(self._observations)) - 1

    def _pose(self, context, output):
        k = self._completed(context)
        position = self._observations[k].ee_position if k >= 0 else np.zeros(3)
        output.set_value(RigidTransform(position))

    def _contacts(self, context, output):
        k = self._completed(context)
        if k < 0:
            output.set_value(ActionContacts())
            return
        obs = self._observations[k]
        output.set_value(ActionContacts(k, obs.contact_points, obs.contact_dx))


def build(tracker, observations, seed):
    builder = DiagramBuilder()
    source = builder.AddSystem(ScriptedActions(observations))
    tracking = builder.AddSystem(SoftTrackingFilter(tracker, seed, ACTION_PERIOD / 4))
    builder.Connect(source.GetOutputPort("ee_pose"), tracking.GetInputPort("ee_pose"))
    builder.Connect(
        source.GetOutputPort("action_contacts"), tracking.GetInputPort("action_contacts")
    )
    return builder.Build(), tracking


@pytest.fixture(scope="module")
def observations():
    _, actions = separation_scenario()
    return list(actions)


def test_filter_matches_the_bare_tracker_and_clones_rerun_identically(
    disc_penetration, observations
):
    seed = 5
    diagram, tracking = build(SoftTracker(disc_penetration), observations, seed)
    simulator = Simulator(diagram)
    context = simulator.get_mutable_context()
    half = len(observations) // 2 * ACTION_PERIOD + ACTION_PERIOD / 2
    simulator.AdvanceTo(half)
    snapshot = context.Clone()
    snapshot_state = tracking.tracking_state(tracking.GetMyContextFromRoot(snapshot))
    points_at_half = snapshot_state.tracker.map_points().copy()
    simulator.AdvanceTo(len(observations) * ACTION_PERIOD + ACTION_PERIOD / 2)
    # The clone shares the belief copy-on-write: the original's updates must not reach it
    # (read from the tracker itself, not a cached output).
    np.testing.assert_array_equal(snapshot_state.tracker.map_points(), points_at_half)
    tracking_context = tracking.GetMyContextFromRoot(context)
    points = tracking.GetOutputPort("map_points").Eval(tracking_context)
    labels = tracking.GetOutputPort("segment_labels").Eval(tracking_context)
    assert tracking.tracking_state(tracking_context).n_updates == len(observations)

    reference = SoftTracker(disc_penetration)
    rng = np.random.default_rng(seed)
    for obs in observations:
        reference.update(rng, obs.ee_position, obs.contact_points, obs.contact_dx, np.eye(3))
    np.testing.assert_array_equal(points, reference.map_points())
    np.testing.assert_array_equal(labels, reference.segment())
    assert len(np.unique(labels)) == 2  # the two boxes, as in the core key-case test

    rerun = Simulator(diagram, snapshot)
    rerun.AdvanceTo(len(observations) * ACTION_PERIOD + ACTION_PERIOD / 2)
    rerun_context = tracking.GetMyContextFromRoot(rerun.get_context())
    np.testing.assert_array_equal(tracking.GetOutputPort("map_points").Eval(rerun_context), points)


def test_filter_accepts_a_baseline_tracker(observations):
    diagram, tracking = build(make_tracker("dbscan"), observations, 0)
    simulator = Simulator(diagram)
    simulator.AdvanceTo(len(observations) * ACTION_PERIOD + ACTION_PERIOD / 2)
    context = tracking.GetMyContextFromRoot(simulator.get_context())
    assert tracking.GetOutputPort("map_points").Eval(context).shape == (16, 3)


def test_filter_rejects_a_non_tracker():
    with pytest.raises(ValueError, match="tracker"):
        SoftTrackingFilter(object(), 0, 0.001)


def test_filter_rejects_an_unknown_contact_motion_or_one_without_the_robot():
    tracker = make_tracker("dbscan")
    with pytest.raises(ValueError, match=r"^dx_model: expected one of \('ee', 'normal', 'cone'\)"):
        SoftTrackingFilter(tracker, 0, 0.001, dx_model="tangent")
    for model in ("normal", "cone"):
        with pytest.raises(ValueError, match=f"^dx_model '{model}' needs robot_sdf"):
            SoftTrackingFilter(tracker, 0, 0.001, dx_model=model)


def test_action_contacts_reject_nan_and_mismatched_dx():
    with pytest.raises(ValueError, match=r"ActionContacts\.points"):
        ActionContacts(0, [[np.nan, 0.0, 0.0]], [[0.0, 0.0, 0.0]])
    with pytest.raises(ValueError, match=r"ActionContacts\.dx"):
        ActionContacts(0, [[0.0, 0.0, 0.0]], np.zeros((2, 3)))


def test_target_pose_estimator_recovers_a_pushed_box(disc_penetration, observations):
    """Filter -> estimator on the key case: box A's final pose comes out of ICP within 1 cm."""
    from stucco_drake.core import BoxSdf
    from stucco_drake.systems.target_pose_estimator import TargetPoseEstimator

    world, actions = separation_scenario()
    observations = list(actions)
    builder = DiagramBuilder()
    source = builder.AddSystem(ScriptedActions(observations))
    tracking = builder.AddSystem(
        SoftTrackingFilter(SoftTracker(disc_penetration), 0, ACTION_PERIOD / 4)
    )
    box = BoxSdf((0.05, 0.05, 1.0), (0.0, 0.0, 0.0))
    estimator = builder.AddSystem(TargetPoseEstimator(box, disc_penetration, 0, ACTION_PERIOD / 4))
    for name in ("ee_pose", "action_contacts"):
        builder.Connect(source.GetOutputPort(name), tracking.GetInputPort(name))
    builder.Connect(source.GetOutputPort("ee_pose"), estimator.GetInputPort("ee_pose"))
    for name in ("map_points", "segment_labels", "tracked_action"):
        builder.Connect(tracking.GetOutputPort(name), estimator.GetInputPort(name))
    diagram = builder.Build()
    simulator = Simulator(diagram)
    # Estimates run one check after the tracker's update, so run one period past the end.
    simulator.AdvanceTo((len(observations) + 1) * ACTION_PERIOD + ACTION_PERIOD / 2)
    context = estimator.GetMyContextFromRoot(simulator.get_context())
    estimate = estimator.GetOutputPort("estimate").Eval(context)
    assert estimate is not None
    centres = world.box_centers
    nearest = centres[np.argmin(np.linalg.norm(centres - estimate.pose[:2], axis=1))]
    print(f"\nestimated ({estimate.x:.4f}, {estimate.y:.4f}), boxes at {centres.tolist()}")
    # Each box was touched on one face only, at points the MAP particle partly merged: the pose
    # is loosely pinned (ICP accuracy itself is tested in test_icp.py). Within 3 cm of a box,
    # and both segments were fitted.
    assert np.linalg.norm(estimate.pose[:2] - nearest) <= 0.03
    assert len(estimate.segments) == 2
    assert all(report.n_points == 8 for report in estimate.segments)


def test_target_pose_estimator_rejects_a_negative_touch_tolerance(disc_penetration):
    from stucco_drake.core.shapes import BoxSdf
    from stucco_drake.systems.target_pose_estimator import TargetPoseEstimator

    box = BoxSdf((0.05, 0.05, 1.0), (0.0, 0.0, 0.0))
    with pytest.raises(ValueError, match=r"^touch_tolerance: must be >= 0"):
        TargetPoseEstimator(box, disc_penetration, 0, 0.1, touch_tolerance=-0.01)
    estimator = TargetPoseEstimator(box, disc_penetration, 0, 0.1, touch_tolerance=None)
    assert estimator.touch_tolerance is None
