"""Builds a scene file into a Drake Diagram: plant, scene graph, joint control and planar IK.

The Diagram holds a discrete MultibodyPlant (SAP) with the iiwa14 and bubble gripper welded to
the world at ``scene.robot_base``, the table, walls and objects of the scene; an
InverseDynamicsController on a robot-only plant (arm and gripper, no objects) tracking the
joint command of a :class:`PlanarEndEffectorController`; and, unless the caller feeds steps
itself, a :class:`PlanarActionSequence` playing ``scene.actions``.

Exported ports (robot vectors use the robot-only plant's ordering, see ``BuiltScene``):
    input ``planar_step`` (only with ``external_actions=True``): (dx, dy) in m, world frame.
    output ``robot_state``: measured [q; v] of the robot.
    output ``applied_torque``: generalized forces the plant's actuators apply to the robot (N m
        for the arm, N for the fingers): the plant's net actuation, mapped to robot order. With
        the scene files' unsampled output ports this is the torque of the step that starts at
        the current state; with sampled ports, that of the step that ended there.
    output ``commanded_torque``: what the joint controller asked for (same units).
    output ``desired_state``: the joint command [q; v].
    output ``planar_goal``: (x, y) the current action moves the gripper frame to (m, world).
    output ``plant_state``: the full plant state; ``contact_results``; ``query_object``.
    output ``body_poses``: the plant's body poses (list of RigidTransform, by BodyIndex).
    output ``action_index`` (only with the built-in action sequence).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
from pydrake.geometry import (
    CollisionFilterDeclaration,
    MeshcatVisualizer,
    ProximityProperties,
    RoleAssign,
)
from pydrake.math import RigidTransform, RollPitchYaw
from pydrake.multibody.parsing import ModelDirectives, Parser, ProcessModelDirectives
from pydrake.multibody.plant import AddMultibodyPlant, CoulombFriction, MultibodyPlant
from pydrake.multibody.tree import ModelInstanceIndex
from pydrake.systems.controllers import InverseDynamicsController
from pydrake.systems.framework import Diagram, DiagramBuilder
from pydrake.systems.primitives import MatrixGain

from stucco_drake.robot.models import add_iiwa14_with_bubble_gripper, configure_parser
from stucco_drake.scenes.meshcat_session import show_over_the_shoulder
from stucco_drake.scenes.primitives import add_primitive
from stucco_drake.scenes.robot_selectors import actuation_selector, robot_joints, state_selector
from stucco_drake.scenes.scene_file import ControlParams, Primitive, SceneFile, SceneFileError
from stucco_drake.systems.planar_controller import (
    ArmKinematics,
    PlanarActionSequence,
    PlanarEndEffectorController,
    gripper_rotation,
    solve_start_ik,
)

IIWA, GRIPPER = "iiwa", "bubble_gripper"


@dataclasses.dataclass
class BuiltScene:
    """The built Diagram and handles into it.

    Attributes:
        diagram: the Diagram (see the module docstring for its ports).
        plant: the simulation plant (robot and objects); ``scene_graph`` its SceneGraph.
        robot_plant: the robot-only plant the controller (and any wrench estimator) uses.
        controller: the planar IK system; ``actions`` the action source (None if external).
        q_start: the robot's start positions (robot-plant ordering, rad and m).
        free_bodies: name -> body of every free (movable) object.
        welded_bodies: name -> body of every object welded to the world.
    """

    scene: SceneFile
    diagram: Diagram
    plant: MultibodyPlant
    scene_graph: object
    robot_plant: MultibodyPlant
    controller: PlanarEndEffectorController
    actions: PlanarActionSequence | None
    q_start: np.ndarray
    free_bodies: dict
    welded_bodies: dict

    def gripper_frame(self, plant: MultibodyPlant | None = None):
        """The gripper frame (grasp centre) of ``plant`` (default: the simulation plant)."""
        plant = plant or self.plant
        return plant.GetFrameByName("gripper_frame", plant.GetModelInstanceByName(GRIPPER))


#: Side of the square pedestal column under a raised robot base (m).
PEDESTAL_WIDTH = 0.16


def robot_base_pose(scene: SceneFile) -> RigidTransform:
    """World pose of the iiwa's base link from ``scene.robot_base`` = [x, y, z, yaw]."""
    x, y, z, yaw = scene.robot_base
    return RigidTransform(RollPitchYaw(0.0, 0.0, yaw), [x, y, z])


