"""One Blind Object Retrieval episode: rummage a scene through the BOR Diagram, then score it.

Units: m, rad, s; positions and poses in the world frame.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable

import numpy as np
from pydrake.systems.analysis import Simulator

from stucco_drake.bor.diagram import BorDiagram, build_bor_diagram, object_surfaces
from stucco_drake.core.metrics import contact_error, fowlkes_mallows, target_pose_error
from stucco_drake.scenes import SceneFile, load_scene
from stucco_drake.scenes.builder import yaw_of

#: ``grasp(bor, simulator, estimate) -> result``, called once rummaging is over; a result with
#: a ``success`` attribute (or a bool) fills :attr:`EpisodeResult.grasp_success`.
GraspHook = Callable[[BorDiagram, Simulator, object], object]

#: Plant steps past an action's end until its estimate exists: the detector closes the action,
#: the assembler forms its contacts, the filter updates, the pose estimator runs (one each),
#: plus one because a Simulator stopped at t has not yet run the updates due at t.
_PIPELINE_STEPS = 5


def executor_grasp(bor: BorDiagram, simulator: Simulator, estimate):
    """The grasp hook of the BOR task: grasp at the estimated target pose with
    :func:`stucco_drake.bor.grasp.grasp_estimate` (which continues from the simulator's state in a
    scene of its own). Without an estimate there is nothing to grasp: returns False."""
    from stucco_drake.bor.grasp import grasp_estimate

    if estimate is None:
        return False
    tracking = bor.tracking.GetMyContextFromRoot(simulator.get_context())
    points = bor.tracking.GetOutputPort("map_points").Eval(tracking)
    return grasp_estimate(bor.scene, simulator, estimate, points, bor.target_shape)


def hypotheses_grasp(bor: BorDiagram, simulator: Simulator, hypotheses):
    """The grasp hook at the target-pose ``hypotheses``' chosen pose (the grasp chosen across
    them), the clutter to keep the fingers from being the points that pose does not explain,
    placed by its motion scale between where they were sensed and where they are tracked (as
    :func:`stucco_drake.bor.log.grasp_from_log` does), a box gone down on as the estimator's
    ``box_approach`` says (withdrawn when blocked as its ``withdraw_when_blocked`` says).
    Without hypotheses: False."""
    from stucco_drake.bor.grasp import grasp_at_pose

    if hypotheses is None:
        return False
    context = simulator.get_context()
    tracked = bor.tracking.GetOutputPort("map_points").Eval(
        bor.tracking.GetMyContextFromRoot(context))
    state = bor.target_estimator.estimator_state(
        bor.target_estimator.GetMyContextFromRoot(context))
    clutter = hypotheses.unexplained_points(state.sensed_points, tracked)
    params = bor.target_estimator.hypothesis_params
    return grasp_at_pose(bor.scene, simulator, hypotheses.pose, clutter, bor.target_shape,
                         box_approach=params.box_approach,
                         withdraw_when_blocked=params.withdraw_when_blocked)  # fmt: skip


#: The grasp hooks of :func:`run_episode` by target-pose estimator.
GRASP_HOOKS = {"rules": executor_grasp, "hypotheses": hypotheses_grasp}


def action_stop_time(scene: SceneFile, k: int) -> float:
    """When (s) :func:`run_episode` stops to read action k's results."""
    return (k + 1) * scene.action_duration + _PIPELINE_STEPS * float(scene.plant.time_step)


def make_bor_simulator(bor: BorDiagram, context=None) -> Simulator:
    """A Simulator of ``bor.diagram`` (from ``context``, e.g. a clone, or the default one).

    The joint controller's integral term is the Diagram's only continuous state. An
    error-controlled integrator adapts its step from its own history, which a context does not
    hold, so a cloned context would re-run differently; a fixed step of the plant's time step
    (the events bound the steps anyway) makes every re-run from a clone identical, provided it
    stops at the same times (:func:`action_stop_time`).
    """
    simulator = Simulator(bor.diagram, context) if context is not None else Simulator(bor.diagram)
    integrator = simulator.get_mutable_integrator()
    integrator.set_fixed_step_mode(True)
    integrator.set_maximum_step_size(float(bor.scene.scene.plant.time_step))
    simulator.Initialize()
    return simulator


