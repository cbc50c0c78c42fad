"""The Blind Object Retrieval Diagram: a scene, proprioceptive contact sensing, STUCCO, ICP.

:func:`build_bor_diagram` nests a scene's Diagram (plant, joint control, planar IK and action
sequence; see :mod:`stucco_drake.scenes.builder`) and adds around it, with
:func:`~stucco_drake.tracking.add_contact_tracking` (the chain any Diagram can use),

    robot state + applied torque -> ExternalWrenchEstimator -> ContactDetector
    -> ContactIsolator (bubbles first, BubbleContactSensor; else the CPF)
    -> ActionContactsAssembler -> SoftTrackingFilter -> TargetPoseEstimator

so that the tracker and the pose estimator update once per action, on the scene's action
clock. Only the bubble sensor and the ground-truth labeller read the plant's contact results;
the wrench estimator sees the arm's state and torques alone. :func:`run_episode` (in
:mod:`stucco_drake.bor.episode`) plays a scene through it and scores the result.

Units: m, rad, s; poses in the world frame; quaternions w-first.
"""

from __future__ import annotations

import dataclasses

import numpy as np
from pydrake.geometry import Box, Cylinder
from pydrake.multibody.plant import MultibodyPlant
from pydrake.systems.framework import Diagram, DiagramBuilder

from stucco_drake.bor.grasp import build_grasp_scene
from stucco_drake.bor.policies import PolicySettings, add_policy
from stucco_drake.core.baselines import make_tracker
from stucco_drake.core.hypothesis_params import HypothesisParams
from stucco_drake.core.motion_scale import (
    MOTION_SCALES,
    check_light_force,
    scales_under_push_limit,
)
from stucco_drake.core.penetration import RobotPenetration
from stucco_drake.core.shapes import BoxSdf, CylinderSdf
from stucco_drake.robot.gripper_sdf import gripper_penetration
from stucco_drake.robot.models import bubble_bodies, iiwa_observed_robot_arguments
from stucco_drake.scenes import BuiltScene, SceneFile, load_scene
from stucco_drake.scenes.builder import GRIPPER, IIWA, robot_base_pose
from stucco_drake.systems.action_contacts_assembler import (
    ActionContactsAssembler,
)
from stucco_drake.systems.bubble_contact_sensor import BubbleContactSensor
from stucco_drake.systems.contact_detector import (
    ContactDetector,
    calibrate_residual_statistics,
)
from stucco_drake.systems.contact_isolator import ContactIsolator
from stucco_drake.systems.contact_tracking_visualizer import ContactTrackingVisualizer
from stucco_drake.systems.contact_truth import RobotObjectContacts as PlantContacts
from stucco_drake.systems.observed_robot import ObservedRobot
from stucco_drake.systems.planar_controller import ActionClock
from stucco_drake.systems.policy_visualizer import PolicyVisualizer
from stucco_drake.systems.rummaging_policy import RummagingPolicy
from stucco_drake.systems.soft_tracking_filter import SoftTrackingFilter
from stucco_drake.systems.target_pose_estimator import TargetPoseEstimator
from stucco_drake.systems.wrench_estimator import ExternalWrenchEstimator
from stucco_drake.tracking import Tactile, add_contact_tracking


@dataclasses.dataclass
class BorDiagram:
    """The built BOR Diagram and handles into it.

    Attributes:
        diagram: the Diagram; it exports ``map_points``, ``segment_labels``, ``target_pose``,
            ``estimate``, ``action_contacts``, ``action_truth`` and ``in_contact``.
        scene: the nested scene (its ``diagram`` is the subsystem named ``scene``).
        method, seed: the tracking method and the seed every random stream derives from.
        target_name, target_shape: the target object and its known shape in its own frame.
        penetration: the gripper's pxpen used by the tracker and the pose estimator.
        estimator, detector, isolator, bubble_sensor, assembler, tracking, target_estimator:
            the systems.
        truth: the assembler's ground-truth labeller (:class:`RobotObjectContacts`).
        policy: the :class:`~stucco_drake.systems.rummaging_policy.RummagingPolicy` choosing
            the actions (None: the scene's prescribed list plays); the Diagram then exports
            its ``policy_done``.
    """

    diagram: Diagram
    scene: BuiltScene
    method: str
    seed: int
    target_name: str
    target_shape: BoxSdf | CylinderSdf
    penetration: RobotPenetration
    estimator: ExternalWrenchEstimator
    detector: ContactDetector
    isolator: ContactIsolator
    bubble_sensor: BubbleContactSensor
    assembler: ActionContactsAssembler
    tracking: SoftTrackingFilter
    target_estimator: TargetPoseEstimator
    truth: RobotObjectContacts
    policy: RummagingPolicy | None = None


