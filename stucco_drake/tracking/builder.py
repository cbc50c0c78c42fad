"""The contact-tracking chain added to any Drake Diagram around the user's robot.

:func:`add_contact_tracking` adds, to the caller's ``DiagramBuilder``, the systems that turn a
robot's proprioception (and optionally soft-bubble touch) into tracked contact points and a
target pose estimate:

    momentum observer -> chi-square detector -> contact isolator (bubbles first, else the CPF)
    -> per-action contact assembler -> tracking filter (STUCCO or a baseline) -> target pose

and returns them with their named output ports, the way a hardware station exports its ports.
It builds no robot: the robot model (:class:`~stucco_drake.systems.observed_robot.ObservedRobot`)
and the output ports it reads come from the caller. Our BOR Diagram
(:mod:`stucco_drake.bor.diagram`) is this chain around the iiwa scene.

The detector needs the estimator's free-space wrench statistics (``residual_statistics`` in
``estimator_kwargs``; the paper's Eq. 1). For our iiwa,
:func:`~stucco_drake.systems.contact_detector.calibrate_residual_statistics` runs random
free-space motions and caches the fit. For another robot: run your Diagram with this chain in
free space (no contact), log the estimator's ``ee_wrench`` output
(``chain.estimator.GetOutputPort("ee_wrench")``) over a few seconds of motion like your task's,
and fit it with :func:`stucco_drake.core.detection.fit_residual_statistics` (samples, floor
std); the uncalibrated default is only for wiring.
"""

from __future__ import annotations

import dataclasses

import numpy as np
from pydrake.systems.framework import DiagramBuilder, OutputPort
from pydrake.systems.primitives import MatrixGain

from stucco_drake.core.hypothesis_params import HypothesisParams
from stucco_drake.core.motion_scale import MOTION_SCALES
from stucco_drake.core.penetration import RobotPenetration
from stucco_drake.core.shapes import BoxSdf, CylinderSdf
from stucco_drake.systems.action_contacts_assembler import ActionContactsAssembler
from stucco_drake.systems.bubble_contact_sensor import BubbleContactSensor
from stucco_drake.systems.contact_detector import ContactDetector, default_threshold
from stucco_drake.systems.contact_isolator import ContactIsolator, GripperPoseFromState
from stucco_drake.systems.observed_robot import ObservedRobot
from stucco_drake.systems.soft_tracking_filter import SoftTrackingFilter
from stucco_drake.systems.target_pose_estimator import TargetPoseEstimator
from stucco_drake.systems.wrench_estimator import ExternalWrenchEstimator


@dataclasses.dataclass
class Tactile:
    """Soft-bubble touch sensing in a simulated plant (optional input of the chain).

    Attributes:
        plant, scene_graph: the simulated plant (robot and objects) and its SceneGraph.
        bodies: the plant's bodies whose ellipsoid collision geometries are the bubbles.
        contact_results, body_poses: the plant's contact-results and body-poses output ports
            (or ports that export them).
        noise_std, noise_seed: Gaussian noise on each reported point (m) and its seed.
    """

    plant: object
    scene_graph: object
    bodies: list
    contact_results: OutputPort
    body_poses: OutputPort
    noise_std: float = 0.0
    noise_seed: int | None = None


@dataclasses.dataclass
class ContactTracking:
    """The chain's systems (None where not added) and its exported output ports by name."""

    estimator: ExternalWrenchEstimator
    detector: ContactDetector
    pose: GripperPoseFromState
    bubble_sensor: BubbleContactSensor | None
    isolator: ContactIsolator
    assembler: ActionContactsAssembler
    tracking: SoftTrackingFilter
    target_estimator: TargetPoseEstimator
    outputs: dict[str, OutputPort]


#: The chain's outputs: (system attribute, port name).
OUTPUTS = (
    ("tracking", "map_points"), ("tracking", "segment_labels"),
    ("target_estimator", "target_pose"), ("target_estimator", "estimate"),
    ("target_estimator", "pose_hypotheses"), ("target_estimator", "target_confidence"),
    ("assembler", "action_contacts"), ("assembler", "ee_pose"), ("detector", "in_contact"),
)  # fmt: skip


