"""What chooses the BOR Diagram's actions besides a scene's prescribed script.

- :class:`~stucco_drake.core.probe_params.ProbeParams`: the prescribed actions, then guarded probes
  where the target's pose hypotheses disagree, then of its likeliest pose (``--policy probe``).
- :class:`~stucco_drake.core.rummage_params.RummageParams`: rummaging chosen from the belief from
  the first action, stopping once the target is known (``--policy belief``).
- :class:`~stucco_drake.core.coverage.CoverageParams`: no policy, the non-adaptive baseline:
  the scene with its actions replaced by the coverage sweep's raster (``--policy sweep``).

The first two add a :class:`~stucco_drake.systems.rummaging_policy.RummagingPolicy` to the
Diagram (:func:`add_policy`); the third changes the scene (:func:`coverage_scene`).
"""

from __future__ import annotations

import dataclasses

import numpy as np
from pydrake.systems.framework import DiagramBuilder

from stucco_drake.bor.grasp import build_grasp_scene
from stucco_drake.core.coverage import CoverageParams, coverage_waypoints, waypoint_steps
from stucco_drake.core.penetration import RobotPenetration
from stucco_drake.core.probe_params import ProbeParams
from stucco_drake.core.probe_paths import gripper_footprint
from stucco_drake.core.probing import FaceProbePolicy
from stucco_drake.core.rummage_params import RummageParams
from stucco_drake.core.rummaging import BeliefRummagingPolicy
from stucco_drake.robot.gripper_sdf import gripper_penetration
from stucco_drake.scenes import BuiltScene, SceneFile
from stucco_drake.systems.rummaging_policy import RummagingPolicy

#: Settings of a policy in the Diagram.
PolicySettings = ProbeParams | RummageParams


def footprint(built: BuiltScene, penetration: RobotPenetration) -> np.ndarray:
    """(m, 2) the gripper's planar footprint about its frame's origin in world axes (m), at
    its start pose: the gripper's yaw is held for the whole episode."""
    frame = built.gripper_frame()
    R_WE = frame.CalcPoseInWorld(built.plant.CreateDefaultContext()).rotation().matrix()
    return gripper_footprint(penetration, R_WE)


def add_policy(builder: DiagramBuilder, sub, built: BuiltScene, chain, settings: PolicySettings,
               penetration: RobotPenetration, target_shape) -> RummagingPolicy:  # fmt: skip
    """The policy of ``settings`` in the Diagram, fed by the scene's body poses (``sub``'s
    ``body_poses``), the detector's verdict, the pose hypotheses and the formed contacts
    (``chain``'s); its step
    drives ``sub``'s ``planar_step``, and the Diagram exports its ``policy_done``."""
    scene = built.scene
    max_step = float(scene.control.max_step)
    shape_xy = footprint(built, penetration)
    if isinstance(settings, ProbeParams):
        prescribed = scene.planar_steps()
        core = FaceProbePolicy(target_shape, shape_xy, max_step, settings,
                               in_workspace=scene.in_workspace)
    elif isinstance(settings, RummageParams):
        prescribed = np.zeros((0, 2))
        target_mass = built.free_bodies[scene.target].default_mass()  # known with its model
        core = BeliefRummagingPolicy(target_shape, shape_xy, max_step, scene.gripper_start.xy,
                                     settings, in_workspace=scene.in_workspace,
                                     target_mass=target_mass)
    else:
        raise TypeError(f"no policy for settings of type {type(settings).__name__}")
    policy = builder.AddNamedSystem("rummaging_policy", RummagingPolicy(
        prescribed, scene.action_duration, built.gripper_frame(), core))
    builder.Connect(sub.GetOutputPort("body_poses"), policy.GetInputPort("body_poses"))
    builder.Connect(chain.detector.GetOutputPort("current_action"),
                    policy.GetInputPort("current_action"))
    builder.Connect(chain.target_estimator.GetOutputPort("pose_hypotheses"),
                    policy.GetInputPort("pose_hypotheses"))
    builder.Connect(chain.assembler.GetOutputPort("action_contacts"),
                    policy.GetInputPort("action_contacts"))
    builder.Connect(policy.GetOutputPort("planar_step"), sub.GetInputPort("planar_step"))
    builder.ExportOutput(policy.GetOutputPort("policy_done"), "policy_done")
    return policy


def coverage_scene(scene: SceneFile, params: CoverageParams | None = None) -> SceneFile:
    """``scene`` with its actions replaced by the coverage sweep's raster
    (:func:`~stucco_drake.core.coverage.coverage_waypoints`): lanes one gripper footprint
    wide, pushed as deep as the workspace allows, from the gripper's start."""
    penetration = gripper_penetration(opening=scene.gripper_start.finger_position)
    shape_xy = footprint(build_grasp_scene(scene), penetration)
    width = float(np.ptp(shape_xy[:, 1]))
    points = coverage_waypoints(scene.gripper_start.xy, params or CoverageParams(), width,
                                scene.in_workspace)
    steps = waypoint_steps(scene.gripper_start.xy, points, float(scene.control.max_step))
    return dataclasses.replace(scene, actions=(steps / scene.control.max_step).tolist())


def policy_info(policy: RummagingPolicy, context, prescribed: int) -> dict:
    """What the policy did, for an episode log's ``info["policy"]``: its name, the actions
    prescribed and its own, and its counters."""
    core = policy.policy_state(context).policy
    if isinstance(core, FaceProbePolicy):
        return {"name": "probe", "prescribed_actions": prescribed, "probe_actions": core.actions,
                "touches": core.touches, "probes": core.probes_done, "bumps": core.bumps,
                "probe_phases": dict(sorted(core.phase_actions.items()))}
    return {"name": "belief", "actions": core.actions, "rounds": core.rounds,
            "touches": core.touches, "contacts": core.contacts, "bumps": core.bumps,
            "shoves": core.shoves, "confidence": core.confidence,
            "action_kinds": dict(sorted(core.action_kinds.items())),
            "probe_phases": dict(sorted(core.probe_phases.items())),
            "confidence_trace": [[int(k), float(c)] for k, c in core.trace]}
