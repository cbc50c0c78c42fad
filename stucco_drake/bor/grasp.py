"""Grasping the target at its estimated pose after rummaging (Blind Object Retrieval's last step).

:func:`execute_grasp` runs a top-down grasp from the simulator's current state with a
:class:`~stucco_drake.systems.grasp_executor.GraspExecutor`: raise, open, move above the
estimate while turning so the fingers close across the target's short horizontal side, descend,
close, lift 10 cm. A round target may be closed on along any axis: when a finger lands on
something on the way down, the gripper rises and tries the next one. It judges the outcome
two ways:

* **lift success**: the target's origin ends at least ``min_lift`` (5 cm) above where it was
  before the grasp, and lies between the fingers (see :func:`between_fingers`);
* **the paper's geometric criterion** (RA-L 2022 Sec. V-C: "closed on the two long sides of the
  box and not on a corner, or around more than half of the tomato can"), made precise in
  :func:`geometric_check` from the true target pose and the measured gripper pose once the
  fingers have closed.

Units: m, rad, s; poses in the world frame; the table top is at z = 0.
"""

from __future__ import annotations

import dataclasses
import math
import time

import numpy as np
from pydrake.math import RigidTransform
from pydrake.systems.analysis import Simulator

from stucco_drake.core.box_approach import aside_shifts, box_approach_offsets
from stucco_drake.core.grasp_choice import PAD_HALF_WIDTH, grasp_at, grasp_closes
from stucco_drake.core.grasp_yaw import cylinder_grasp_yaws
from stucco_drake.core.hypothesis_params import END_APPROACHES, check_box_approach
from stucco_drake.core.shapes import BoxSdf, CylinderSdf
from stucco_drake.scenes.builder import GRIPPER, IIWA, BuiltScene, build_scene, yaw_of
from stucco_drake.scenes.scene_file import SceneFile
from stucco_drake.systems.grasp_executor import GraspExecutor

#: Gripper frame to the palm's underside, and to the bubbles' lowest point (m, along world z).
PALM_ABOVE_FRAME, BUBBLE_BELOW_FRAME = 0.06, 0.055
#: Clearances (m): palm above the target's top, bubbles above the table, safe transit height.
PALM_CLEARANCE, TABLE_CLEARANCE, SAFE_HEIGHT = 0.01, 0.01, 0.30
EXECUTOR_NAME = "grasp_executor"
#: Finger actuator effort limit (N) in grasp scenes; see :func:`build_grasp_scene`.
FINGER_EFFORT = 120.0


@dataclasses.dataclass
class GraspResult:
    """Outcome of one grasp.

    Attributes:
        success: lift >= ``min_lift`` and the target's origin between the fingers at the end.
        lift_height: rise of the target's origin from before the grasp to the end (m).
        geometric_ok: the paper's criterion at the end of closing (see :func:`geometric_check`).
        final_pose: the target's true (x, y, z, yaw) at the end (m, rad, world).
        reason: why it failed (or "ok"), with the numbers.
        sim_time: simulated duration of the grasp (s); wall_time: its wall-clock time (s).
        attempts: descents made (more than one when a descent or a slide was blocked and another
            closing yaw or approach was tried).
        withdrew: the last attempt was blocked and the gripper rose without closing
            (``withdraw_when_blocked``).
    """

    success: bool
    lift_height: float
    geometric_ok: bool
    final_pose: np.ndarray
    reason: str
    sim_time: float = 0.0
    wall_time: float = 0.0
    attempts: int = 1
    withdrew: bool = False