def add_contact_tracking(
    builder: DiagramBuilder,
    robot: ObservedRobot,
    *,
    robot_state: OutputPort,
    applied_torque: OutputPort,
    action_index: OutputPort,
    time_step: float,
    tracker,
    tracker_seed: int,
    penetration: RobotPenetration,
    target_shape: BoxSdf | CylinderSdf,
    icp_seed: int,
    cpf_seed: int,
    estimator_kwargs: dict | None = None,
    threshold: float | None = None,
    isolator_kwargs: dict | None = None,
    tactile: Tactile | None = None,
    truth=None,
    truth_state: OutputPort | None = None,
    dx_model: str = "ee",
    hypothesis_params: HypothesisParams | None = None,
    motion_scales=MOTION_SCALES,
) -> ContactTracking:
    """Adds the contact-tracking chain to ``builder``; returns its systems and outputs.

    Args:
        robot: the robot model: robot-only plant, end-effector frame E, observed joints.
        robot_state: output port of the robot's measured [q; v] in ``robot.plant``'s order
            (2 nv; rad, m, rad/s, m/s); the chain selects the observed joints.
        applied_torque: output port of the generalized forces the robot's actuators applied,
            in the same order (nv; N m or N).
        action_index: output port of the current action's index (1,), which the detector
            uses to close one action's contacts and open the next (the tracker updates once
            per completed action).
        time_step: the plant's time step (s); every per-step system runs at it.
        tracker: a :class:`~stucco_drake.core.tracker.Tracker` (e.g. ``SoftTracker``).
        tracker_seed, icp_seed, cpf_seed: seeds of the tracker, pose-estimate restarts, CPF.
        penetration: pxpen of the robot's geometry in E (for the tracker's contact motion and
            the pose estimator's free space).
        target_shape: the target object's known shape in its own frame.
        estimator_kwargs: :class:`ExternalWrenchEstimator` settings (gain, noise,
            ``residual_statistics``, ``sampled_plant_outputs``, ...).
        threshold: the detector's chi-square threshold (default
            :func:`~stucco_drake.systems.contact_detector.default_threshold`).
        isolator_kwargs: :class:`ContactIsolator` settings; pass ``samples`` (points and
            normals on the robot's surface in E) for a robot other than ours.
        tactile: bubble sensing (optional): the isolator then prefers bubble points.
        truth, truth_state: an optional ground-truth labeller for scoring and the port of the
            state it reads (see :class:`ActionContactsAssembler`).
        dx_model: how tracked contact points move (see :class:`SoftTrackingFilter`).
        hypothesis_params: settings of the target pose estimator's pose hypotheses (m, rad
            and dimensionless costs, see
            :class:`~stucco_drake.core.hypothesis_params.HypothesisParams`; None: its
            defaults).
        motion_scales: the motion scales those hypotheses search (see
            :class:`~stucco_drake.systems.target_pose_estimator.TargetPoseEstimator`).
    """
    _check_arguments(penetration, truth, truth_state)
    h = float(time_step)
    joint_state, joint_torque = _observed_joints(builder, robot, robot_state, applied_torque)
    estimator, detector, pose = _add_proprioception(
        builder, h, robot, joint_state, joint_torque, action_index, estimator_kwargs, threshold)
    bubbles = _add_tactile(builder, h, tactile)
    isolator = _add_isolator(builder, h, cpf_seed, isolator_kwargs, estimator, pose, detector,
                             bubbles)  # fmt: skip
    assembler = _add_assembler(builder, h, detector, isolator, pose, truth, truth_state)
    tracking, target = _add_tracking(builder, h, assembler, tracker, tracker_seed, penetration,
                                     target_shape, icp_seed, dx_model,
                                     hypothesis_params, motion_scales)  # fmt: skip
    chain = ContactTracking(estimator, detector, pose, bubbles, isolator, assembler, tracking,
                            target, {})  # fmt: skip
    chain.outputs = {name: getattr(chain, system).GetOutputPort(name) for system, name in OUTPUTS}
    if truth is not None:
        chain.outputs["action_truth"] = assembler.GetOutputPort("action_truth")
    return chain


def _check_arguments(penetration, truth, truth_state) -> None:
    """One-line errors before anything is added."""
    if getattr(penetration, "robot_sdf", None) is None:
        raise ValueError("add_contact_tracking: penetration must be a grid pxpen "
                         "(RobotPenetration): the target pose estimator reads its grid")
    if (truth is None) != (truth_state is None):
        raise ValueError("add_contact_tracking: truth and truth_state go together")


def _add_proprioception(builder, h, robot: ObservedRobot, joint_state, joint_torque,
                        action_index, estimator_kwargs, threshold):  # fmt: skip
    """The momentum observer, the chi-square detector (on the action clock ``action_index``)
    and the gripper pose, all from the observed joints' state and torques."""
    estimator = builder.AddNamedSystem(
        "wrench_estimator", ExternalWrenchEstimator(h, robot, **(estimator_kwargs or {})))
    builder.Connect(joint_state, estimator.GetInputPort("state"))
    builder.Connect(joint_torque, estimator.GetInputPort("applied_torque"))
    detector = builder.AddNamedSystem("contact_detector", ContactDetector(
        h, default_threshold() if threshold is None else threshold))  # fmt: skip
    for name in ("residual_chi2", "ee_position", "ee_wrench"):
        builder.Connect(estimator.GetOutputPort(name), detector.GetInputPort(name))
    builder.Connect(action_index, detector.GetInputPort("action_index"))
    # Its own context on the same robot plant: the pose may be evaluated at any time.
    pose = builder.AddNamedSystem("gripper_pose", GripperPoseFromState(ObservedRobot(
        robot.plant, robot.frame, joints=robot.joints, positions=robot.positions)))
    builder.Connect(joint_state, pose.GetInputPort("state"))
    return estimator, detector, pose


