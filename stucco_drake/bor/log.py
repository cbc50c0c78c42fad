"""Episode logs of the Drake BOR scenes: simulate each (scene, seed) once, replay every method.

:func:`record_episode` plays a scene's actions, each perturbed by uniform noise of up to
``action_noise`` (0.5 mm) per axis drawn from the run's seed, through the BOR Diagram
(:func:`~stucco_drake.bor.build_bor_diagram`) and writes what every tracking method needs into
an :class:`~stucco_drake.eval.episode_log.EpisodeLog`: per action the gripper pose, the
detected contact points with their dx, which object each truly touched, the planar pose of
every object and the gripper's distance to each; at the end the plant's state. Replaying a
log (:func:`stucco_drake.eval.replay.replay`) needs the gripper's pxpen
(:func:`log_penetration`) and grasps from the logged final state (:func:`grasp_from_log`).
The recording itself (:class:`EpisodeRecorder`) is shared with the closed-loop training
trials of :mod:`stucco_drake.training`; with ``policy``, :func:`record_episode` lets a policy
of :mod:`stucco_drake.bor.policies` choose the actions (``table --policy probe|belief|sweep``).

Units: m, rad, s; poses in the world frame.
"""

from __future__ import annotations

import dataclasses
import functools
import math

import numpy as np
from pydrake.systems.analysis import Simulator

from stucco_drake.bor.diagram import (
    build_bor_diagram,
    collision_shapes,
    object_surfaces,
    target_shape,
    target_slide,
)
from stucco_drake.bor.episode import make_bor_simulator, run_episode
from stucco_drake.bor.grasp import build_grasp_scene, estimate_clutter, grasp_at_pose
from stucco_drake.bor.policies import PolicySettings, coverage_scene, policy_info
from stucco_drake.core.coverage import CoverageParams
from stucco_drake.core.hypothesis_params import END_APPROACHES, HypothesisParams
from stucco_drake.core.penetration import RobotPenetration
from stucco_drake.core.shapes import BoxSdf, CylinderSdf
from stucco_drake.eval.episode_log import EpisodeLog, box_spec, cylinder_spec
from stucco_drake.eval.sets import PAPER_SCENES
from stucco_drake.eval.sources import EpisodeSource
from stucco_drake.eval.target_estimates import (
    hypotheses_estimate,
    log_motion_scales,
    rules_estimate,
)
from stucco_drake.robot.gripper_samples import sample_gripper_surface
from stucco_drake.robot.gripper_sdf import gripper_penetration
from stucco_drake.runtime import kernels
from stucco_drake.scenes import BuiltScene, SceneFile, load_scene
from stucco_drake.scenes.builder import yaw_of

#: Half-width (m) of the uniform noise added to every action axis (paper Sec. V).
ACTION_NOISE = 5e-4
#: Spacing (m) of the gripper surface samples for the robot-object distance (ambiguity).
_DISTANCE_SPACING = 0.006


def perturbed_scene(scene: SceneFile, seed: int, action_noise: float = ACTION_NOISE) -> SceneFile:
    """``scene`` with every action axis moved by U(-action_noise, action_noise) m, drawn from
    ``numpy.random.default_rng(seed)`` (the scene's actions are in units of ``max_step``)."""
    rng = np.random.default_rng(seed)
    actions = np.asarray(scene.actions, dtype=np.float64).reshape(-1, 2)
    noise = rng.uniform(-action_noise, action_noise, actions.shape) / scene.control.max_step
    return dataclasses.replace(scene, actions=(actions + noise).tolist())


# --------------------------------------------------------------------------- planar geometry
def _planar_spec(sdf, X_BG) -> np.ndarray:
    """The shape row (see ``box_spec``) of a collision shape at X_BG in its body frame: an
    upright box or cylinder keeps its kind; a lying cylinder becomes its box footprint."""
    R = X_BG.rotation().matrix()
    offset = X_BG.translation()[:2]
    if isinstance(sdf, CylinderSdf):
        axis = R[:, 2]
        if abs(abs(axis[2]) - 1.0) < 1e-6:
            return cylinder_spec(sdf.radius, sdf.half_height, offset)
        if abs(axis[2]) < 1e-6:
            yaw = math.atan2(axis[1], axis[0])
            return box_spec(sdf.half_height, sdf.radius, sdf.radius, offset, yaw)
    elif isinstance(sdf, BoxSdf):
        half = np.asarray(sdf.half_extents, dtype=np.float64)
        up = int(np.argmax(np.abs(R[2])))  # the box axis along the body's z
        if abs(abs(R[2, up]) - 1.0) < 1e-6:
            a, b = [i for i in range(3) if i != up]
            yaw = math.atan2(R[1, a], R[0, a])
            return box_spec(half[a], half[b], half[up], offset, yaw)
    raise ValueError(f"cannot log a {type(sdf).__name__} tilted in its body frame as planar")


