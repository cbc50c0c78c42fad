"""The two sensing scenes of ``test_sensing_in_scene.py`` and what they are judged with: the
scenes' text, one simulation of each with the sensing chain wired as in
:func:`stucco_drake.bor.build_bor_diagram`, the plant's own contact results as ground truth,
and helpers that pick steps and actions out of a run. Units: m, N, s; world frame.
"""


from __future__ import annotations

import time

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.multibody.plant import ContactResults
from pydrake.multibody.tree import BodyIndex
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder, LeafSystem
from pydrake.systems.primitives import LogVectorOutput, MatrixGain
from test_scene import TABLE

from stucco_drake.robot.models import bubble_bodies, iiwa_observed_robot_arguments
from stucco_drake.scenes import build_scene, load_scene_text
from stucco_drake.scenes.builder import GRIPPER, IIWA, robot_base_pose
from stucco_drake.systems.bubble_contact_sensor import BubbleContactSensor
from stucco_drake.systems.contact_detector import (
    ContactDetector,
    calibrate_residual_statistics,
    default_threshold,
)
from stucco_drake.systems.contact_isolator import ContactIsolator, GripperPoseFromState
from stucco_drake.systems.observed_robot import ObservedRobot
from stucco_drake.systems.wrench_estimator import ExternalWrenchEstimator
from stucco_drake.tracking import observed_joint_selectors

GAIN = 50.0  # observer bandwidth (1/s), bor's default
SETTLE_STEPS = 50  # 0.1 s at 2 ms: five observer time constants
MAX_PATCHES = 4  # patch centroids kept per step by the truth system
CONTACT_FORCE = 1.0  # N: a true contact step for the per-action labels
MIN_CONTACT_STEPS = 5  # 10 ms of such steps make an action a true contact action

# The gripper starts at (0.15, 0) with its closing axis along world y, so its sides (finger
# plates' faces, gripper y) face world +-x and the plates' outer faces world +-y.
_R = 1.0 / 3.0  # a 1 cm retreat, in units of the 3 cm step
CLOSED_OBJECTS = """primitives:
- {name: cylinder, shape: cylinder, size: [0.03, 0.12], xyz: [0.225, 0.0325, 0.06],
   mass: 1.0, friction: 0.8}
- {name: box_side, shape: box, size: [0.1, 0.15, 0.12], xyz: [0.05, 0.025, 0.06],
   mass: 1.0, friction: 0.8}
- {name: box_plate, shape: box, size: [0.14, 0.1, 0.12], xyz: [0.18, -0.105, 0.06],
   mass: 1.0, friction: 0.8}
"""
CLOSED_ACTIONS = [
    # 0-3: the cylinder, whose axis is in front of the +x finger plate only (single patch).
    (1, 0), (-_R, 0), (1, 0), (-_R, 0),
    # 4-5 travel; 6-9: box_side's face against both plates (two patches).
    (-1, 0), (-0.5, 0), (-1, 0), (_R, 0), (-1, 0), (_R, 0),
    # 10-11 travel; 12-15: box_plate pushed with the -y finger plate's outer face.
    (1, 0), (0.5, 0), (0, -1), (0, _R), (0, -1), (0, _R),
]  # fmt: skip
SINGLE_PATCH, TWO_PATCH, PLATE_FACE = (0, 1, 2, 3), (6, 7, 8, 9), (12, 13, 14, 15)
OPEN_OBJECTS = """primitives:
- {name: post, shape: box, size: [0.04, 0.02, 0.12], xyz: [0.15, 0.0, 0.06], welded: true,
   friction: 0.5}
"""
_S = 2.5 / 3.0  # 2.5 cm: each bubble's apex starts 2 cm from the post
OPEN_ACTIONS = [(0, -_S), (0, _S), (0, _S), (0, -_S)] * 2


def scene_text(objects: str, actions, finger: float) -> str:
    steps = "".join(f"  - [{a:.6f}, {b:.6f}]\n" for a, b in actions)
    return (
        f"name: sensing\ngripper_start:\n  xy: [0.15, 0.0]\n  height: 0.1\n"
        f"  finger_position: {finger}\naction_duration: 0.5\n"
        f"plant:\n  time_step: 0.002\n  discrete_contact_approximation: sap\n"
        f"  contact_model: hydroelastic_with_fallback\n  use_sampled_output_ports: false\n"
        f"{TABLE}{objects}actions:\n{steps}"
    )