def build_grasp_scene(scene: SceneFile, *, meshcat=None, external_actions: bool = True,
                      finger_effort: float | None = FINGER_EFFORT,
                      **executor_kwargs) -> BuiltScene:
    """``build_scene`` with a :class:`GraspExecutor` (named ``grasp_executor``) between the
    planar controller and the joint controller; it stays transparent until a grasp starts.

    ``executor_kwargs`` go to :class:`GraspExecutor` (period, gain, lift, durations, ...).
    ``finger_effort`` (N, None keeps the model's) raises the finger actuators' effort limit:
    the model's 40 N squeezes at most 2 x 40 x 0.545 (bubble-box friction) = 44 N of friction,
    less than the 10 kg box's 98 N weight; the paper's Panda fingers (30 N, friction 2) held
    up to 120 N. 120 N per finger gives 131 N.
    """

    def insert(builder, desired, robot_state):
        if finger_effort is not None:
            _set_finger_effort(builder, finger_effort)
        robot_plant = _robot_plant_of(builder)
        executor = builder.AddNamedSystem(EXECUTOR_NAME, GraspExecutor(
            robot_plant, robot_plant.GetModelInstanceByName(IIWA),
            robot_plant.GetFrameByName("gripper_frame",
                                       robot_plant.GetModelInstanceByName(GRIPPER)),
            **executor_kwargs))
        builder.Connect(desired, executor.GetInputPort("desired_state"))
        builder.Connect(robot_state, executor.GetInputPort("robot_state"))
        builder.ExportOutput(executor.GetOutputPort("grasp_phase"), "grasp_phase")
        return executor.GetOutputPort("desired_state")

    return build_scene(scene, meshcat=meshcat, external_actions=external_actions,
                       command_hook=insert)


def _set_finger_effort(builder, effort: float) -> None:
    plant = builder.GetSubsystemByName("plant")
    gripper = plant.GetModelInstanceByName(GRIPPER)
    for index in plant.GetJointActuatorIndices(gripper):
        plant.get_joint_actuator(index).set_effort_limit(effort)


def _robot_plant_of(builder):
    # The joint controller owns the robot-only plant the builder made; reuse it rather than
    # building a second copy (its model instances and frames are what the executor needs).
    return builder.GetSubsystemByName("joint_controller").get_multibody_plant_for_control()


def grasp_pose(target_pose, target_shape, current_yaw: float):
    """(x, y, yaw, z_grasp) of the gripper frame for a top-down grasp (m, rad, world).

    ``target_pose`` is a RigidTransform X_WO or (x, y, yaw). The grasp is
    :func:`~stucco_drake.core.grasp_choice.grasp_at`'s: across a box's shorter horizontal
    side; a cylinder keeps ``current_yaw``. The height puts the palm ``PALM_CLEARANCE`` above
    the top of a target resting on the table (its top at twice its half height), but keeps the
    bubbles ``TABLE_CLEARANCE`` above the table.
    """
    x, y, yaw = grasp_at(np.array(_planar(target_pose)), target_shape, current_yaw)[0]
    hz = target_shape.half_extents[2] if isinstance(target_shape, BoxSdf) \
        else target_shape.half_height
    z = max(2 * hz + PALM_CLEARANCE - PALM_ABOVE_FRAME, BUBBLE_BELOW_FRAME + TABLE_CLEARANCE)
    return float(x), float(y), float(yaw), z


def geometric_check(X_WO: RigidTransform, X_WG: RigidTransform, target_shape) -> tuple[bool, str]:
    """The paper's geometric grasp criterion, from true target pose X_WO and gripper pose X_WG:
    :func:`~stucco_drake.core.grasp_choice.grasp_closes` with the grasp centre p (the gripper
    frame's origin) and the closing axis (gripper x) projected on the target's horizontal
    plane, both in the target frame. Returns (ok, the numbers it was judged on)."""
    X_OG = X_WO.inverse() @ X_WG
    p = X_OG.translation()[:2]
    u = X_OG.rotation().matrix()[:2, 0]
    grasp = np.array([p[0], p[1], math.atan2(u[1], u[0])])
    ok = bool(grasp_closes(grasp, np.zeros(3), target_shape)[0, 0])
    c = np.asarray(target_shape.center)[:2]
    if isinstance(target_shape, BoxSdf):
        hx, hy, _ = target_shape.half_extents
        short, long_ = (0, 1) if hx <= hy else (1, 0)
        angle = math.degrees(math.acos(min(1.0, abs(math.cos(grasp[2] - short * math.pi / 2)))))
        return ok, (f"axis error {angle:.1f} deg, offsets short {p[short] - c[short]:+.3f} "
                    f"long {p[long_] - c[long_]:+.3f} m")
    axis = c - p
    d = abs(axis[0] * math.sin(grasp[2]) - axis[1] * math.cos(grasp[2]))
    return ok, f"axis offset {d:.3f} m from the closing line"