def planar_objects(built: BuiltScene, plant_context) -> tuple[list[str], np.ndarray, np.ndarray]:
    """(names, shape rows (m, 7), shape_object (m,)) of every object on the table (free and
    welded, not the table), in the order of :func:`~stucco_drake.bor.object_surfaces`."""
    names = list(object_surfaces(built, plant_context))
    bodies = {**built.free_bodies, **built.welded_bodies}
    specs, owner = [], []
    for k, name in enumerate(names):
        for sdf, X_BG in collision_shapes(built.plant, built.scene_graph, bodies[name]):
            specs.append(_planar_spec(sdf, X_BG))
            owner.append(k)
    return names, np.array(specs).reshape(-1, 7), np.array(owner, dtype=np.int64)


def planar_poses(built: BuiltScene, plant_context, names) -> np.ndarray:
    """(k, 3) planar poses (x, y, yaw about z) of the named objects' bodies (m, rad)."""
    bodies = {**built.free_bodies, **built.welded_bodies}
    poses = []
    for name in names:
        X = bodies[name].EvalPoseInWorld(plant_context)
        poses.append([*X.translation()[:2], yaw_of(X.rotation())])
    return np.array(poses).reshape(-1, 3)


class GripperObjectDistance:
    """Distance (m, 0 in contact) from the gripper to each object, for the paper's ambiguity.

    The gripper's collision surface is sampled once (``_DISTANCE_SPACING`` apart, fingers at
    ``opening``); each object's distance is the least signed distance of a sample to its
    exact box/cylinder surfaces, clipped at 0. Sampling makes it up to half a spacing long.
    """

    def __init__(self, opening: float):
        points, _ = sample_gripper_surface(np.random.default_rng(0), _DISTANCE_SPACING, opening)
        self._points = points

    def __call__(self, built: BuiltScene, plant_context, names) -> np.ndarray:
        X_WG = built.gripper_frame().CalcPoseInWorld(plant_context)
        points = self._points @ X_WG.rotation().matrix().T + X_WG.translation()
        surfaces = object_surfaces(built, plant_context)
        return np.array([
            max(0.0, min(float(np.min(s(points))) for s in surfaces[name])) for name in names
        ])  # fmt: skip


# ------------------------------------------------------------------------------- recording
class EpisodeRecorder:
    """Collects an :class:`EpisodeLog` action by action from a running BOR Diagram.

    Whatever drives the simulation (a fixed action list through
    :func:`~stucco_drake.bor.episode.run_episode`, or a closed-loop policy) calls
    :meth:`on_action` once per action, after that action's contacts are formed, then
    :meth:`log`. Per action it keeps the end-effector pose, the detected contacts with their
    dx, the object each truly touched, every object's planar pose and the gripper's distance
    to each object (m, rad, world frame).
    """

    def __init__(self, bor, context):
        self._bor, self._context = bor, context
        built = bor.scene
        self._plant_context = built.plant.GetMyContextFromRoot(context)
        self._assembler_context = bor.assembler.GetMyContextFromRoot(context)
        self.names, self._specs, self._owner = planar_objects(built, self._plant_context)
        self._index = {name: k for k, name in enumerate(self.names)}
        self._distance = GripperObjectDistance(built.scene.gripper_start.finger_position)
        self._poses = [planar_poses(built, self._plant_context, self.names)]
        self._distances, self._positions, self._rotations = [], [], []
        self._points, self._dx, self._objects, self._offsets = [], [], [], [0]
        self._peak_forces = []

    def on_action(self, k: int, contacts) -> None:
        """Record action ``k`` (its ``ActionContacts``), with the context at its end."""
        bor, built, plant_context = self._bor, self._bor.scene, self._plant_context
        truth = bor.diagram.GetOutputPort("action_truth").Eval(self._context)
        X_WE = bor.assembler.GetOutputPort("ee_pose").Eval(self._assembler_context)
        self._positions.append(X_WE.translation().copy())
        self._rotations.append(X_WE.rotation().matrix().copy())
        self._points.append(np.asarray(contacts.points, dtype=np.float64).reshape(-1, 3))
        self._dx.append(np.asarray(contacts.dx, dtype=np.float64).reshape(-1, 3))
        self._peak_forces.append(float(contacts.peak_force))
        self._objects.extend(self._index.get(t.name, -1) for t in truth)
        self._offsets.append(self._offsets[-1] + len(self._points[-1]))
        self._poses.append(planar_poses(built, plant_context, self.names))
        self._distances.append(self._distance(built, plant_context, self.names))

    def log(self, scene: str, seed: int, action_noise: float, info: dict) -> EpisodeLog:
        """The log of what was recorded; the plant's current [q; v] is its ``final_state``.

        ``info`` is added to the producer's metadata (producer, target, finger position,
        final simulated time in s).
        """
        built, plant_context = self._bor.scene, self._plant_context
        return EpisodeLog(
            scene=scene,
            seed=int(seed),
            action_noise=float(action_noise),
            ee_position=np.array(self._positions).reshape(-1, 3),
            ee_rotation=np.array(self._rotations).reshape(-1, 3, 3),
            contact_offsets=np.array(self._offsets),
            contact_points=np.concatenate(self._points or [np.zeros((0, 3))]).reshape(-1, 3),
            contact_dx=np.concatenate(self._dx or [np.zeros((0, 3))]).reshape(-1, 3),
            contact_object=np.array(self._objects, dtype=np.int64),
            object_names=self.names,
            object_poses=np.array(self._poses),
            object_shapes=self._specs,
            shape_object=self._owner,
            robot_object_distance=np.array(self._distances).reshape(-1, len(self.names)),
            robot_shape=np.zeros(0),
            action_peak_force=np.array(self._peak_forces, dtype=np.float64),
            final_state=built.plant.GetPositionsAndVelocities(plant_context),
            info={
                "producer": "drake",
                "target": built.scene.target,
                "finger_position": float(built.scene.gripper_start.finger_position),
                "final_time_s": float(self._context.get_time()),
                **info,
            },
        )


