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

    def __init__(self, observations, peak_forces=None):
        super().__init__()
        self._observations = observations
        # (k,) each action's peak force (N); None: not measured (NaN).
        self._peak_forces = peak_forces
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
        force = np.nan if self._peak_forces is None else self._peak_forces[k]
        output.set_value(ActionContacts(k, obs.contact_points, obs.contact_dx, force))


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


def test_target_pose_estimator_recovers_a_pushed_box(disc_penetration):
    """Filter -> estimator on the key case, then a touch on box A's far side: ICP on the
    tracked points recovers A's final pose (pushed 8 cm out of the gap, then 1 cm sideways)
    to within 2 mm and 1 degree."""
    from stucco_drake.core import BoxSdf
    from stucco_drake.systems.target_pose_estimator import TargetPoseEstimator

    world, actions = separation_scenario()
    observations = list(actions)
    # The key case touches each box on one face only: that pins the face's line and direction
    # but leaves the box free to slide along it, and its last contact step (where the estimate
    # is taken, as in the paper) comes before the sweeps that put the tracked points back on
    # the faces. So go round box A, touch its +x face and push it 1 cm: two faces pin the pose.
    a_y = world.box_centers[0, 1]
    for target in ((0.26, world.ee[1]), (0.26, a_y), (0.21, a_y)):
        while np.linalg.norm(target - world.ee) > 1e-9:
            observations.append(world.step(np.clip(target - world.ee, -0.03, 0.03)))
    assert len(observations[-1].contact_objects) == 1 and observations[-1].contact_objects[0] == 0
    truth = np.array([*world.box_centers[0], 0.0])  # box A at the end; the boxes never turn
    np.testing.assert_allclose(truth[:2], [0.14, 0.1525], atol=1e-9)

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
    # The chosen segment is box A's contacts, and only them (the scenario's own labels).
    true_objects = np.concatenate([obs.contact_objects for obs in observations])
    chosen = np.isin(estimate.labels, estimate.members)
    assert np.all(true_objects[chosen] == 0) and chosen.sum() == np.sum(true_objects == 0) == 9
    error = estimate.pose - truth
    yaw_error = (error[2] + np.pi / 4) % (np.pi / 2) - np.pi / 4  # a square: 90-degree symmetry
    print(f"\nestimated ({estimate.x:.4f}, {estimate.y:.4f}, {np.degrees(estimate.yaw):.2f} deg),"
          f" box A at {truth[:2].tolist()}: error {1e3 * np.linalg.norm(error[:2]):.2f} mm, "
          f"{np.degrees(yaw_error):.3f} deg")
    # Measured: 0.00 mm and 0.000 deg. The contacts are exact and the boxes translate with the
    # disc as the tracker's motion model assumes, so the tracked points lie on A's faces; what
    # is left is ICP's matching to model points 2 mm apart along the outline (at most half a
    # spacing, 1 mm, for points between two of them), doubled. One degree: a 1 mm error over
    # the 6 cm the tracked points span on the first face turns it by 0.95 degree.
    assert np.linalg.norm(error[:2]) <= 0.002
    assert abs(yaw_error) <= np.radians(1.0)


def test_target_pose_estimator_rejects_a_negative_touch_tolerance(disc_penetration):
    from stucco_drake.core.shapes import BoxSdf
    from stucco_drake.systems.target_pose_estimator import TargetPoseEstimator

    box = BoxSdf((0.05, 0.05, 1.0), (0.0, 0.0, 0.0))
    with pytest.raises(ValueError, match=r"^touch_tolerance: must be >= 0"):
        TargetPoseEstimator(box, disc_penetration, 0, 0.1, touch_tolerance=-0.01)
    estimator = TargetPoseEstimator(box, disc_penetration, 0, 0.1, touch_tolerance=None)
    assert estimator.touch_tolerance is None