def pedestal(scene: SceneFile) -> Primitive | None:
    """The welded column a raised base stands on (None for a base at z <= 0).

    Why raised: with the gripper pointing down, the iiwa's elbow limit (120 degrees) keeps the
    wrist at least about 0.41 m from the shoulder. Standing at table height the arm reaches
    0.45-0.78 m, too narrow a band for the paper's gripper paths; 0.4 m up it reaches
    0.10-0.70 m around the base.
    """
    x, y, z, yaw = scene.robot_base
    if z <= 0:
        return None
    return Primitive(
        name="robot_pedestal", shape="box", size=[PEDESTAL_WIDTH, PEDESTAL_WIDTH, z],
        xyz=[x, y, z / 2], rpy=[0.0, 0.0, yaw], welded=True, rgba=[0.3, 0.3, 0.32, 1.0],
    )


def _add_robot(plant: MultibodyPlant, scene: SceneFile):
    parser = configure_parser(Parser(plant))
    iiwa, gripper = add_iiwa14_with_bubble_gripper(parser, iiwa_name=IIWA, gripper_name=GRIPPER)
    plant.WeldFrames(
        plant.world_frame(), plant.GetFrameByName("iiwa_link_0", iiwa), robot_base_pose(scene)
    )
    return iiwa, gripper


def _joint_gains(robot_plant: MultibodyPlant, arm, control: ControlParams):
    """Per-velocity (kp, ki, kd) of the joint controller: the arm's gains on the arm's joints,
    the fingers' on every other robot joint."""
    nv = robot_plant.num_velocities()
    kp, ki, kd = (np.full(nv, g) for g in (control.finger_kp, control.finger_ki, control.finger_kd))
    for index in robot_plant.GetJointIndices(arm):
        joint = robot_plant.get_joint(index)
        dofs = slice(joint.velocity_start(), joint.velocity_start() + joint.num_velocities())
        kp[dofs], ki[dofs], kd[dofs] = control.kp, control.ki, control.kd
    return kp, ki, kd


def make_robot_plant(scene: SceneFile) -> MultibodyPlant:
    """A finalized continuous plant of the arm and gripper alone, welded as in the scene."""
    plant = MultibodyPlant(time_step=0.0)
    _add_robot(plant, scene)
    plant.Finalize()
    return plant


def _filter_base_wrist_contact(plant: MultibodyPlant, scene_graph) -> None:
    """Excludes contact between the arm's base links (0, 1) and its wrist (links 5-7, gripper).

    Why: with the gripper pointing down and 0.2-0.25 m from the base, the wrist passes within a
    few millimetres of the base link. Such self-contact would only add forces that belong to no
    object, so we let the links pass (the scenes keep the gripper out of that zone).
    """
    iiwa = plant.GetModelInstanceByName(IIWA)
    gripper = plant.GetModelInstanceByName(GRIPPER)
    base = [plant.GetBodyByName(f"iiwa_link_{i}", iiwa) for i in (0, 1)]
    wrist = [plant.GetBodyByName(f"iiwa_link_{i}", iiwa) for i in (5, 6, 7)]
    wrist += [plant.get_body(i) for i in plant.GetBodyIndices(gripper)]
    scene_graph.collision_filter_manager().Apply(
        CollisionFilterDeclaration().ExcludeBetween(
            plant.CollectRegisteredGeometries(base), plant.CollectRegisteredGeometries(wrist)
        )
    )


def _override_friction(plant: MultibodyPlant, scene_graph, scene: SceneFile) -> None:
    """Gives every collision geometry of each model in ``scene.friction`` that friction."""
    inspector = scene_graph.model_inspector()
    for name, mu in scene.friction.items():
        if not plant.HasModelInstanceNamed(name):
            raise SceneFileError(f"{scene.name}: friction.{name}: the scene has no model {name!r}")
        instance = plant.GetModelInstanceByName(name)
        for index in plant.GetBodyIndices(instance):
            for gid in plant.GetCollisionGeometriesForBody(plant.get_body(index)):
                properties = ProximityProperties(inspector.GetProximityProperties(gid))
                properties.UpdateProperty("material", "coulomb_friction", CoulombFriction(mu, mu))
                scene_graph.AssignRole(plant.get_source_id(), gid, properties, RoleAssign.kReplace)


