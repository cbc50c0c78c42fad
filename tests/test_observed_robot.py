"""The proprioceptive systems on a robot that is not ours: a two-link planar arm.

The arm (two revolute joints about world z, links of 0.5 and 0.4 m; no actuators) moves under a
constant 1.2 N force applied at its tip. The truth is closed-form planar kinematics: the tip
position (l1 c1 + l2 c12, l1 s1 + l2 s12) and the external joint torques J(q)^T f.
"""

from __future__ import annotations

import numpy as np
import pytest
from pydrake.common.value import AbstractValue
from pydrake.multibody.math import SpatialForce
from pydrake.multibody.parsing import Parser
from pydrake.multibody.plant import (
    AddMultibodyPlantSceneGraph,
    ExternallyAppliedSpatialForce,
    MultibodyPlant,
)
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import ConstantValueSource, ConstantVectorSource, LogVectorOutput

from stucco_drake.systems.contact_isolator import GripperPoseFromState
from stucco_drake.systems.observed_robot import ObservedRobot
from stucco_drake.systems.wrench_estimator import ExternalWrenchEstimator

L1, L2, H = 0.5, 0.4, 0.002
FORCE = np.array([0.6, -1.0, 0.0])  # N, world, at the tip
Q0 = np.array([0.3, 0.8])

URDF = f"""<?xml version="1.0"?>
<robot name="planar_arm">
  <link name="base"/>
  <link name="upper">
    <inertial><origin xyz="{L1 / 2} 0 0"/><mass value="1.0"/>
      <inertia ixx="0.001" iyy="0.02" izz="0.02" ixy="0" ixz="0" iyz="0"/></inertial>
  </link>
  <link name="fore">
    <inertial><origin xyz="{L2 / 2} 0 0"/><mass value="0.5"/>
      <inertia ixx="0.001" iyy="0.007" izz="0.007" ixy="0" ixz="0" iyz="0"/></inertial>
  </link>
  <link name="tip"/>
  <joint name="shoulder" type="revolute"><parent link="base"/><child link="upper"/>
    <axis xyz="0 0 1"/></joint>
  <joint name="elbow" type="revolute"><parent link="upper"/><child link="fore"/>
    <origin xyz="{L1} 0 0"/><axis xyz="0 0 1"/></joint>
  <joint name="tip_weld" type="fixed"><parent link="fore"/><child link="tip"/>
    <origin xyz="{L2} 0 0"/></joint>
</robot>
"""


def planar_arm(plant: MultibodyPlant) -> MultibodyPlant:
    Parser(plant).AddModelsFromString(URDF, "urdf")
    plant.WeldFrames(plant.world_frame(), plant.GetFrameByName("base"))
    plant.Finalize()
    return plant


def tip_and_torques(q):
    """Closed-form tip position (m) and J(q)^T FORCE (N m) of the planar arm."""
    c1, s1 = np.cos(q[0]), np.sin(q[0])
    c12, s12 = np.cos(q[0] + q[1]), np.sin(q[0] + q[1])
    tip = np.array([L1 * c1 + L2 * c12, L1 * s1 + L2 * s12, 0.0])
    J = np.array([[-L1 * s1 - L2 * s12, -L2 * s12], [L1 * c1 + L2 * c12, L2 * c12]])
    return tip, J.T @ FORCE[:2]