def between_fingers(X_WG: RigidTransform, p_WO, finger_q) -> bool:
    """Whether point p_WO (m, world) lies between the fingers: in the gripper frame, along the
    closing axis x between the two bubble apexes (-q_left, q_right; 1 cm tolerance for the
    squeezed membranes), within a pad's width across it (|y| <= 2 PAD_HALF_WIDTH, as a box
    grasped off-centre along its long side is still held), and within 0.15 m along z."""
    p = X_WG.inverse() @ np.asarray(p_WO)
    left, right = finger_q
    return (-left - 0.01 <= p[0] <= right + 0.01 and abs(p[1]) <= 2 * PAD_HALF_WIDTH
            and abs(p[2]) <= 0.15)


def _planar(target_pose) -> tuple[float, float, float]:
    if isinstance(target_pose, RigidTransform):
        t = target_pose.translation()
        return float(t[0]), float(t[1]), yaw_of(target_pose.rotation())
    x, y, yaw = (float(v) for v in np.asarray(target_pose, dtype=float).ravel()[[0, 1, -1]])
    return x, y, yaw


def _finger_positions(built: BuiltScene, plant_context) -> tuple[float, float]:
    gripper = built.plant.GetModelInstanceByName(GRIPPER)
    return tuple(built.plant.GetJointByName(name, gripper).get_translation(plant_context)
                 for name in ("left_finger_joint", "right_finger_joint"))


def grasp_at_pose(built: BuiltScene, simulator: Simulator, target_pose, clutter,
                  target_shape, *, box_approach: str = "top",
                  withdraw_when_blocked: bool = False) -> GraspResult:  # fmt: skip
    """:func:`execute_grasp` at an estimated ``target_pose`` (x, y, yaw; m, rad, world).

    A cylinder is closed on first along the yaw that keeps the open fingers off ``clutter``
    ((n, 3) m, world: tracked points the estimate does not put on the target), then along the
    other axes (:func:`~stucco_drake.core.grasp_yaw.cylinder_grasp_yaws`). A box is gone down
    on as ``box_approach`` says (:attr:`~stucco_drake.core.hypothesis_params.HypothesisParams.
    box_approach`): ``"end"`` beyond an end and along it (the end whose descent keeps the
    fingers off ``clutter`` first, then straight down, then the other end when a descent is
    blocked: :func:`~stucco_drake.core.box_approach.box_approach_offsets`), ``"end_aside"``
    likewise with each end's descent shifted sideways off ``clutter``
    (:func:`~stucco_drake.core.box_approach.aside_shifts`), ``"top"`` straight.
    ``withdraw_when_blocked`` as :func:`execute_grasp`'s.
    """
    context = simulator.get_context()
    X_WG = built.gripper_frame().CalcPoseInWorld(built.plant.GetMyContextFromRoot(context))
    x, y, yaw = (float(v) for v in target_pose)
    if check_box_approach(box_approach) in END_APPROACHES and isinstance(target_shape, BoxSdf):
        centre = grasp_at(np.array([x, y, yaw]), target_shape)[0, :2]
        half = target_shape.half_extents
        offsets = box_approach_offsets((*centre, yaw), half, clutter, X_WG.translation()[:2])
        shifts = aside_shifts((*centre, yaw), half, offsets, clutter) \
            if box_approach == "end_aside" else None
        return execute_grasp(built, simulator, (x, y, yaw), target_shape,
                             approach_offsets=offsets, side_shifts=shifts,
                             withdraw_when_blocked=withdraw_when_blocked)  # fmt: skip
    yaws = cylinder_grasp_yaws((x, y), clutter, yaw_of(X_WG.rotation()))
    return execute_grasp(built, simulator, (x, y, yaw), target_shape, cylinder_yaws=yaws,
                         withdraw_when_blocked=withdraw_when_blocked)