class GripperObjectContacts(LeafSystem):
    """Ground truth from the plant's contact results, as one vector per step.

    Output ``truth``: [F (3): total force the objects apply to the gripper's bodies (N, world);
    number of gripper-object contacts; 1.0 if an arm link touches an object; centroids of the
    ``MAX_PATCHES`` strongest contacts (3 each, m, world; NaN when fewer); τ (3): the total
    moment of those forces about the world origin (N·m, world); force magnitudes of the
    ``MAX_PATCHES`` strongest contacts (N; NaN when fewer)].
    """

    def __init__(self, built):
        super().__init__()
        plant = built.plant
        gripper = plant.GetModelInstanceByName(GRIPPER)
        arm = plant.GetModelInstanceByName(IIWA)
        objects = {b.index() for b in {**built.free_bodies, **built.welded_bodies}.values()}
        self._kind = {}
        for i in range(plant.num_bodies()):
            body = plant.get_body(BodyIndex(i))
            kind = {gripper: "gripper", arm: "arm"}.get(body.model_instance())
            kind = kind or ("object" if body.index() in objects else "other")
            for gid in plant.GetCollisionGeometriesForBody(body):
                self._kind[gid] = kind
        self._results = self.DeclareAbstractInputPort(
            "contact_results", AbstractValue.Make(ContactResults())
        )
        self.DeclareVectorOutputPort("truth", 8 + 4 * MAX_PATCHES, self._calc)

    def _calc(self, context, output):
        results = self._results.Eval(context)
        total, arm, found = np.zeros(3), 0.0, []
        pairs = []
        for i in range(results.num_hydroelastic_contacts()):
            info = results.hydroelastic_contact_info(i)
            surface = info.contact_surface()
            # F_Ac_W acts on the body of geometry M, at the centroid C, with a moment there.
            pairs.append((surface.id_M(), surface.id_N(), info.F_Ac_W().translational(),
                          np.array(surface.centroid()), info.F_Ac_W().rotational()))  # fmt: skip
        for i in range(results.num_point_pair_contacts()):
            info = results.point_pair_contact_info(i)
            # contact_force() acts on body B.
            pairs.append((info.point_pair().id_B, info.point_pair().id_A, info.contact_force(),
                          np.array(info.contact_point()), np.zeros(3)))  # fmt: skip
        torque = np.zeros(3)
        for on, other, force, point, moment in pairs:
            kinds = (self._kind.get(on), self._kind.get(other))
            if sorted(kinds) == ["arm", "object"]:
                arm = 1.0
            if sorted(kinds) != ["gripper", "object"]:
                continue
            sign = 1.0 if kinds[0] == "gripper" else -1.0
            f_gripper = sign * force
            total += f_gripper
            torque += np.cross(point, f_gripper) + sign * moment
            found.append((np.linalg.norm(f_gripper), point))
        found.sort(key=lambda item: -item[0])
        out = np.full(8 + 4 * MAX_PATCHES, np.nan)
        out[:3], out[3], out[4] = total, len(found), arm
        for k, (norm, point) in enumerate(found[:MAX_PATCHES]):
            out[5 + 3 * k : 8 + 3 * k] = point
            out[8 + 3 * MAX_PATCHES + k] = norm
        out[5 + 3 * MAX_PATCHES : 8 + 3 * MAX_PATCHES] = torque
        output.SetFromVector(out)



