"""The tracking training set (paper Sec. V-B): closed-loop trials in the SELECT scenes.

A trial draws a start and a goal for the gripper in the scene's reach, then drives the BOR
Diagram (:func:`~stucco_drake.bor.diagram.build_bor_diagram` with ``external_actions``) one
action at a time: greedily towards the goal, and after every action the contact detector judged
in contact, a random walk of :data:`WALK_LENGTH` uniform actions (restarted by each new contact),
until the gripper is within :data:`DIST_FOR_DONE` of the goal or :data:`MAX_ACTIONS` actions
are played. :func:`record_trial` logs it as an :class:`~stucco_drake.eval.episode_log.EpisodeLog`
(the same recorder as the BOR episodes); a trial in contact during fewer than
:data:`MIN_CONTACT_FRACTION` of its actions, or in which the simulation flung an object (see
:data:`MAX_OBJECT_STEP`), is marked discarded (``info["discarded"]``) and the training set
skips it.

What follows the authors' code (``collect_tracking_training_data.py``, see the experiment
notes, Sec. 2.4) and what is adapted to an arm on a pedestal:

- Greedy action: the authors pick, of 100 uniform actions in [-1, 1]^2, the one whose
  predicted position xy + 0.03 u is nearest the goal; its exact optimum is
  clip((goal - xy) / max_step, -1, 1), which is used here (no sampling noise).
- Start and goal: uniform in the workspace box, at least :data:`MIN_SEPARATION` apart, the
  gripper clear of every object at both (as the authors). Added: both within the arm's
  ``reach``, and the straight path between them clear of the robot's column (distance from the
  base >= ``reach[0]``), since the paper's floating gripper had no column to get around.
- Every action's predicted end point must stay within the workspace and reach: a greedy step
  that would leave it turns by 15 degree increments until it does not (it slides around the
  column); a random step that would leave it is redrawn.
- Contact for the random walk: the detector's verdict on the action just ended (the authors'
  ``in_contact()``). "In contact" for the discard rule: the action gave at least one contact
  point to the tracker. As the authors also require, a trial with fewer than two contact
  actions is discarded (FMI needs pairs).
- The scenes have no retrieval target; the BOR Diagram's pose estimator needs one, so the
  first movable object stands in (its estimate is not used).

Units: m, rad, s; positions in the world frame.
"""

from __future__ import annotations

import dataclasses
import math
import time

import numpy as np

from stucco_drake.bor.diagram import build_bor_diagram, object_surfaces
from stucco_drake.bor.episode import action_stop_time, make_bor_simulator
from stucco_drake.bor.log import EpisodeRecorder, log_penetration
from stucco_drake.eval.episode_log import EpisodeLog
from stucco_drake.eval.sets import TRAINING_SCENES
from stucco_drake.eval.sources import EpisodeSource
from stucco_drake.robot.gripper_samples import sample_gripper_surface
from stucco_drake.scenes import SceneFile, build_scene, load_scene
from stucco_drake.systems.planar_controller import StartUnreachable, gripper_rotation

#: Random actions taken after each detected contact (paper: "random walk of length 6").
WALK_LENGTH = 6
#: A trial ends when the gripper is this close to its goal (m; the authors' dist_for_done).
DIST_FOR_DONE = 0.04
#: Most actions per trial (the authors' 300).
MAX_ACTIONS = 300
#: Least start-goal distance (m; the authors' 0.7 in a 1.4 m square).
MIN_SEPARATION = 0.7
#: Trials in contact during fewer than this fraction of their actions are discarded.
MIN_CONTACT_FRACTION = 0.05
#: Trials in which an object moved farther than this in one action (m) are discarded: a push
#: of at most one step (0.03 m) carries an object at most a few centimetres (the BOR and
#: training episodes move one by at most 0.05 m an action), so such a jump is the simulation
#: flinging an object squeezed between the arm and a wall, not a motion to track.
MAX_OBJECT_STEP = 0.1
#: Start/goal draws tried before giving up when the arm cannot reach the drawn start.
_START_DRAWS = 20
#: Least distance (m) from the gripper's surface to any object at the start and the goal.
CLEARANCE = 0.02
#: Angle (rad) by which a greedy step that would leave the reachable region is turned.
_DETOUR_STEP = math.radians(15.0)
#: Draws of a random step before giving up on finding one inside the region (then: no step).
_WALK_DRAWS = 100
#: Spacing (m) of the gripper surface samples of the clearance check.
_CLEARANCE_SPACING = 0.01