def estimate_clutter(estimate, points) -> np.ndarray:
    """The tracked ``points`` ((n, 3) m, world, oldest first) outside the segments a
    :class:`~stucco_drake.core.target_pose.TargetPoseEstimate` fitted (by its ``labels`` and
    ``members``)."""
    # Points sensed after the estimate was made (a live estimate is not remade when no
    # segment has enough points) lie beyond its labels and were not fitted: they stay.
    return np.delete(points, np.flatnonzero(np.isin(estimate.labels, estimate.members)), axis=0)


def grasp_estimate(built: BuiltScene, simulator: Simulator, estimate, points,
                   target_shape) -> GraspResult:
    """:func:`grasp_at_pose` at a :class:`~stucco_drake.core.target_pose.TargetPoseEstimate`,
    the clutter being :func:`estimate_clutter`'s."""
    return grasp_at_pose(built, simulator, (estimate.x, estimate.y, estimate.yaw),
                         estimate_clutter(estimate, points), target_shape)  # fmt: skip


def _grasp_context(built: BuiltScene, simulator: Simulator):
    """(built, simulator) holding a GraspExecutor, at the given simulator's state.

    A scene built without the executor is rebuilt with it and the plant's state and the
    clock are copied over; the joint controller's integral term restarts at zero.
    """
    if built.diagram.HasSubsystemNamed(EXECUTOR_NAME):
        return built, simulator
    grasp_built = build_grasp_scene(built.scene, external_actions=True)
    grasp_sim = Simulator(grasp_built.diagram)
    context = grasp_sim.get_mutable_context()
    context.SetTime(simulator.get_context().get_time())
    src = built.plant.GetMyContextFromRoot(simulator.get_context())
    dst = grasp_built.plant.GetMyMutableContextFromRoot(context)
    grasp_built.plant.SetPositionsAndVelocities(
        dst, built.plant.GetPositionsAndVelocities(src))
    grasp_sim.Initialize()
    return grasp_built, grasp_sim