def _start_positions(robot_plant: MultibodyPlant, scene: SceneFile):
    """(hold, q_start, q_arm): robot positions with the fingers at their held opening, the same
    with the arm solved by IK for the gripper's start pose, and those arm positions (rad)."""
    start = scene.gripper_start
    arm = robot_plant.GetModelInstanceByName(IIWA)
    hold = robot_plant.GetPositions(robot_plant.CreateDefaultContext())
    for joint in robot_joints(robot_plant, (IIWA, GRIPPER)):
        if joint.model_instance() != arm:
            first = joint.position_start()
            hold[first:first + joint.num_positions()] = start.finger_position
    X_start = RigidTransform(gripper_rotation(start.yaw), [*start.xy, start.height])
    kin = ArmKinematics(robot_plant, arm, robot_plant.GetFrameByName("gripper_frame"))
    # Seed the IK with the nominal posture turned about the base (joint 1) to face the start:
    # from the unturned posture, Newton steps reach far-off directions by bending the other
    # joints towards their limits instead.
    seed = np.array(scene.control.nominal_q, dtype=float)
    q_full = hold.copy()
    q_full[kin.q_index] = seed
    kin.set_positions(q_full)
    base = robot_base_pose(scene).translation()
    p_nominal = kin.pose().translation() - base
    p_start = np.array([*start.xy, 0.0]) - base
    seed[0] += math.atan2(p_start[1], p_start[0]) - math.atan2(p_nominal[1], p_nominal[0])
    seed[0] = math.remainder(seed[0], 2 * math.pi)
    q_arm = solve_start_ik(kin, hold, X_start, seed)
    q_start = hold.copy()
    q_start[kin.q_index] = q_arm
    return hold, q_start, q_arm


def build_scene(scene: SceneFile, *, meshcat=None, external_actions: bool = False,
                command_hook=None) -> BuiltScene:
    """Builds ``scene`` into a Diagram (see the module docstring); optionally draws to meshcat
    (and points its camera into the scene, see :func:`show_over_the_shoulder`).

    With ``external_actions`` the Diagram exports a ``planar_step`` input instead of playing
    ``scene.actions``. ``command_hook(builder, desired_state, robot_state)``, if given, gets the
    planar controller's joint command port and the measured robot state port and returns the
    port the joint controller tracks instead (a system inserted by the caller, e.g. for grasping);
    the exported ``desired_state`` is then that port.
    """
    builder = DiagramBuilder()
    plant, scene_graph = _add_plant(builder, scene)
    robot_plant = make_robot_plant(scene)
    hold, q_start, q_arm = _start_positions(robot_plant, scene)
    _set_start_positions(plant, robot_plant, q_start)
    select_state, idc, from_actuation = _add_joint_control(builder, plant, robot_plant,
                                                           scene.control)  # fmt: skip
    ctrl = _add_planar_controller(builder, robot_plant, scene, hold, q_arm)
    builder.Connect(select_state.get_output_port(), ctrl.GetInputPort("robot_state"))
    desired = ctrl.GetOutputPort("desired_state")
    if command_hook is not None:
        desired = command_hook(builder, desired, select_state.get_output_port())
    builder.Connect(desired, idc.get_input_port_desired_state())
    sequence = _add_actions(builder, scene, ctrl, external_actions)

    builder.ExportOutput(select_state.get_output_port(), "robot_state")
    builder.ExportOutput(from_actuation.get_output_port(), "applied_torque")
    builder.ExportOutput(idc.get_output_port_control(), "commanded_torque")
    builder.ExportOutput(desired, "desired_state")
    builder.ExportOutput(ctrl.GetOutputPort("planar_goal"), "planar_goal")
    builder.ExportOutput(plant.get_state_output_port(), "plant_state")
    builder.ExportOutput(plant.get_contact_results_output_port(), "contact_results")
    builder.ExportOutput(plant.get_body_poses_output_port(), "body_poses")
    builder.ExportOutput(scene_graph.get_query_output_port(), "query_object")
    if meshcat is not None:
        MeshcatVisualizer.AddToBuilder(builder, scene_graph, meshcat)
    diagram = builder.Build()
    diagram.set_name(f"scene_{scene.name}")
    free, welded = _object_bodies(plant)
    built = BuiltScene(scene, diagram, plant, scene_graph, robot_plant, ctrl, sequence, q_start,
                       free, welded)
    if meshcat is not None:
        show_over_the_shoulder(meshcat, built)
    return built


def _add_plant(builder: DiagramBuilder, scene: SceneFile):
    """(plant, scene_graph): the finalized simulation plant of the robot, the scene's models
    and primitives (and the pedestal of a raised base), with the scene's friction."""
    plant, scene_graph = AddMultibodyPlant(scene.plant, builder)
    _add_robot(plant, scene)
    parser = configure_parser(Parser(plant))
    ProcessModelDirectives(ModelDirectives(directives=scene.directives), plant, parser)
    column = pedestal(scene)
    for primitive in scene.primitives + ([column] if column else []):
        add_primitive(plant, primitive)
    _override_friction(plant, scene_graph, scene)
    plant.Finalize()
    _filter_base_wrist_contact(plant, scene_graph)
    return plant, scene_graph


def _set_start_positions(plant: MultibodyPlant, robot_plant: MultibodyPlant, q_start) -> None:
    """Both plants' default robot positions at ``q_start`` (robot-plant ordering, rad and m)."""
    robot_plant.SetDefaultPositions(q_start)
    # The objects' default poses come from the directives; the robot's from the start IK.
    for name in (IIWA, GRIPPER):
        q_instance = robot_plant.GetPositionsFromArray(
            robot_plant.GetModelInstanceByName(name), q_start
        )
        plant.SetDefaultPositions(plant.GetModelInstanceByName(name), q_instance)


