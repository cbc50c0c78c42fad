"""Grasping at a given target pose, without rummaging (the target at its scene pose).

Each grasp simulates about 10 s; run with ``-s`` to see the lift heights.
"""

from __future__ import annotations

import numpy as np
from pydrake.math import RigidTransform

from stucco_drake.bor.grasp import build_grasp_scene, execute_grasp, geometric_check
from stucco_drake.core.shapes import BoxSdf, CylinderSdf
from stucco_drake.scenes import load_scene
from stucco_drake.scenes.playback import make_simulator
from stucco_drake.systems.grasp_executor import PHASES

# The targets' geometry in their body frames (the scene files' model sizes, m).
CRACKER_BOX = BoxSdf((0.0329, 0.079, 0.1037))
TOMATO_CAN = CylinderSdf(0.0384, 0.06)


def _grasp(name: str, shape, offset=(0.0, 0.0), **kwargs):
    scene = load_scene(name)
    built = build_grasp_scene(scene)
    simulator = make_simulator(built)
    plant_context = built.plant.GetMyContextFromRoot(simulator.get_context())
    X_WO = built.free_bodies[scene.target].EvalPoseInWorld(plant_context)
    pose = RigidTransform(X_WO.rotation(), X_WO.translation() + np.array([*offset, 0.0]))
    result = execute_grasp(built, simulator, pose, shape, **kwargs)
    print(f"\n{name} offset {offset}: success {result.success}, lift "
          f"{result.lift_height * 100:.1f} cm, geometric_ok {result.geometric_ok}, "
          f"{result.wall_time:.0f} s wall; {result.reason}")
    return result


def test_fb_true_pose_lifts_the_box():
    result = _grasp("FB", CRACKER_BOX)
    assert result.success, result.reason
    assert result.lift_height >= 0.05
    assert result.geometric_ok, result.reason


def test_fb_pose_10cm_off_fails():
    result = _grasp("FB", CRACKER_BOX, offset=(0.1, 0.0))
    assert not result.success
    assert result.lift_height < 0.05


def test_tc_true_pose_lifts_the_can():
    # Closing along world y (the start yaw) would put the open fingers' plates on the master
    # chef can and the cracker box beside the target; -0.5 rad clears both.
    result = _grasp("TC", TOMATO_CAN, cylinder_yaws=[-0.5])
    assert result.success, result.reason
    assert result.geometric_ok, result.reason
    assert result.attempts == 1


def test_tc_blocked_descent_tries_the_next_yaw():
    """Along world y the open fingers land on the master chef can and the cracker box, and
    the descent stops short: the executor rises and tries the next axis, 60 deg round, which
    lifts the can. With that one yaw only, the grasp fails."""
    result = _grasp("TC", TOMATO_CAN, cylinder_yaws=[np.pi / 2, np.pi / 2 + np.pi / 3])
    assert result.attempts == 2, result.reason
    assert result.success, result.reason
    assert result.geometric_ok, result.reason
    blocked = _grasp("TC", TOMATO_CAN, cylinder_yaws=[np.pi / 2])
    assert blocked.attempts == 1
    assert not blocked.success


def test_geometric_check_box_and_can():
    def gripper(x, y, yaw):
        from stucco_drake.systems.planar_controller import gripper_rotation
        return RigidTransform(gripper_rotation(yaw), [x, y, 0.15])

    X_WO = RigidTransform([0.0, 0.0, 0.1])
    assert geometric_check(X_WO, gripper(0.0, 0.03, 0.0), CRACKER_BOX)[0]
    assert geometric_check(X_WO, gripper(0.0, 0.0, np.pi), CRACKER_BOX)[0]
    # Closing along the long axis, turned 30 deg, or at the end of the box: corner grasps.
    assert not geometric_check(X_WO, gripper(0.0, 0.0, np.pi / 2), CRACKER_BOX)[0]
    assert not geometric_check(X_WO, gripper(0.0, 0.0, np.pi / 6), CRACKER_BOX)[0]
    assert not geometric_check(X_WO, gripper(0.0, 0.07, 0.0), CRACKER_BOX)[0]
    # The can: pads past its axis (offset 3 cm < 4 cm) or not (5 cm), or it is off to the side.
    assert geometric_check(X_WO, gripper(0.0, 0.03, 0.0), TOMATO_CAN)[0]
    assert not geometric_check(X_WO, gripper(0.0, 0.05, 0.0), TOMATO_CAN)[0]
    assert not geometric_check(X_WO, gripper(0.05, 0.0, 0.0), TOMATO_CAN)[0]