# ------------------------------------------------------------------------- scene geometry
def collision_shapes(plant: MultibodyPlant, scene_graph, body) -> list:
    """(sdf, X_BG) of each box or cylinder collision geometry of ``body``: the shape's signed
    distance in its geometry frame G (m) and G's pose in the body frame. Other shapes are
    skipped (the scenes' objects are made of boxes and cylinders)."""
    inspector = scene_graph.model_inspector()
    shapes = []
    for gid in plant.GetCollisionGeometriesForBody(body):
        shape = inspector.GetShape(gid)
        if isinstance(shape, Box):
            sdf = BoxSdf((shape.width() / 2, shape.depth() / 2, shape.height() / 2))
        elif isinstance(shape, Cylinder):
            sdf = CylinderSdf(shape.radius(), shape.length() / 2)
        else:
            continue
        shapes.append((sdf, inspector.GetPoseInFrame(gid)))
    return shapes


def _volume(sdf) -> float:
    if isinstance(sdf, BoxSdf):
        return 8.0 * float(np.prod(sdf.half_extents))
    return 2.0 * np.pi * sdf.radius**2 * sdf.half_height


def target_shape(built: BuiltScene) -> BoxSdf | CylinderSdf:
    """The scene target's known shape in its body frame: its largest collision box or cylinder
    (centre offset kept; the geometry must not be rotated relative to the body but about z)."""
    body = built.free_bodies[built.scene.target]
    shapes = collision_shapes(built.plant, built.scene_graph, body)
    if not shapes:
        raise ValueError(f"target {built.scene.target!r} has no box or cylinder collision shape")
    sdf, X_BG = max(shapes, key=lambda s: _volume(s[0]))
    if isinstance(sdf, CylinderSdf):
        return CylinderSdf(sdf.radius, sdf.half_height, tuple(map(float, X_BG.translation())))
    if not np.allclose(X_BG.rotation().matrix(), np.eye(3), atol=1e-9):
        raise ValueError(f"target {built.scene.target!r}: its box is rotated in its body frame")
    return BoxSdf(sdf.half_extents, tuple(map(float, X_BG.translation())))


def target_slide(built: BuiltScene) -> dict:
    """What decides whether the gripper can slide ``built``'s target: its ``mass`` (kg), the
    lowest dynamic ``friction`` coefficient of its collision geometries, and the scene's push
    limit ``max_push_force`` (N, ``control.max_push_force``; None: none). The arguments of
    :func:`~stucco_drake.core.motion_scale.scales_under_push_limit`; episode logs keep them."""
    body = built.free_bodies[built.scene.target]
    inspector = built.scene_graph.model_inspector()
    friction = min(inspector.GetProximityProperties(gid).GetProperty(
        "material", "coulomb_friction").dynamic_friction()
        for gid in built.plant.GetCollisionGeometriesForBody(body))  # fmt: skip
    return {"mass": float(body.default_mass()), "friction": float(friction),
            "max_push_force": built.scene.control.max_push_force}


def target_motion_scales(built: BuiltScene, params: HypothesisParams | None = None) -> tuple:
    """The motion scales the target's pose hypotheses search in ``built``'s scene: every one,
    or with ``params.still_when_unslidable`` only 0 when the push limit cannot slide the
    target (:func:`target_slide`)."""
    if not (params or HypothesisParams()).still_when_unslidable:
        return tuple(MOTION_SCALES)
    return scales_under_push_limit(**target_slide(built))