@pytest.fixture(scope="module")
def run():
    builder = DiagramBuilder()
    plant, _ = AddMultibodyPlantSceneGraph(builder, H)
    planar_arm(plant)
    model = planar_arm(MultibodyPlant(0.0))
    robot = ObservedRobot(model, model.GetFrameByName("tip"))
    # K_O h = 1: the residual is the last step's external torque itself (no filtering lag).
    estimator = builder.AddSystem(ExternalWrenchEstimator(H, robot, gain=1.0 / H))
    pose = builder.AddSystem(GripperPoseFromState(
        ObservedRobot(model, model.GetFrameByName("tip"))))  # fmt: skip
    push = ExternallyAppliedSpatialForce()
    push.body_index = plant.GetBodyByName("fore").index()
    push.p_BoBq_B = [L2, 0.0, 0.0]
    push.F_Bq_W = SpatialForce(np.zeros(3), FORCE)
    source = builder.AddSystem(ConstantValueSource(AbstractValue.Make([push])))
    builder.Connect(source.get_output_port(), plant.get_applied_spatial_force_input_port())
    zero = builder.AddSystem(ConstantVectorSource(np.zeros(2)))  # no actuators: nothing applied
    builder.Connect(zero.get_output_port(), estimator.GetInputPort("applied_torque"))
    for system in (estimator, pose):
        builder.Connect(plant.get_state_output_port(), system.GetInputPort("state"))
    logs = {name: LogVectorOutput(port, builder, H) for name, port in (
        ("r", estimator.GetOutputPort("external_joint_torques")),
        ("position", estimator.GetOutputPort("ee_position")),
        ("pose", pose.GetOutputPort("gripper_pose")),
        ("x", plant.get_state_output_port()),
    )}  # fmt: skip
    simulator = Simulator(builder.Build())
    plant.SetPositions(plant.GetMyMutableContextFromRoot(simulator.get_mutable_context()), Q0)
    simulator.AdvanceTo(0.3)
    context = simulator.get_context()
    return {name: log.FindLog(context).data().T for name, log in logs.items()}


def test_external_torques_of_another_robot_match_closed_form(run):
    x, r = run["x"], run["r"]
    assert np.abs(x[-1, :2] - Q0).max() > 0.02  # the force did move the arm
    # Each update estimates the external torque of the step that led to its state (sampled
    # plant outputs), J^T f at the step's start; the discrete observer is exact for Drake's
    # discrete plant, so only round-off remains (measured 3e-14 N m against torques of 1 N m).
    truth = np.array([tip_and_torques(q)[1] for q in x[5:-1, :2]])
    np.testing.assert_allclose(r[6:], truth, rtol=0, atol=1e-9)


def test_end_effector_position_and_pose_of_another_robot(run):
    tips = np.array([tip_and_torques(q)[0] for q in run["x"][1:, :2]])
    np.testing.assert_allclose(run["position"][1:], tips, atol=1e-9)
    np.testing.assert_allclose(run["pose"][1:, :3], tips, atol=1e-9)


def test_observed_robot_rejects_bad_arguments():
    model = planar_arm(MultibodyPlant(0.0))
    tip = model.GetFrameByName("tip")
    with pytest.raises(ValueError, match="joints"):
        ObservedRobot(model, tip, joints=[0, 0])
    with pytest.raises(ValueError, match="joints"):
        ObservedRobot(model, tip, joints=[2])
    with pytest.raises(ValueError, match="positions"):
        ObservedRobot(model, tip, positions=[0.0])
    other = planar_arm(MultibodyPlant(0.0))
    with pytest.raises(ValueError, match="not a frame of the plant"):
        ObservedRobot(model, other.GetFrameByName("tip"))
    unfinalized = MultibodyPlant(0.0)
    with pytest.raises(ValueError, match="finalized"):
        ObservedRobot(unfinalized, unfinalized.world_frame())


def test_contact_tracking_refuses_bad_arguments_before_adding_anything():
    from pydrake.systems.framework import DiagramBuilder

    from stucco_drake.core import BoxSdf, CylinderSdf, FunctionPenetration, SoftTracker
    from stucco_drake.tracking import add_contact_tracking

    model = planar_arm(MultibodyPlant(0.0))
    robot = ObservedRobot(model, model.GetFrameByName("tip"))
    builder = DiagramBuilder()
    pxpen = FunctionPenetration(CylinderSdf(0.02, 0.05))
    kwargs = dict(robot_state=None, applied_torque=None, action_index=None, time_step=H,
                  tracker=SoftTracker(pxpen), tracker_seed=0, target_shape=BoxSdf((1, 1, 1)),
                  icp_seed=0, cpf_seed=0)  # fmt: skip
    with pytest.raises(ValueError, match="grid pxpen"):
        add_contact_tracking(builder, robot, penetration=pxpen, **kwargs)
    assert builder.GetSystems() == []