def run_scene(objects, actions, finger, *, lock_fingers, cache_dir):
    """Simulates a scene with the sensing chain; returns per-step logs and per-action flags."""
    scene = load_scene_text(scene_text(objects, actions, finger))
    built = build_scene(scene)
    h = float(scene.plant.time_step)
    fingers = np.full(2, finger)
    X_WB = robot_base_pose(scene)
    builder = DiagramBuilder()
    sub = builder.AddSystem(built.diagram)
    iiwa = ObservedRobot(**iiwa_observed_robot_arguments(X_WB, fingers))
    S, T = observed_joint_selectors(iiwa)
    arm_state, arm_torque = builder.AddSystem(MatrixGain(S)), builder.AddSystem(MatrixGain(T))
    builder.Connect(sub.GetOutputPort("robot_state"), arm_state.get_input_port())
    builder.Connect(sub.GetOutputPort("applied_torque"), arm_torque.get_input_port())
    stats = calibrate_residual_statistics(time_step=h, estimator_kwargs={"gain": GAIN},
                                          cache_dir=cache_dir)  # fmt: skip
    estimator = builder.AddSystem(ExternalWrenchEstimator(
        h, iiwa, gain=GAIN,
        residual_statistics=stats,
        sampled_plant_outputs=bool(scene.plant.use_sampled_output_ports),
    ))  # fmt: skip
    builder.Connect(arm_state.get_output_port(), estimator.GetInputPort("state"))
    builder.Connect(arm_torque.get_output_port(), estimator.GetInputPort("applied_torque"))
    detector = builder.AddSystem(ContactDetector(h, default_threshold()))
    for name in ("residual_chi2", "ee_position"):
        builder.Connect(estimator.GetOutputPort(name), detector.GetInputPort(name))
    builder.Connect(sub.GetOutputPort("action_index"), detector.GetInputPort("action_index"))
    pose = builder.AddSystem(GripperPoseFromState(
        ObservedRobot(**iiwa_observed_robot_arguments(X_WB, fingers))))
    builder.Connect(arm_state.get_output_port(), pose.GetInputPort("state"))
    bubbles = builder.AddSystem(BubbleContactSensor(
        built.plant, built.scene_graph, h, bubble_bodies(built.plant)))
    builder.Connect(sub.GetOutputPort("contact_results"), bubbles.GetInputPort("contact_results"))
    builder.Connect(sub.GetOutputPort("body_poses"), bubbles.GetInputPort("body_poses"))
    truth = builder.AddSystem(GripperObjectContacts(built))
    builder.Connect(sub.GetOutputPort("contact_results"), truth.get_input_port())
    logs = {
        "wrench": LogVectorOutput(estimator.GetOutputPort("ee_wrench"), builder, h),
        "in_contact": LogVectorOutput(detector.GetOutputPort("in_contact"), builder, h),
        "truth": LogVectorOutput(truth.get_output_port(), builder, h),
        "action": LogVectorOutput(sub.GetOutputPort("action_index"), builder, h),
    }
    for name, n_bubbles in (("bor", 2), ("cpf", 0)):
        iso = builder.AddSystem(ContactIsolator(h, seed=0, opening=finger, n_bubbles=n_bubbles))
        builder.Connect(estimator.GetOutputPort("ee_wrench"), iso.GetInputPort("ee_wrench"))
        builder.Connect(pose.GetOutputPort("gripper_pose"), iso.GetInputPort("gripper_pose"))
        builder.Connect(detector.GetOutputPort("in_contact"), iso.GetInputPort("in_contact"))
        if n_bubbles:
            for port in ("bubble_in_contact", "bubble_contact_points"):
                builder.Connect(bubbles.GetOutputPort(port), iso.GetInputPort(port))
        for port in ("has_contact", "contact_point", "contact_source", "contact_spread",
                     "contact_ambiguous"):  # fmt: skip
            logs[name, port] = LogVectorOutput(iso.GetOutputPort(port), builder, h)
        if n_bubbles:
            # Every bubble point of the step (both bubbles may fire).
            logs[name, "bubble_points"] = LogVectorOutput(
                bubbles.GetOutputPort("bubble_contact_points"), builder, h
            )
            logs[name, "bubble_flags"] = LogVectorOutput(
                bubbles.GetOutputPort("bubble_in_contact"), builder, h
            )
    simulator = Simulator(builder.Build())
    if lock_fingers:
        plant_context = built.plant.GetMyMutableContextFromRoot(simulator.get_mutable_context())
        for name in ("left_finger_joint", "right_finger_joint"):
            built.plant.GetJointByName(name).Lock(plant_context)
    completed = detector.GetOutputPort("completed_action")
    start, actions_done = time.perf_counter(), []
    for a in range(len(actions)):
        # Half a step past the boundary the detector has closed action a.
        simulator.AdvanceTo((a + 1) * scene.action_duration + 0.5 * h)
        context = detector.GetMyContextFromRoot(simulator.get_context())
        actions_done.append(completed.Eval(context))
    out = {"actions": actions_done, "wall": time.perf_counter() - start}
    for key, logger in logs.items():
        log = logger.FindLog(simulator.get_context())
        out["t"], out[key] = log.sample_times(), log.data().T
    truth_log = out["truth"]
    out["F"], out["n_patches"], out["arm_contact"] = (
        truth_log[:, :3], truth_log[:, 3], truth_log[:, 4]
    )
    out["patches"] = truth_log[:, 5 : 5 + 3 * MAX_PATCHES].reshape(-1, MAX_PATCHES, 3)
    out["torque"] = truth_log[:, 5 + 3 * MAX_PATCHES : 8 + 3 * MAX_PATCHES]
    out["patch_force"] = truth_log[:, 8 + 3 * MAX_PATCHES :]
    out["action_of_step"] = np.round(out["action"][:, 0]).astype(int)
    return out


# ---------------------------------------------------------------------------------- helpers
def force_norm(run) -> np.ndarray:
    return np.linalg.norm(run["F"], axis=1)


def steady_contact(run, window: int = SETTLE_STEPS, tolerance: float = 0.1) -> np.ndarray:
    """Steps whose true force is >= 2 N and stayed within ``tolerance`` (relative) of its
    current value over the last ``window`` steps: the estimator (a first-order filter with a
    20 ms time constant) has settled on it. Sliding objects chatter, so this is mostly the
    hold phase of each push."""
    F, norm = run["F"], force_norm(run)
    steady = np.zeros(len(F), dtype=bool)
    for i in range(window, len(F)):
        if norm[i] >= 2.0:
            drift = np.linalg.norm(F[i - window : i + 1] - F[i], axis=1)
            steady[i] = np.all(drift <= tolerance * norm[i])
    return steady


def settled_contact(run) -> np.ndarray:
    """Steps in contact (true force >= CONTACT_FORCE) for the last SETTLE_STEPS steps."""
    touching = force_norm(run) >= CONTACT_FORCE
    settled = np.zeros_like(touching)
    for i in range(SETTLE_STEPS, len(touching)):
        settled[i] = touching[i - SETTLE_STEPS : i + 1].all()
    return settled


def nearest_patch_error(points, patches) -> np.ndarray:
    """Per step, distance (m) from the point to the nearest true patch centroid."""
    d = np.linalg.norm(points[:, None] - patches, axis=2)
    return np.nanmin(np.where(np.isnan(d), np.inf, d), axis=1)


def in_actions(run, actions) -> np.ndarray:
    return np.isin(run["action_of_step"], actions)