@dataclasses.dataclass(frozen=True)
class PosedSurface:
    """Signed distance (m) of a primitive shape placed at X_WG in the world; picklable."""

    sdf: BoxSdf | CylinderSdf
    X_GW: np.ndarray  # 4x4

    def __call__(self, points) -> np.ndarray:
        points = np.asarray(points, dtype=np.float64)
        return self.sdf(points @ self.X_GW[:3, :3].T + self.X_GW[:3, 3])


def object_surfaces(built: BuiltScene, plant_context) -> dict[str, list[PosedSurface]]:
    """name -> the collision surfaces of every object (every free body, and the welded walls
    standing on the table; not the table itself) at the poses in ``plant_context``, for the
    contact error. A free object is listed wherever it is, even pushed off the table."""
    surfaces = {}
    for name, body in {**built.free_bodies, **built.welded_bodies}.items():
        X_WB = body.EvalPoseInWorld(plant_context)
        posed = [
            PosedSurface(sdf, X_WB.multiply(X_BG).inverse().GetAsMatrix4())
            for sdf, X_BG in collision_shapes(built.plant, built.scene_graph, body)
        ]
        # The table (welded, its top at z = 0, its centre below) is no object the robot
        # rummages among.
        if posed and (name in built.free_bodies
                      or max(np.linalg.inv(s.X_GW)[2, 3] for s in posed) > 0.0):  # fmt: skip
            surfaces[name] = posed
    return surfaces


# ------------------------------------------------------------------ ground truth for scoring
class RobotObjectContacts(PlantContacts):
    """Ground truth for evaluation: the robot's contacts with objects, from contact results.

    :class:`~stucco_drake.systems.contact_truth.RobotObjectContacts` for a built scene: the
    robot is the arm and the gripper, the objects are ``BuiltScene.free_bodies`` and
    ``welded_bodies`` (named as there); the scratch context is the scene Diagram's.
    """

    def __init__(self, built: BuiltScene):
        plant = built.plant
        robot = [plant.GetModelInstanceByName(n) for n in (IIWA, GRIPPER)]
        super().__init__(plant, built.diagram, robot, {**built.free_bodies,
                                                       **built.welded_bodies})  # fmt: skip


# --------------------------------------------------------------------------------- building
def _seeds(seed: int) -> list[int]:
    """Independent integer seeds of the tracker, the ICP restarts and the CPF from one seed."""
    return [int(s) for s in np.random.SeedSequence(seed).generate_state(3)]


def _noise_seeds(seed: int) -> list[int]:
    """Seeds of the torque and bubble noise from the episode's seed, a stream of their own
    (the others' draws stay as they were without noise)."""
    return [int(s) for s in np.random.SeedSequence([seed, 1]).generate_state(2)]