def test_fb_slide_stopped_by_the_box_tries_the_next_approach():
    """The first attempt descends 16 cm beside the box along its closing axis (its short one;
    the open fingers span 20 cm with their plates, so the inner one lands 3 cm clear of the
    long face, 3.3 cm from the centre) and slides to the grasp point, which drives that finger
    into the long face. Guarded, the slide counts as blocked (it trails its reference by more
    than 3 cm) and the next attempt, straight down, lifts the box; given that first approach
    alone, the slide shoves the box over (it ends about 13 cm off and 7 cm lower) and nothing
    is lifted."""
    scene = load_scene("FB")
    built = build_grasp_scene(scene)
    plant_context = built.plant.GetMyContextFromRoot(make_simulator(built).get_context())
    X_WO = built.free_bodies[scene.target].EvalPoseInWorld(plant_context)
    across = X_WO.rotation().matrix()[:2, 0]  # the box's short axis in the world's plane
    beside = 0.16 * across / np.linalg.norm(across)
    guarded = _grasp("FB", CRACKER_BOX, approach_offsets=[beside, (0.0, 0.0)])
    assert guarded.attempts == 2, guarded.reason
    assert guarded.success, guarded.reason
    alone = _grasp("FB", CRACKER_BOX, approach_offsets=[beside])
    assert alone.attempts == 1
    assert not alone.success, alone.reason
    start = X_WO.translation()
    assert np.hypot(*(alone.final_pose[:2] - start[:2])) > 0.10  # shoved 13.7 cm
    assert alone.final_pose[2] < start[2] - 0.05  # and knocked over: 7.1 cm lower


def test_a_blocked_last_attempt_withdraws_without_moving_anything():
    """The shove of the test above, given ``withdraw_when_blocked``: the slide is blocked as
    before, the gripper rises to the 0.30 m safe height with its fingers open, and every
    object stays within 5 mm of where the scene put it (the potted meat can is nudged 2 mm;
    pressing on, the box ends 13.7 cm off and the potted meat can 11 cm)."""
    scene = load_scene("FB")
    built = build_grasp_scene(scene)
    simulator = make_simulator(built)
    plant_context = built.plant.GetMyContextFromRoot(simulator.get_context())
    start = {name: body.EvalPoseInWorld(plant_context).translation().copy()
             for name, body in built.free_bodies.items()}
    X_WO = built.free_bodies[scene.target].EvalPoseInWorld(plant_context)
    across = X_WO.rotation().matrix()[:2, 0]
    result = execute_grasp(built, simulator, X_WO, CRACKER_BOX, withdraw_when_blocked=True,
                           approach_offsets=[0.16 * across / np.linalg.norm(across)])
    assert result.withdrew and result.attempts == 1 and not result.success, result.reason
    plant_context = built.plant.GetMyContextFromRoot(simulator.get_context())
    for name, body in built.free_bodies.items():
        moved = np.linalg.norm(body.EvalPoseInWorld(plant_context).translation() - start[name])
        assert moved < 0.005, (name, moved)
    assert built.gripper_frame().CalcPoseInWorld(plant_context).translation()[2] > 0.29
    executor = built.diagram.GetSubsystemByName("grasp_executor")
    phase = executor.GetOutputPort("grasp_phase").Eval(
        executor.GetMyContextFromRoot(simulator.get_context()))
    assert phase[0] == len(PHASES)  # done


def test_an_end_descent_shifted_sideways_moves_back_in_line_before_sliding():
    """FB's box (long axis along world y): an end approach 13.9 cm beyond its +y end, the
    descent shifted 5 cm to -x. The slide first moves back in line, then along, and the box
    is lifted at the first attempt. Sliding straight from the shifted point instead, a finger
    (its bubble 2.2 cm clear of the long face when in line) would still be 4.3 cm off line
    where its pad reaches the box's end: it meets the end face, and nothing is lifted."""
    scene = load_scene("FB")
    built = build_grasp_scene(scene)
    plant_context = built.plant.GetMyContextFromRoot(make_simulator(built).get_context())
    rotation = built.free_bodies[scene.target].EvalPoseInWorld(plant_context).rotation()
    along, across = rotation.matrix()[:2, 1], rotation.matrix()[:2, 0]
    end, shift = 0.139 * along / np.linalg.norm(along), -0.05 * across / np.linalg.norm(across)
    shifted = _grasp("FB", CRACKER_BOX, approach_offsets=[end], side_shifts=[shift])
    assert shifted.success and shifted.attempts == 1, shifted.reason
    diagonal = _grasp("FB", CRACKER_BOX, approach_offsets=[end + shift])
    assert not diagonal.success, diagonal.reason


def test_only_a_target_the_push_limit_cannot_slide_is_held_still():
    """By the models' masses and friction (``models/ycb``) and the scenes' 30 N push limit: BC's
    10 kg box needs 0.5 * 10 * 9.81 = 49 N to slide, TC's 2 kg can 9.8 N."""
    from stucco_drake.bor.diagram import build_bor_diagram, target_motion_scales, target_slide
    from stucco_drake.core.hypothesis_params import HypothesisParams
    from stucco_drake.core.motion_scale import MOTION_SCALES

    still = HypothesisParams(still_when_unslidable=True)
    box, can = (build_grasp_scene(load_scene(name)) for name in ("BC", "TC"))
    assert target_slide(can) == {"mass": 2.0, "friction": 0.5, "max_push_force": 30.0}
    assert target_motion_scales(box, still) == (0.0,)
    assert target_motion_scales(can, still) == MOTION_SCALES
    assert target_motion_scales(box) == MOTION_SCALES
    live = build_bor_diagram(load_scene("BC"), "stucco", 0, hypothesis_params=still)
    assert live.target_estimator.motion_scales == (0.0,)
