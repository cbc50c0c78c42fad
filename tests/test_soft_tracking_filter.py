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
    simulator.AdvanceTo(len(observations) * ACTION_PERIOD + ACTION_PERIOD / 2)
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


def test_action_contacts_reject_nan_and_mismatched_dx():
    with pytest.raises(ValueError, match=r"ActionContacts\.points"):
        ActionContacts(0, [[np.nan, 0.0, 0.0]], [[0.0, 0.0, 0.0]])
    with pytest.raises(ValueError, match=r"ActionContacts\.dx"):
        ActionContacts(0, [[0.0, 0.0, 0.0]], np.zeros((2, 3)))