@dataclasses.dataclass(frozen=True)
class TrialPlan:
    """A trial's start and goal of the gripper frame, (x, y) in m, world frame."""

    start: tuple[float, float]
    goal: tuple[float, float]


def _segment_distance(point, a, b) -> float:
    """Distance (m) from ``point`` to the segment a-b (planar)."""
    point, a, b = (np.asarray(v, dtype=np.float64) for v in (point, a, b))
    ab = b - a
    s = np.clip(np.dot(point - a, ab) / max(float(np.dot(ab, ab)), 1e-12), 0.0, 1.0)
    return float(np.linalg.norm(a + s * ab - point))


def with_target(scene: SceneFile) -> SceneFile:
    """``scene``, its first movable primitive as the target if it names none (see module doc)."""
    if scene.target:
        return scene
    movable = [p.name for p in scene.primitives if not p.welded]
    if not movable:
        raise ValueError(f"{scene.name}: a training scene needs a movable object")
    return dataclasses.replace(scene, target=movable[0])


class ClearanceCheck:
    """Whether the gripper, placed at a planar point, keeps :data:`CLEARANCE` from every object.

    The objects (and the robot's column) are the scene's collision shapes at their initial
    poses; the gripper is sampled on its surface (``rng`` draws the samples), at the scene's
    gripper height and yaw.
    """

    def __init__(self, scene: SceneFile, rng: np.random.Generator):
        built = build_scene(scene)
        context = built.plant.CreateDefaultContext()
        self._surfaces = [s for group in object_surfaces(built, context).values() for s in group]
        start = scene.gripper_start
        points, _ = sample_gripper_surface(rng, _CLEARANCE_SPACING, start.finger_position)
        self._points = points @ gripper_rotation(start.yaw).matrix().T
        self._height = float(start.height)

    def clearance(self, xy) -> float:
        """Least signed distance (m) from the gripper at ``xy`` (m, world) to any object."""
        points = self._points + np.array([xy[0], xy[1], self._height])
        return min(float(np.min(s(points))) for s in self._surfaces)

    def __call__(self, xy) -> bool:
        return self.clearance(xy) >= CLEARANCE


def plan_trial(scene: SceneFile, rng: np.random.Generator, clear=None,
               max_draws: int = 10_000) -> TrialPlan:
    """Draws a start and goal (see the module doc) with ``rng``; ``clear(xy) -> bool`` is the
    clearance check (default a :class:`ClearanceCheck` of ``scene`` drawing from ``rng``)."""
    clear = ClearanceCheck(scene, rng) if clear is None else clear
    x_min, x_max, y_min, y_max = scene.workspace
    base = np.asarray(scene.robot_base[:2], dtype=np.float64)
    for _ in range(max_draws):
        start, goal = rng.uniform([x_min, y_min], [x_max, y_max], size=(2, 2))
        if (
            np.linalg.norm(goal - start) >= MIN_SEPARATION
            and scene.in_workspace(start) and scene.in_workspace(goal)
            and _segment_distance(base, start, goal) >= scene.reach[0]
            and clear(start) and clear(goal)
        ):  # fmt: skip
            return TrialPlan(tuple(map(float, start)), tuple(map(float, goal)))
    raise RuntimeError(f"{scene.name}: no start and goal found in {max_draws} draws")