def build_bor_diagram(
    scene: SceneFile | str,
    method: str = "stucco",
    seed: int = 0,
    *,
    meshcat=None,
    tracker_params=None,
    threshold: float | None = None,
    estimator_gain: float = 50.0,
    dx_model: str = "ee",
    external_actions: bool = False,
    policy: PolicySettings | None = None,
    hypothesis_params: HypothesisParams | None = None,
) -> BorDiagram:
    """Builds the BOR Diagram of ``scene`` (a SceneFile or a scene name) with ``method``.

    Args:
        scene: the scene.
        method: a tracker name of :func:`~stucco_drake.core.baselines.make_tracker`.
        seed: seed of every random stream (tracker, ICP restarts, CPF, sensor noise).
        meshcat: draw the scene to this Meshcat (None: no drawing).
        tracker_params: the method's parameters; default the scene's for STUCCO (its
            ``tracker_preset`` and overrides), the paper's for the baselines.
        threshold: detection threshold on the chi-square statistic (default
            :func:`~stucco_drake.systems.contact_detector.default_threshold`).
        estimator_gain: the momentum observer's bandwidth K_O (1/s).
        dx_model: how the tracker moves contact points, ``"ee"`` (paper), ``"normal"`` or
            ``"cone"`` (see :class:`~stucco_drake.systems.soft_tracking_filter.SoftTrackingFilter`).
        external_actions: export a ``planar_step`` input, (dx, dy) in m (world), read at the
            start of each action, instead of playing ``scene.actions`` (closed-loop policies).
        policy: what chooses the actions besides ``scene.actions`` (see
            :mod:`stucco_drake.bor.policies`): ProbeParams, the actions then probes of the
            target's likeliest pose; RummageParams, rummaging chosen from the belief from
            the start; None: the actions alone.
        hypothesis_params: the target pose estimator's hypotheses' settings (HypothesisParams,
            m and rad; None: the defaults): its confidence, a policy's choices and the grasp.
    """
    scene = load_scene(scene) if isinstance(scene, str) else scene
    # The grasp executor sits in the scene from the start (transparent until a grasp starts),
    # so the grasp continues this very simulation and shows in its recording.
    if policy is not None and external_actions:
        raise ValueError("build_bor_diagram: policy and external_actions exclude each other")
    built = build_grasp_scene(scene, meshcat=meshcat,
                              external_actions=external_actions or policy is not None)
    h = float(scene.plant.time_step)
    fingers = np.full(2, scene.gripper_start.finger_position)
    X_WB = robot_base_pose(scene)
    tracker_seed, icp_seed, cpf_seed = _seeds(seed)
    if method == "stucco" and tracker_params is None:
        tracker_params = scene.tracker_params()
    penetration = gripper_penetration(opening=scene.gripper_start.finger_position)
    shape = target_shape(built)

    builder = DiagramBuilder()
    sub = builder.AddNamedSystem("scene", built.diagram)

    noise = scene.sensor_noise
    torque_seed, bubble_seed = _noise_seeds(seed)
    observer, stats = _observer_settings(scene, h, estimator_gain, torque_seed)
    action_index = _action_index(builder, sub, scene, external_actions or policy is not None,
                                 export=policy is None)
    if hypothesis_params is not None and hypothesis_params.light_force is not None:
        slide = target_slide(built)
        check_light_force(hypothesis_params.light_force, slide["mass"], slide["friction"])
    robot = ObservedRobot(**iiwa_observed_robot_arguments(X_WB, fingers))
    truth = RobotObjectContacts(built)
    chain = add_contact_tracking(
        builder, robot, robot_state=sub.GetOutputPort("robot_state"),
        applied_torque=sub.GetOutputPort("applied_torque"), action_index=action_index, time_step=h,
        tracker=make_tracker(method, tracker_params, penetration), tracker_seed=tracker_seed,
        penetration=penetration, target_shape=shape, icp_seed=icp_seed, cpf_seed=cpf_seed,
        # The scene's ports decide which torque goes with which state (estimator's Timing).
        estimator_kwargs=dict(observer, residual_statistics=stats, sampled_plant_outputs=bool(
            scene.plant.use_sampled_output_ports)),
        threshold=threshold, isolator_kwargs={"opening": scene.gripper_start.finger_position},
        tactile=_tactile(built, sub, noise.bubble_point_std, bubble_seed),
        truth=truth, truth_state=sub.GetOutputPort("plant_state"), dx_model=dx_model,
        hypothesis_params=hypothesis_params,
        motion_scales=target_motion_scales(built, hypothesis_params),
    )  # fmt: skip
    tracking, target, assembler = chain.tracking, chain.target_estimator, chain.assembler
    chooser = None if policy is None else add_policy(builder, sub, built, chain, policy,
                                                     penetration, shape)
    _draw_and_export(builder, meshcat, shape, chain, chooser)
    diagram = builder.Build()
    diagram.set_name(f"bor_{scene.name}_{method}")
    return BorDiagram(diagram, built, method, int(seed), scene.target, shape, penetration,
                      chain.estimator, chain.detector, chain.isolator, chain.bubble_sensor,
                      assembler, tracking, target, truth, chooser)  # fmt: skip