def record_episode(
    scene: SceneFile | str,
    seed: int,
    *,
    action_noise: float = ACTION_NOISE,
    n_actions: int | None = None,
    method: str = "stucco",
    tracker_params=None,
    dx_model: str = "ee",
    policy: PolicySettings | CoverageParams | None = None,
    hypothesis_params=None,
) -> EpisodeLog:
    """Simulates ``scene`` once with run ``seed``'s perturbed actions and logs it.

    The BOR Diagram runs with ``method`` (``tracker_params``, ``dx_model``; its live tracking
    result goes to ``info["live"]`` for reference; the log's observations do not depend on it
    unless a ``policy`` is given). ``policy`` (:mod:`stucco_drake.bor.policies`): ProbeParams,
    the prescribed actions followed by probes of the target chosen from that live tracking's
    pose hypotheses; RummageParams, rummaging chosen from them from the first action;
    CoverageParams, the coverage sweep's raster instead of the prescribed actions. With a
    policy in the Diagram, ``info["policy"]`` says what it did
    (:func:`~stucco_drake.bor.policies.policy_info`); ``hypothesis_params`` sets its live pose
    hypotheses (None: the defaults). Every random stream derives from ``seed``. Returns the
    log; the plant's final [q; v] is its ``final_state``.
    """
    base = load_scene(scene) if isinstance(scene, str) else scene
    if isinstance(policy, CoverageParams):
        base = coverage_scene(base, policy)
        policy = None
    scene = perturbed_scene(base, seed, action_noise)
    bor = build_bor_diagram(scene, method, seed, tracker_params=tracker_params,
                            dx_model=dx_model, policy=policy, hypothesis_params=hypothesis_params)
    simulator = make_bor_simulator(bor)
    recorder = EpisodeRecorder(bor, simulator.get_mutable_context())
    result = run_episode(scene, method, seed, n_actions, bor=bor, simulator=simulator,
                         on_action=recorder.on_action)
    info = {
        "wall_time_s": float(result.wall_time_s),
        "kernels": kernels.status(),  # "pinned": the same log on any machine (runtime/kernels.py)
        "live": {"method": method, "ce_cm": float(result.ce_cm), "fmi": float(result.fmi)},
        "target_slide": target_slide(bor.scene),  # replays judge whether the target could slide
    }
    if bor.policy is not None:
        info["policy"] = policy_info(bor.policy, bor.policy.GetMyContextFromRoot(
            simulator.get_context()), len(scene.actions))
    return recorder.log(base.name, seed, action_noise, info)


# ------------------------------------------------------------------------------- replaying
@functools.lru_cache(maxsize=4)
def _gripper_penetration(opening: float) -> RobotPenetration:
    return gripper_penetration(opening=opening)


def log_penetration(log: EpisodeLog) -> RobotPenetration:
    """The gripper's pxpen at the log's finger opening (cached per process)."""
    return _gripper_penetration(float(log.info["finger_position"]))


def _grasp_scene(scene: str):
    return build_grasp_scene(load_scene(scene))