def _add_joint_control(builder: DiagramBuilder, plant: MultibodyPlant,
                       robot_plant: MultibodyPlant, control: ControlParams):  # fmt: skip
    """(select_state, idc, from_actuation): the robot's state taken out of the plant's, the
    inverse-dynamics joint controller driving the plant's actuation, and the torque the
    plant applies mapped back to robot order."""
    S = state_selector(plant, robot_plant, (IIWA, GRIPPER))
    select_state = builder.AddNamedSystem("robot_state_selector", MatrixGain(S))
    builder.Connect(plant.get_state_output_port(), select_state.get_input_port())
    arm = robot_plant.GetModelInstanceByName(IIWA)
    kp, ki, kd = _joint_gains(robot_plant, arm, control)
    idc = builder.AddNamedSystem("joint_controller", InverseDynamicsController(
        robot_plant, kp, ki, kd, False
    ))
    B = actuation_selector(plant, robot_plant)
    to_actuation = builder.AddNamedSystem("to_actuation", MatrixGain(B))
    # The torque as the plant applies it (its net actuation), back in robot order.
    from_actuation = builder.AddNamedSystem("applied_torque", MatrixGain(B.T))
    builder.Connect(plant.get_net_actuation_output_port(), from_actuation.get_input_port())
    builder.Connect(select_state.get_output_port(), idc.get_input_port_estimated_state())
    builder.Connect(idc.get_output_port_control(), to_actuation.get_input_port())
    builder.Connect(to_actuation.get_output_port(), plant.get_actuation_input_port())
    return select_state, idc, from_actuation


def _add_planar_controller(builder: DiagramBuilder, robot_plant: MultibodyPlant,
                           scene: SceneFile, hold, q_arm):  # fmt: skip
    """The planar IK moving the gripper frame at the start's height and yaw, from the arm's
    start positions ``q_arm`` (rad) with the fingers held at ``hold``."""
    start, control = scene.gripper_start, scene.control
    arm = robot_plant.GetModelInstanceByName(IIWA)
    frame_r = robot_plant.GetFrameByName(
        "gripper_frame", robot_plant.GetModelInstanceByName(GRIPPER)
    )
    return builder.AddNamedSystem("planar_controller", PlanarEndEffectorController(
        robot_plant, arm, frame_r, height=start.height, yaw=start.yaw, q_start=q_arm,
        q_nominal=q_arm, hold_positions=hold, start_xy=start.xy,
        period=control.ik_period, action_duration=scene.action_duration,
        move_fraction=control.move_fraction, gain=control.ik_gain, max_step=control.max_step,
        max_push_force=control.max_push_force, joint_kp=control.kp,
    ))


def _add_actions(builder: DiagramBuilder, scene: SceneFile, ctrl,
                 external_actions: bool) -> PlanarActionSequence | None:  # fmt: skip
    """The source of the controller's planar steps: the exported ``planar_step`` input with
    ``external_actions`` (None returned), else the sequence playing ``scene.actions`` (scaled
    by ``max_step``, m) and its exported ``action_index``."""
    if external_actions:
        builder.ExportInput(ctrl.GetInputPort("planar_step"), "planar_step")
        return None
    sequence = builder.AddNamedSystem(
        "action_sequence", PlanarActionSequence(scene.planar_steps(), scene.action_duration))
    builder.Connect(sequence.GetOutputPort("planar_step"), ctrl.GetInputPort("planar_step"))
    builder.ExportOutput(sequence.GetOutputPort("action_index"), "action_index")
    return sequence


def _object_bodies(plant: MultibodyPlant):
    """Bodies of every model that is not the robot, split into free and welded-to-world.

    Keys are model instance names (``model::body`` for a model with several bodies).
    """
    free, welded = {}, {}
    skip = {"WorldModelInstance", "DefaultModelInstance", IIWA, GRIPPER}
    for i in range(plant.num_model_instances()):
        instance = ModelInstanceIndex(i)
        name = plant.GetModelInstanceName(instance)
        if name in skip:
            continue
        bodies = [plant.get_body(b) for b in plant.GetBodyIndices(instance)]
        for body in bodies:
            key = name if len(bodies) == 1 else f"{name}::{body.name()}"
            (free if body.is_floating_base_body() else welded)[key] = body
    return free, welded


def yaw_of(R) -> float:
    """Yaw (rad) of the x axis of rotation R, about world z."""
    m = R.matrix()
    return math.atan2(m[1, 0], m[0, 0])