def _add_assembler(builder, h, detector, isolator, pose, truth, truth_state):
    """The per-action contact assembler: the detector's actions, the isolator's points, the
    gripper pose and, with ``truth``, the state its labeller reads."""
    assembler = builder.AddNamedSystem("action_contacts", ActionContactsAssembler(h, truth=truth))
    if truth is not None:
        builder.Connect(truth_state, assembler.GetInputPort("truth_state"))
    for name in ("current_action", "completed_action"):
        builder.Connect(detector.GetOutputPort(name), assembler.GetInputPort(name))
    for name in ("has_contact", "contact_points"):
        builder.Connect(isolator.GetOutputPort(name), assembler.GetInputPort(name))
    builder.Connect(pose.GetOutputPort("gripper_pose"), assembler.GetInputPort("gripper_pose"))
    return assembler


def _add_isolator(builder, h, cpf_seed, isolator_kwargs, estimator, pose, detector, bubbles):
    n_bubbles = 0 if bubbles is None else bubbles.num_bubbles
    isolator = builder.AddNamedSystem("contact_isolator", ContactIsolator(
        h, seed=cpf_seed, n_bubbles=n_bubbles, **(isolator_kwargs or {})))  # fmt: skip
    builder.Connect(estimator.GetOutputPort("ee_wrench"), isolator.GetInputPort("ee_wrench"))
    builder.Connect(pose.GetOutputPort("gripper_pose"), isolator.GetInputPort("gripper_pose"))
    builder.Connect(detector.GetOutputPort("in_contact"), isolator.GetInputPort("in_contact"))
    if bubbles is not None:
        for name in ("bubble_in_contact", "bubble_contact_points"):
            builder.Connect(bubbles.GetOutputPort(name), isolator.GetInputPort(name))
    return isolator


def _add_tracking(builder, h, assembler, tracker, tracker_seed, penetration, target_shape,
                  icp_seed, dx_model, hypothesis_params=None,
                  motion_scales=MOTION_SCALES):  # fmt: skip
    tracking = builder.AddNamedSystem("soft_tracking", SoftTrackingFilter(
        tracker, tracker_seed, h, dx_model=dx_model, robot_sdf=penetration.robot_sdf))
    for name in ("ee_pose", "action_contacts"):
        builder.Connect(assembler.GetOutputPort(name), tracking.GetInputPort(name))
    target = builder.AddNamedSystem("target_pose_estimator", TargetPoseEstimator(
        target_shape, penetration, icp_seed, h, hypothesis_params=hypothesis_params,
        motion_scales=motion_scales))
    builder.Connect(assembler.GetOutputPort("ee_pose"), target.GetInputPort("ee_pose"))
    for name in ("map_points", "segment_labels", "tracked_action", "point_spread"):
        builder.Connect(tracking.GetOutputPort(name), target.GetInputPort(name))
    return tracking, target


def observed_joint_selectors(robot: ObservedRobot) -> tuple[np.ndarray, np.ndarray]:
    """(S, T): the observed joints' [q; v] = S [q; v] and torques = T tau of the robot plant's
    full vectors (0/1 matrices, for ``MatrixGain``)."""
    nv, n = robot.plant.num_velocities(), robot.n
    S, T = np.zeros((2 * n, 2 * nv)), np.zeros((n, nv))
    rows = np.arange(n)
    S[rows, robot.joints] = 1.0
    S[n + rows, nv + robot.joints] = 1.0
    T[rows, robot.joints] = 1.0
    return S, T


def _observed_joints(builder, robot: ObservedRobot, robot_state, applied_torque):
    """Selector systems taking the observed joints' [q; v] and torques out of the robot's."""
    S, T = observed_joint_selectors(robot)
    state = builder.AddNamedSystem("observed_state", MatrixGain(S))
    torque = builder.AddNamedSystem("observed_torque", MatrixGain(T))
    builder.Connect(robot_state, state.get_input_port())
    builder.Connect(applied_torque, torque.get_input_port())
    return state.get_output_port(), torque.get_output_port()


def _add_tactile(builder: DiagramBuilder, h: float, tactile: Tactile | None):
    if tactile is None:
        return None
    bubbles = builder.AddNamedSystem("bubble_sensor", BubbleContactSensor(
        tactile.plant, tactile.scene_graph, h, tactile.bodies,
        noise_std=tactile.noise_std, noise_seed=tactile.noise_seed))  # fmt: skip
    builder.Connect(tactile.contact_results, bubbles.GetInputPort("contact_results"))
    builder.Connect(tactile.body_poses, bubbles.GetInputPort("body_poses"))
    return bubbles


__all__ = ["OUTPUTS", "ContactTracking", "Tactile", "add_contact_tracking",
           "observed_joint_selectors"]