@dataclasses.dataclass
class EpisodeResult:
    """What one episode produced and how well.

    Attributes:
        scene, method, seed: what ran; n_actions: the actions played.
        scene_target, target_shape: the target's name and known shape (in its own frame).
        map_points: (n, 3) tracked contact points at the end (m, world).
        labels: (n,) their segment labels (the tracker's; -1 = noise for DBSCAN).
        truth_labels: (n,) the object each point was truly sensed on ("" = none known).
        isolation_errors: (n,) distance (m) from each sensed point to the nearest true contact
            at the step it was sensed (NaN when none); the points as sensed, before tracking.
        contacts_per_action: (n_actions,) number of contact points each action gave.
        detected_actions: actions the detector judged in contact.
        object_poses: name -> (x, y, z, yaw) of every free object at the end (m, rad).
        surfaces: name -> the object's :class:`~stucco_drake.bor.PosedSurface` list at the end.
        estimate: the target-pose estimator's :class:`TargetPoseEstimate` (None if none).
        target_pose_true: (x, y, yaw) of the target at the end (m, rad).
        ce_cm: contact error (cm) against the true object surfaces at their final poses.
        fmi: Fowlkes-Mallows index of the labels against the truth (points with known truth).
        grasp: the grasp hook's result (None without a hook); grasp_success its success.
        wall_time_s: wall-clock time of the simulation (s); sim_time_s the simulated time.
    """

    scene: str
    method: str
    seed: int
    n_actions: int
    scene_target: str
    target_shape: object
    map_points: np.ndarray
    labels: np.ndarray
    truth_labels: np.ndarray
    isolation_errors: np.ndarray
    contacts_per_action: np.ndarray
    detected_actions: int
    object_poses: dict
    surfaces: dict
    estimate: object
    target_pose_true: np.ndarray
    ce_cm: float
    fmi: float
    grasp: object
    grasp_success: bool | None
    wall_time_s: float
    sim_time_s: float

    def estimate_error(self) -> tuple[float, float] | None:
        """(position error in cm, yaw error in deg) of the target pose estimate against the
        target's true final pose, the yaw modulo the target's symmetry (NaN for a cylinder;
        see :func:`~stucco_drake.core.metrics.target_pose_error`); None without an estimate."""
        if self.estimate is None:
            return None
        distance, yaw = target_pose_error(self.estimate.pose, self.target_pose_true,
                                          self.target_shape)  # fmt: skip
        return 100.0 * distance, float(np.degrees(yaw))

    def estimate_words(self) -> str:
        """How far the target pose estimate is from the truth, in words (see
        :meth:`estimate_error`)."""
        error = self.estimate_error()
        if error is None:
            return "no target estimate"
        if np.isnan(error[1]):  # a cylinder: every yaw is the same pose
            return f"target estimate {error[0]:.2f} cm off"
        return f"target estimate {error[0]:.2f} cm and {error[1]:.1f} deg off"

    def summary(self) -> str:
        """One line: grasp success (or n/a), CE, FMI, how far the target pose estimate is from
        the truth, contacts and wall time."""
        gs = "n/a" if self.grasp_success is None else ("yes" if self.grasp_success else "no")
        iso = np.nanmedian(self.isolation_errors) * 100 if np.isfinite(
            self.isolation_errors).any() else float("nan")  # fmt: skip
        return (
            f"{self.scene} {self.method} seed {self.seed}: GS {gs}, CE {self.ce_cm:.2f} cm, "
            f"FMI {self.fmi:.3f}, {self.estimate_words()}, {len(self.map_points)} contacts in "
            f"{self.n_actions} actions (median isolation error {iso:.2f} cm), "
            f"wall {self.wall_time_s:.1f} s"
        )


def _with_singletons(labels: np.ndarray) -> np.ndarray:
    """Noise labels (-1) become one cluster each, the way the paper scores DBSCAN's noise."""
    labels = np.asarray(labels, dtype=np.int64).copy()
    noise = labels < 0
    labels[noise] = labels.max(initial=0) + 1 + np.arange(noise.sum())
    return labels


def score(points, labels, truth_names, surfaces) -> tuple[float, float]:
    """(CE in cm, FMI) of tracked ``points`` (n, 3) with ``labels`` against ``truth_names``
    (n,) and the true ``surfaces`` (callables, m); NaN when undefined (no points; FMI: fewer
    than two points of known truth)."""
    ce = fmi = float("nan")
    if len(points):
        ce = 100.0 * contact_error(points, surfaces)
        known = np.asarray(truth_names) != ""
        if known.sum() >= 2:  # FMI counts pairs: one point has none
            fmi = fowlkes_mallows(np.asarray(truth_names)[known], _with_singletons(labels)[known])
    return ce, fmi


def _play(bor: BorDiagram, simulator: Simulator, scene: SceneFile, n_actions: int,
          on_action) -> tuple[int, list, list[int]]:  # fmt: skip
    """Advances ``simulator`` through the first ``n_actions`` actions, or until the policy
    stops: (actions played, (sensed point, truth) of every contact, contacts per action)."""
    context = simulator.get_mutable_context()
    truth, counts = [], []
    for k in range(n_actions):
        simulator.AdvanceTo(action_stop_time(scene, k))
        contacts = bor.diagram.GetOutputPort("action_contacts").Eval(context)
        if contacts.action_index != k:
            raise RuntimeError(f"action {k}: the assembler reports {contacts.action_index}")
        action_truth = bor.diagram.GetOutputPort("action_truth").Eval(context)
        truth.extend((contacts.points[i], action_truth[i]) for i in range(len(contacts.points)))
        counts.append(len(contacts.points))
        if on_action is not None:
            on_action(k, contacts)
        if bor.policy is not None and bor.diagram.GetOutputPort("policy_done").Eval(context)[0]:
            return k + 1, truth, counts  # the policy has stopped: no action k + 1
    return n_actions, truth, counts