class GreedyRandomWalkPolicy:
    """The authors' data-collection policy, on normalized actions u in [-1, 1]^2.

    :meth:`act` gives the next action from the gripper's measured position and whether the
    action just ended was in contact: ``WALK_LENGTH`` uniform random actions after a contact
    (drawn from ``rng``; each contact restarts the count), else the greedy action towards
    ``goal``. Every action keeps its predicted end point xy + max_step u inside the scene's
    workspace and reach (see the module doc).
    """

    def __init__(self, scene: SceneFile, goal, rng: np.random.Generator,
                 walk_length: int = WALK_LENGTH):
        self._scene, self._rng = scene, rng
        self._goal = np.asarray(goal, dtype=np.float64)
        self._max_step = float(scene.control.max_step)
        self._walk_length = int(walk_length)
        self.walk_left = 0

    def _inside(self, xy, u) -> bool:
        return self._scene.in_workspace(np.asarray(xy) + self._max_step * np.asarray(u))

    def greedy(self, xy) -> np.ndarray:
        """clip((goal - xy) / max_step, -1, 1), turned if needed to stay reachable."""
        delta = (self._goal - np.asarray(xy, dtype=np.float64)) / self._max_step
        for k in range(1, int(math.pi / _DETOUR_STEP) * 2 + 1):
            angle = (k // 2) * _DETOUR_STEP * (1 if k % 2 else -1)  # 0, +15, -15, +30, ...
            c, s = math.cos(angle), math.sin(angle)
            u = np.clip([c * delta[0] - s * delta[1], s * delta[0] + c * delta[1]], -1.0, 1.0)
            if self._inside(xy, u):
                return u
        return np.zeros(2)

    def random(self, xy) -> np.ndarray:
        """A uniform action in [-1, 1]^2 whose end point is reachable (zero if none found)."""
        for _ in range(_WALK_DRAWS):
            u = self._rng.uniform(-1.0, 1.0, 2)
            if self._inside(xy, u):
                return u
        return np.zeros(2)

    def act(self, xy, in_contact: bool) -> np.ndarray:
        """The next normalized action from the measured ``xy`` (m, world)."""
        if in_contact:
            self.walk_left = self._walk_length
        if self.walk_left > 0:
            self.walk_left -= 1
            return self.random(xy)
        return self.greedy(xy)


def contact_fraction(log: EpisodeLog) -> float:
    """Fraction of the log's actions that gave the tracker at least one contact point."""
    return int(np.count_nonzero(np.diff(log.contact_offsets))) / max(log.n_actions, 1)


def discard_reason(log: EpisodeLog, min_contact_fraction: float = MIN_CONTACT_FRACTION) -> str:
    """Why a trial is left out of the training set ("" to keep it): in contact (at least one
    contact point) during fewer than ``min_contact_fraction`` of its actions, or in fewer than
    two actions, or an object flung (moved more than :data:`MAX_OBJECT_STEP` in one action)."""
    if log.n_actions and log.object_poses.shape[1]:
        step = np.linalg.norm(np.diff(log.object_poses[:, :, :2], axis=0), axis=2)
        action, k = np.unravel_index(int(np.argmax(step)), step.shape)
        if step[action, k] > MAX_OBJECT_STEP:
            return (f"{log.object_names[k]} moved {step[action, k]:.2f} m in action {action} "
                    f"(> {MAX_OBJECT_STEP} m: flung by the simulation)")
    fraction = contact_fraction(log)
    if fraction < min_contact_fraction:
        return (f"in contact during {fraction:.1%} of {log.n_actions} actions "
                f"(< {min_contact_fraction:.0%})")
    contact_actions = int(np.count_nonzero(np.diff(log.contact_offsets)))
    if contact_actions < 2:
        return f"in contact during only {contact_actions} action(s)"
    return ""


def record_trial(
    scene: SceneFile | str,
    seed: int,
    *,
    max_actions: int = MAX_ACTIONS,
    method: str = "stucco",
    plan: TrialPlan | None = None,
) -> EpisodeLog:
    """Plays one closed-loop training trial of ``scene`` and logs it.

    Args:
        scene: a training scene (SceneFile or name).
        seed: the trial's seed: ``numpy.random.SeedSequence(seed)`` gives the start/goal draw
            and the random walk their generators; the BOR Diagram (tracker, CPF) gets ``seed``.
        max_actions: most actions played.
        method: the BOR Diagram's live tracker (the log does not depend on it).
        plan: start and goal (default: drawn by :func:`plan_trial`, again while the arm
            cannot reach the drawn start).

    Returns:
        The log; ``info`` holds the plan, whether the goal was reached, the fraction of actions
        in contact, the detector's contact verdicts, ``discarded`` and its reason.
    """
    base = load_scene(scene) if isinstance(scene, str) else scene
    plan_rng, walk_rng = (np.random.default_rng(s) for s in np.random.SeedSequence(seed).spawn(2))
    plan, scene, bor = _reachable_trial(base, plan_rng, plan, method, seed)
    policy = GreedyRandomWalkPolicy(scene, plan.goal, walk_rng)
    played = _play_trial(bor, scene, plan, policy, max_actions)
    log = played.recorder.log(base.name, seed, 0.0, {
        "wall_time_s": float(played.wall),
        "trial": {
            "start": list(plan.start), "goal": list(plan.goal), "reached_goal": played.reached,
            "actions": played.actions, "detector_in_contact": played.verdicts,
        },
    })  # fmt: skip
    reason = discard_reason(log)
    log.info["contact_fraction"] = contact_fraction(log)
    log.info["discarded"] = bool(reason)
    log.info["discard_reason"] = reason
    return log


def _reachable_trial(base: SceneFile, plan_rng: np.random.Generator, plan: TrialPlan | None,
                     method: str, seed: int):  # fmt: skip
    """(plan, scene, bor): the trial's plan (``plan``, or drawn from ``plan_rng`` until the
    arm can reach its start, at most :data:`_START_DRAWS` times), ``base`` with the gripper
    starting there and a target (:func:`with_target`), and its BOR Diagram with external
    actions. StartUnreachable for a given ``plan`` the arm cannot reach."""
    drawn = plan is None
    for _ in range(_START_DRAWS):
        plan = plan_trial(base, plan_rng) if drawn else plan
        start = dataclasses.replace(base.gripper_start, xy=list(plan.start))
        scene = with_target(dataclasses.replace(base, gripper_start=start, actions=[]))
        try:
            return plan, scene, build_bor_diagram(scene, method, seed, external_actions=True)
        except StartUnreachable:
            # Within reach by distance, but a joint limit forbids it (joint 1 stops at 170
            # degrees, so straight behind the base is out): draw again from the same generator.
            if not drawn:
                raise
    raise RuntimeError(f"{base.name}: no reachable start in {_START_DRAWS} draws")


@dataclasses.dataclass
class _PlayedTrial:
    """A played trial: its recorder, the normalized actions played, the detector's contact
    verdict on each, whether the goal was reached and the wall time (s) of the actions."""

    recorder: EpisodeRecorder
    actions: list
    verdicts: list
    reached: bool
    wall: float


def _play_trial(bor, scene: SceneFile, plan: TrialPlan, policy: GreedyRandomWalkPolicy,
                max_actions: int) -> _PlayedTrial:  # fmt: skip
    """Simulates ``bor`` action by action, each chosen by ``policy`` from the gripper's
    position (m, world) and the detector's verdict on the action before, until the gripper
    is within :data:`DIST_FOR_DONE` of the goal or ``max_actions`` were played."""
    simulator = make_bor_simulator(bor)
    context = simulator.get_mutable_context()
    recorder = EpisodeRecorder(bor, context)
    plant_context = bor.scene.plant.GetMyContextFromRoot(context)
    detector_context = bor.detector.GetMyContextFromRoot(context)
    step_port = bor.diagram.GetInputPort("planar_step")
    max_step, duration = float(scene.control.max_step), float(scene.action_duration)

    def gripper_xy() -> np.ndarray:
        return bor.scene.gripper_frame().CalcPoseInWorld(plant_context).translation()[:2]

    u = policy.act(gripper_xy(), in_contact=False)
    actions, verdicts, reached = [], [], False
    wall = time.perf_counter()
    for k in range(int(max_actions)):
        actions.append(u.tolist())
        step_port.FixValue(context, max_step * u)
        # Stop where action k ends: the controller reads the next step at that instant, in the
        # next AdvanceTo, so the policy decides it from action k's detector verdict first.
        simulator.AdvanceTo((k + 1) * duration)
        verdict = bor.detector.GetOutputPort("current_action").Eval(detector_context)
        if verdict.action_index != k:
            raise RuntimeError(f"action {k}: the detector reports action {verdict.action_index}")
        verdicts.append(bool(verdict.in_contact))
        xy = gripper_xy()
        reached = bool(np.linalg.norm(np.asarray(plan.goal) - xy) < DIST_FOR_DONE)
        u = np.zeros(2) if reached else policy.act(xy, bool(verdict.in_contact))
        step_port.FixValue(context, max_step * u)
        simulator.AdvanceTo(action_stop_time(scene, k))
        contacts = bor.diagram.GetOutputPort("action_contacts").Eval(context)
        if contacts.action_index != k:
            raise RuntimeError(f"action {k}: the assembler reports {contacts.action_index}")
        recorder.on_action(k, contacts)
        if reached:
            break
    return _PlayedTrial(recorder, actions, verdicts, reached, time.perf_counter() - wall)


def is_discarded(log: EpisodeLog) -> bool:
    """Whether a trial's log is marked discarded (logs of other producers never are)."""
    return bool(log.info.get("discarded", False))


#: The training scenes as sources of ``stucco-drake sweep`` (no grasp: tracking only).
TRAINING_SOURCES = {
    name: EpisodeSource(record_trial, log_penetration, scene_set="training")
    for name in TRAINING_SCENES
}

__all__ = [
    "TRAINING_SCENES",
    "TRAINING_SOURCES",
    "ClearanceCheck",
    "GreedyRandomWalkPolicy",
    "TrialPlan",
    "contact_fraction",
    "discard_reason",
    "is_discarded",
    "plan_trial",
    "record_trial",
    "with_target",
]