def _tactile(built, sub, point_std: float, seed: int) -> Tactile:
    """The bubbles' tactile sensing of the scene ``sub`` (its contact results and body
    poses), each point with noise of ``point_std`` (m) drawn from ``seed``."""
    return Tactile(built.plant, built.scene_graph, bubble_bodies(built.plant),
                   sub.GetOutputPort("contact_results"), sub.GetOutputPort("body_poses"),
                   point_std, seed)  # fmt: skip


def _draw_and_export(builder, meshcat, shape, chain, chooser) -> None:
    """Draws the tracking (and the policy's choices, with a ``chooser``) to ``meshcat`` if
    any, and exports the chain's outputs but the end effector's pose."""
    if meshcat is not None:
        _add_drawing(builder, meshcat, shape, chain)
        if chooser is not None:
            _add_policy_drawing(builder, meshcat, shape, chain, chooser)
    for name, port in chain.outputs.items():
        if name != "ee_pose":
            builder.ExportOutput(port, name)


def _observer_settings(scene: SceneFile, h: float, gain: float, noise_seed: int):
    """(observer, stats): the wrench estimator's settings (bandwidth ``gain`` K_O in 1/s, and
    the scene's torque and velocity noise drawn from ``noise_seed``) and the detector's
    free-space residual statistics calibrated at the plant's time step ``h`` (s)."""
    noise = scene.sensor_noise
    observer = {"gain": gain}
    if noise.torque_std > 0 or noise.velocity_std > 0:
        observer.update(torque_noise_std=noise.torque_std, velocity_noise_std=noise.velocity_std,
                        noise_seed=noise_seed)  # fmt: skip
    # Calibrated once per noise level on draws of their own (seed 0, as a sensor is
    # calibrated once, not per episode): the detector's statistics are those of the sensor.
    calibration = dict(observer, noise_seed=0) if "noise_seed" in observer else observer
    stats = calibrate_residual_statistics(time_step=h, estimator_kwargs=calibration)
    return observer, stats


def _action_index(builder: DiagramBuilder, sub, scene: SceneFile, external_actions: bool,
                  export: bool = True):  # fmt: skip
    """The port of the current action's index: the scene's action sequence, or with
    ``external_actions`` an action clock beside the scene's ``planar_step`` input, exported
    when ``export`` (else a policy inside the Diagram feeds it)."""
    if not external_actions:
        return sub.GetOutputPort("action_index")
    if export:
        builder.ExportInput(sub.GetInputPort("planar_step"), "planar_step")
    clock = builder.AddNamedSystem("action_clock", ActionClock(scene.action_duration))
    return clock.get_output_port()


def _add_policy_drawing(builder: DiagramBuilder, meshcat, shape, chain, chooser) -> None:
    """The policy's push and the pose hypotheses drawn to ``meshcat`` every 0.05 s."""
    drawing = builder.AddNamedSystem("policy_visualizer", PolicyVisualizer(meshcat, shape, 0.05))
    builder.Connect(chooser.GetOutputPort("planar_step"), drawing.GetInputPort("planar_step"))
    builder.Connect(chain.outputs["ee_pose"], drawing.GetInputPort("ee_pose"))
    builder.Connect(chain.target_estimator.GetOutputPort("pose_hypotheses"),
                    drawing.GetInputPort("pose_hypotheses"))


def _add_drawing(builder: DiagramBuilder, meshcat, shape, chain) -> None:
    """The tracked points, their segments, the action's contacts and the target estimate
    (``shape`` at the estimated pose) drawn to ``meshcat``, published every 0.05 s."""
    drawing = builder.AddNamedSystem(
        "contact_tracking_visualizer", ContactTrackingVisualizer(meshcat, shape, 0.05)
    )
    tracking, target, assembler = chain.tracking, chain.target_estimator, chain.assembler
    for system, name in ((tracking, "map_points"), (tracking, "segment_labels"),
                         (assembler, "action_contacts"), (target, "target_pose")):  # fmt: skip
        builder.Connect(system.GetOutputPort(name), drawing.GetInputPort(name))