def _free_body_poses(built, plant_context) -> dict[str, np.ndarray]:
    """Each free body's pose (x, y, z, yaw) in W (m, rad), by name."""
    poses = {}
    for name, body in built.free_bodies.items():
        X = body.EvalPoseInWorld(plant_context)
        poses[name] = np.array([*X.translation(), yaw_of(X.rotation())])
    return poses


def run_episode(
    scene: SceneFile | str,
    method: str = "stucco",
    seed: int = 0,
    n_actions: int | None = None,
    *,
    bor: BorDiagram | None = None,
    simulator: Simulator | None = None,
    meshcat=None,
    grasp: GraspHook | None = None,
    on_action: Callable[[int, object], None] | None = None,
    dx_model: str = "ee",
    tracker_params=None,
    target_estimator: str = "rules",
    hypothesis_params=None,
) -> EpisodeResult:
    """Plays the first ``n_actions`` actions of ``scene`` (all by default) through the BOR
    Diagram (``bor``, or one built for ``method`` and ``seed``), then scores the tracking.
    A Diagram with a policy (``bor.policy``) plays until the policy stops (at most its
    ``max_actions``: any prescribed ones and its own budget).
    ``simulator`` (of ``bor.diagram`` at time 0, default :func:`make_bor_simulator`) may be
    given, e.g. to clone its context midway.

    ``on_action(k, action_contacts)`` is called after each action's contacts are formed;
    ``grasp`` (see :data:`GraspHook`) after the last action's pose estimate. ``dx_model``
    (``"ee"``, the paper, ``"normal"`` or ``"cone"``) is how the tracker moves contact
    points, ``tracker_params`` the method's parameters (None: the scene's for STUCCO, the
    paper's for the baselines) and ``hypothesis_params`` the pose hypotheses' (None: the
    defaults), when the Diagram is built here. ``target_estimator`` says
    which estimate is scored and given to ``grasp``: ``"rules"``, the segment selection's
    ``estimate``, or ``"hypotheses"``, the ``pose_hypotheses`` (grasp them with
    :func:`hypotheses_grasp`; :data:`GRASP_HOOKS` pairs each with its hook).
    """
    scene = load_scene(scene) if isinstance(scene, str) else scene
    bor = bor or build_bor_diagram(scene, method, seed, tracker_params=tracker_params,
                                   meshcat=meshcat, dx_model=dx_model,
                                   hypothesis_params=hypothesis_params)
    total = len(scene.actions) if bor.policy is None else bor.policy.max_actions
    n_actions = total if n_actions is None else min(int(n_actions), total)
    if simulator is None:
        simulator = make_bor_simulator(bor)
    context = simulator.get_mutable_context()
    start = time.perf_counter()
    n_actions, truth, counts = _play(bor, simulator, scene, n_actions, on_action)
    wall = time.perf_counter() - start

    points = np.asarray(bor.diagram.GetOutputPort("map_points").Eval(context))
    labels = np.asarray(bor.diagram.GetOutputPort("segment_labels").Eval(context))
    # The rules' TargetPoseEstimate or the PoseHypotheses: both give the chosen ``pose``.
    estimate = bor.diagram.GetOutputPort(
        "pose_hypotheses" if target_estimator == "hypotheses" else "estimate").Eval(context)
    names = np.array([t.name for _, t in truth], dtype=object).astype(str)
    errors = np.array([np.linalg.norm(p - t.point) for p, t in truth])
    built = bor.scene
    plant_context = built.plant.GetMyContextFromRoot(context)
    poses = _free_body_poses(built, plant_context)
    assembler_context = bor.assembler.GetMyContextFromRoot(context)
    missed = bor.assembler.assembler_state(assembler_context).detected_without_point
    detected = int(np.count_nonzero(counts)) + missed
    by_object = object_surfaces(built, plant_context)
    surfaces = [s for group in by_object.values() for s in group]
    ce, fmi = score(points, labels, names, surfaces)
    target = poses[scene.target]
    result = grasp(bor, simulator, estimate) if grasp is not None else None
    success = result if isinstance(result, bool) or result is None else bool(
        getattr(result, "success", False))  # fmt: skip
    return EpisodeResult(
        scene.name, bor.method, bor.seed, n_actions, scene.target, bor.target_shape, points,
        labels, names, errors,
        np.array(counts), detected, poses, by_object, estimate, target[[0, 1, 3]], ce, fmi,
        result, success, wall, context.get_time(),
    )  # fmt: skip