def grasp_from_log(log: EpisodeLog, tracker, scene: str | None = None,
                   estimator: str = "rules", hypothesis_params=None):
    """Grasp the target where the tracker's points say it is, from the logged final state.

    ``estimator`` picks how the target's pose is estimated, with a generator seeded by
    ``[log.seed, 1]``:

    * ``"rules"`` (Table II's): segment selection as the BOR Diagram does
      (:func:`~stucco_drake.eval.target_estimates.rules_estimate`); a round target is closed
      on away from the points outside the fitted segment;
    * ``"hypotheses"``: the grasp chosen across weighted pose hypotheses
      (:func:`~stucco_drake.eval.target_estimates.hypotheses_estimate`, with
      ``hypothesis_params``; None: the defaults); a round target is closed on away from the
      points the grasped pose does not explain, a box gone down on as their ``box_approach``
      says, a blocked grasp withdrawn as their ``withdraw_when_blocked`` says.

    The grasp then runs in a freshly built grasp scene set to the logged plant state, that of
    ``scene`` (a scene name or file; default: the shipped scene named ``log.scene``). Returns
    the :class:`~stucco_drake.bor.grasp.GraspResult`, or None when no segment can be fitted (no
    grasp is attempted: a failure).
    """
    built = _grasp_scene(log.scene if scene is None else str(scene))
    shape = target_shape(built)
    rng = np.random.default_rng([log.seed, 1])
    points = tracker.map_points()
    if estimator == "rules":
        estimate = rules_estimate(rng, log, tracker, shape, log_penetration(log))
        if estimate is None:
            return None
        pose, clutter = estimate.pose, estimate_clutter(estimate, points)
        grasp = {"box_approach": "top"}
    elif estimator == "hypotheses":
        found = hypotheses_estimate(rng, log, tracker, shape, log_penetration(log),
                                    hypothesis_params, log_motion_scales(log, hypothesis_params))
        if found is None:
            return None
        pose, clutter = found.pose, found.unexplained_points(log.contact_points, points)
        params = hypothesis_params or HypothesisParams()
        grasp = {"box_approach": params.box_approach,
                 "withdraw_when_blocked": params.withdraw_when_blocked}
    else:
        raise ValueError(f"estimator: expected 'rules' or 'hypotheses', got {estimator!r}")
    return _grasp_at_final_state(log, built, pose, clutter, shape, **grasp)


def grasp_true_pose(log: EpisodeLog, scene: str | None = None, *, box_approach: str = "top",
                    withdraw_when_blocked: bool = False):
    """Grasp the target at its true final pose, from the logged final state: the grasp any
    estimator would make were its estimate exact, so what the episode's end allows (a target
    flush against clutter can fail here: a finger lands on the neighbour). ``scene`` as
    :func:`grasp_from_log`'s; a round target is closed on along the gripper's yaw, a box gone
    down on as ``box_approach`` says (:func:`~stucco_drake.bor.grasp.grasp_at_pose`; with
    ``"end"`` or ``"end_aside"`` its descents ordered, and shifted, by the contacts sensed on
    other objects, what an exact estimate leaves unexplained; ``withdraw_when_blocked`` as
    :func:`~stucco_drake.bor.grasp.execute_grasp`'s). Returns the
    :class:`~stucco_drake.bor.grasp.GraspResult`."""
    built = _grasp_scene(log.scene if scene is None else str(scene))
    shape = target_shape(built)
    ends = isinstance(shape, BoxSdf) and box_approach in END_APPROACHES
    clutter = log.contact_points[log.contact_object > 0] if ends else np.zeros((0, 3))
    return _grasp_at_final_state(log, built, log.object_poses[-1, 0], clutter, shape,
                                 box_approach=box_approach,
                                 withdraw_when_blocked=withdraw_when_blocked)


def _grasp_at_final_state(log: EpisodeLog, built, pose, clutter, shape, **grasp_kwargs):
    """:func:`~stucco_drake.bor.grasp.grasp_at_pose` at ``pose`` (x, y, yaw) of the target
    of ``shape`` in the grasp scene ``built``, set to the log's final plant state and time
    (``grasp_kwargs`` go to it)."""
    simulator = Simulator(built.diagram)
    context = simulator.get_mutable_context()
    context.SetTime(float(log.info.get("final_time_s", 0.0)))
    built.plant.SetPositionsAndVelocities(
        built.plant.GetMyMutableContextFromRoot(context), log.final_state
    )
    simulator.Initialize()
    return grasp_at_pose(built, simulator, pose, clutter, shape, **grasp_kwargs)


def grasp_success(log: EpisodeLog, tracker, scene: str | None = None,
                  estimator: str = "rules", hypothesis_params=None) -> bool:
    """The ``grasp`` hook of :func:`stucco_drake.eval.replay.replay` for Drake logs (``scene``,
    ``estimator`` and ``hypothesis_params`` as :func:`grasp_from_log`'s)."""
    result = grasp_from_log(log, tracker, scene, estimator, hypothesis_params)
    return bool(result is not None and result.success)


#: The paper's four Blind Object Retrieval scenes, as sources of ``stucco-drake table``.
BOR_SCENES = PAPER_SCENES
BOR_SOURCES = {
    name: EpisodeSource(record_episode, log_penetration, grasp_success, scene_set="paper")
    for name in BOR_SCENES
}