def execute_grasp(built: BuiltScene, simulator: Simulator, target_pose, target_shape, *,
                  min_lift: float = 0.05, cylinder_yaws=None, approach_offsets=None,
                  side_shifts=None, withdraw_when_blocked: bool = False) -> GraspResult:
    """Grasps at ``target_pose`` (RigidTransform X_WO or (x, y, yaw); m, rad, world) a target of
    ``target_shape`` (BoxSdf / CylinderSdf in the target's frame) and lifts it 10 cm.

    Runs from the simulator's current state (e.g. after rummaging). With a scene from
    :func:`build_grasp_scene` it continues that simulation in place; otherwise the plant's
    state is copied into a freshly built grasp scene (the given simulator is left untouched).
    The target's true pose comes from the plant (model ``scene.target``). A cylinder can be
    grasped at any yaw: ``cylinder_yaws`` (rad, world; default the gripper's current yaw alone)
    are the closing yaws to try in turn, e.g. so the open fingers (0.2 m across, plates
    included) miss known clutter; the next is tried when a descent is blocked (see
    :class:`GraspExecutor`). A box is closed on across its short side only; its
    ``approach_offsets`` ((k, 2) m, world; default straight down alone) are where the attempts
    descend, in turn, from the grasp point before sliding to it, each shifted sideways by its
    row of ``side_shifts`` ((k, 2) m, world; default none; see :class:`GraspExecutor`).
    A target that is not between the fingers once they have closed fails there: the lift and
    hold are not simulated (``sim_time`` is then shorter). With ``withdraw_when_blocked``, a
    blocked last attempt ends the grasp (a failure, ``withdrew``): the gripper rises, fingers
    open, rather than pressing down on what stopped it.
    """
    built, simulator = _grasp_context(built, simulator)
    diagram, plant = built.diagram, built.plant
    context = simulator.get_mutable_context()
    if diagram.HasInputPort("planar_step"):
        # The scene may sit inside a larger Diagram (the BOR Diagram, whose policy feeds it).
        own = diagram.GetMyMutableContextFromRoot(context)
        port = diagram.GetInputPort("planar_step")
        if not port.HasValue(own):
            port.FixValue(own, np.zeros(2))  # the planar controller just holds its place
    executor = diagram.GetSubsystemByName(EXECUTOR_NAME)
    target = built.free_bodies[built.scene.target]
    plant_context = plant.GetMyContextFromRoot(context)
    z_before = target.EvalPoseInWorld(plant_context).translation()[2]
    X_WG = built.gripper_frame().CalcPoseInWorld(plant_context)
    yaws = [yaw_of(X_WG.rotation())] if cylinder_yaws is None else list(cylinder_yaws)
    x, y, yaw, z_grasp = grasp_pose(target_pose, target_shape, yaws[0])
    retry_yaws, offsets = yaws[1:] if isinstance(target_shape, CylinderSdf) else (), None
    shifts = None  # a box's only, with its offsets (the executor checks them)
    if isinstance(target_shape, BoxSdf) and approach_offsets is not None:
        offsets = np.asarray(approach_offsets, dtype=np.float64).reshape(-1, 2)
        retry_yaws, shifts = [yaw] * (len(offsets) - 1), side_shifts
    executor_context = executor.GetMyMutableContextFromRoot(context)
    executor.start(executor_context, (x, y), yaw, SAFE_HEIGHT, z_grasp, retry_yaws=retry_yaws,
                   approach_offsets=offsets, side_shifts=shifts,
                   withdraw=withdraw_when_blocked)  # fmt: skip
    t0, wall0 = context.get_time(), time.perf_counter()

    # A blocked descent or slide starts a new attempt (or the withdrawal), which restarts the
    # phase clock.
    attempt = -1
    while attempt != executor.attempt(executor_context)[0]:
        attempt, t_attempt = executor.attempt(executor_context)
        end = "raise" if executor.withdrew(executor_context) else "close"
        # (a withdrawal's raise may already be over: the clock ran on to the attempt's close)
        simulator.AdvanceTo(max(context.get_time(),
                                t_attempt + executor.phase_end(executor_context, end)))
    withdrew = executor.withdrew(executor_context)
    plant_context = plant.GetMyContextFromRoot(context)
    geometric_ok, geometry = geometric_check(
        target.EvalPoseInWorld(plant_context),
        built.gripper_frame().CalcPoseInWorld(plant_context), target_shape)

    # A target that is not between the closed fingers cannot be lifted by them: the grasp has
    # failed, and the lift and hold (the costliest part to simulate, squeezing) are skipped.
    closed_on = not withdrew and between_fingers(
        built.gripper_frame().CalcPoseInWorld(plant_context),
        target.EvalPoseInWorld(plant_context).translation(),
        _finger_positions(built, plant_context))
    if closed_on:
        simulator.AdvanceTo(t_attempt + executor.total_duration(executor_context))
    plant_context = plant.GetMyContextFromRoot(context)
    X_WO = target.EvalPoseInWorld(plant_context)
    X_WG = built.gripper_frame().CalcPoseInWorld(plant_context)
    lift = float(X_WO.translation()[2] - z_before)
    held = closed_on and between_fingers(X_WG, X_WO.translation(),
                                         _finger_positions(built, plant_context))
    success = lift >= min_lift and held
    reasons = []
    if lift < min_lift:
        reasons.append(f"lifted {lift:.3f} m < {min_lift:.3f} m")
    if withdrew:
        reasons.append(f"every attempt blocked ({attempt}): withdrew without closing")
    elif not closed_on:
        reasons.append("target not between the fingers after closing (no lift attempted)")
    elif not held:
        reasons.append("target not between the fingers")
    reason = "ok" if success else "; ".join(reasons)
    return GraspResult(
        success=success, lift_height=lift, geometric_ok=geometric_ok,
        final_pose=np.array([*X_WO.translation(), yaw_of(X_WO.rotation())]),
        reason=f"{reason} (geometry: {geometry})", sim_time=context.get_time() - t0,
        wall_time=time.perf_counter() - wall0, withdrew=withdrew,
        attempts=attempt if withdrew else attempt + 1)  # the withdrawal's index: the count

