"""Tests for the scene files (diagrams/*.yaml), the scene builder and the planar controller.

Numbers: a free-space step must reach its planar goal within 2 mm while the gripper's height
stays within 2 mm and its yaw within 1 degree; a push must move a box by the step minus the
initial gap (within 5 mm); untouched objects must not creep. Units: m, rad, s.
"""

import math

import numpy as np
import pytest
from pydrake.math import RollPitchYaw

from stucco_drake.core import SoftTrackingParams
from stucco_drake.scenes import (
    DIAGRAMS_DIR,
    SceneFileError,
    build_scene,
    load_scene,
    load_scene_text,
)
from stucco_drake.scenes.builder import IIWA, _joint_gains
from stucco_drake.scenes.playback import make_simulator, play, record

# Action counts of the paper's sequences; the training scenes carry a 10-action smoke push.
SCENES = {"FB": 54, "BC": 102, "IB": 44, "TC": 40,
          "SELECT1": 10, "SELECT2": 10, "SELECT3": 10, "SELECT4": 10}

TABLE = """
directives:
- add_model:
    name: table
    file: package://stucco_drake_models/table.sdf
- add_weld:
    parent: world
    child: table::base_link
"""


def _scene_text(body: str, *, start=(0.15, 0.0), actions=()) -> str:
    """A small scene: the table, the robot at its default base, and ``body`` (YAML)."""
    lines = "\n" + "".join(f"  - [{a}, {b}]\n" for a, b in actions) if actions else " []\n"
    return (f"name: test\ngripper_start:\n  xy: [{start[0]}, {start[1]}]\n  height: 0.1\n"
            f"plant:\n  time_step: 0.002\n  discrete_contact_approximation: sap\n"
            f"  contact_model: hydroelastic_with_fallback\n"
            f"{TABLE}{body}actions:{lines}")


@pytest.mark.parametrize("name", sorted(SCENES))
def test_scene_file_loads_and_builds(name):
    scene = load_scene(name)
    assert scene.name == name
    assert len(scene.actions) == SCENES[name]
    assert isinstance(scene.tracker_params(), SoftTrackingParams)
    assert scene.plant.discrete_contact_approximation == "sap"
    built = build_scene(scene)
    assert built.plant.time_step() == scene.plant.time_step > 0
    assert built.free_bodies, "every scene has movable objects"
    # No two objects start interpenetrating (the table is what they rest on).
    context = built.diagram.CreateDefaultContext()
    query = built.diagram.GetOutputPort("query_object").Eval(context)
    inspector = query.inspector()
    for pair in query.ComputeSignedDistancePairwiseClosestPoints(0.0):
        names = [inspector.GetName(inspector.GetFrameId(g)) for g in (pair.id_A, pair.id_B)]
        if not any(n.startswith("table::") for n in names):
            assert pair.distance > 0, f"{names} overlap by {-pair.distance * 1000:.1f} mm"
    for port in ("robot_state", "applied_torque", "commanded_torque", "desired_state",
                 "planar_goal",
                 "plant_state", "contact_results", "query_object", "action_index"):
        assert built.diagram.HasOutputPort(port)
    assert built.diagram.GetOutputPort("applied_torque").size() == (
        built.robot_plant.num_velocities()
    )


@pytest.mark.parametrize("name", ["FB", "BC", "IB", "TC"])
def test_paper_paths_stay_within_workspace_and_reach(name):
    # The unobstructed path of the prescribed actions (a blocked gripper falls short of it).
    scene = load_scene(name)
    steps = np.clip(scene.actions, -1, 1) * scene.control.max_step
    path = np.array(scene.gripper_start.xy) + np.cumsum(steps, axis=0)
    outside = [tuple(p.round(3)) for p in path if not scene.in_workspace(p)]
    assert not outside


@pytest.mark.parametrize("name", sorted(SCENES))
def test_scene_plays_its_first_actions(name):
    scene = load_scene(name)
    built = build_scene(scene)
    records, _ = play(built, 2)
    assert [r.index for r in records] == [-1, 0, 1]
    height = scene.gripper_start.height
    for rec in records:
        assert abs(rec.gripper_xyz[2] - height) < 0.002
    # The first action starts from the start position and is the paper's clipped, scaled step.
    step = np.clip(scene.actions[0], -1, 1) * scene.control.max_step
    np.testing.assert_allclose(records[1].goal_xy, np.array(scene.gripper_start.xy) + step,
                               atol=1e-6)
    for name_, pose in records[-1].objects.items():  # nothing toppled or was flung
        assert abs(pose[2] - records[0].objects[name_][2]) < 0.005, name_


def test_free_space_steps_reach_their_goals():
    # Steps along x, diagonal, a clipped one (u = 2 -> 0.03 m) and a fractional one.
    actions = [(1, 0), (-1, 1), (0, -2), (0.3, -0.6)]
    built = build_scene(load_scene_text(_scene_text("", actions=actions)))
    records, _ = play(built)
    yaw0 = records[0].gripper_yaw
    for prev, rec, u in zip(records[:-1], records[1:], actions, strict=True):
        step = np.clip(u, -1, 1) * 0.03
        # Each step starts from the measured position at the end of the previous action.
        np.testing.assert_allclose(rec.goal_xy, prev.gripper_xyz[:2] + step, atol=1e-6)
        assert np.linalg.norm(rec.gripper_xyz[:2] - rec.goal_xy) < 0.002
        assert abs(rec.gripper_xyz[2] - 0.1) < 0.002
        assert abs(math.remainder(rec.gripper_yaw - yaw0, 2 * math.pi)) < math.radians(1)
    assert abs(yaw0 - math.pi / 2) < 1e-6


def test_objects_rest_still_when_untouched():
    scene = load_scene("FB")
    scene.actions = []  # the gripper holds its start pose, 0.07 m from the nearest object
    built = build_scene(scene)
    simulator = make_simulator(built)
    before = record(built, simulator, -1)
    simulator.AdvanceTo(1.0)
    after = record(built, simulator, 0)
    for name, pose in before.objects.items():
        assert np.linalg.norm(after.objects[name][:3] - pose[:3]) < 1e-4, name
        assert abs(after.objects[name][3] - pose[3]) < math.radians(0.05), name


def _max_target_tilt(scene, n_actions: int) -> float:
    """The target's largest roll or pitch (deg) over the scene's first n actions, every 20 ms."""
    scene.actions = scene.actions[:n_actions]
    built = build_scene(scene)
    simulator = make_simulator(built)
    plant_context = built.plant.GetMyContextFromRoot(simulator.get_context())
    body = built.free_bodies[scene.target]
    tilt = 0.0
    for t in np.arange(0.02, n_actions * scene.action_duration + 1e-9, 0.02):
        simulator.AdvanceTo(t)
        rpy = RollPitchYaw(body.EvalPoseInWorld(plant_context).rotation()).vector()
        tilt = max(tilt, math.degrees(max(abs(rpy[0]), abs(rpy[1]))))
    return tilt


def test_compliant_arm_keeps_fbs_heavy_box_upright():
    # FB's fifth action is its first full push into the 10 kg box (0.066 m deep, so 21 N at
    # the plates' top edge tips it). FB's stiff arm (kp 2500) strikes it at 60-90 N despite
    # the 30 N push cap and tips it 3.6 deg; a compliant arm (kp 400 on the arm's joints, the
    # fingers unchanged) presses it gradually: 1.1 deg.
    stiff = _max_target_tilt(load_scene("FB"), 5)
    compliant_scene = load_scene("FB")
    compliant_scene.control.kp, compliant_scene.control.kd = 400.0, 40.0
    compliant_scene.control.ki = 0.0
    compliant = _max_target_tilt(compliant_scene, 5)
    assert stiff > 3.0, stiff
    assert compliant < 1.5, compliant


def test_arm_and_finger_gains_are_set_apart():
    scene = load_scene_text(_scene_text(""))
    scene.control.kp, scene.control.finger_kp, scene.control.finger_kd = 400.0, 2000.0, 90.0
    built = build_scene(scene)
    arm = built.robot_plant.GetModelInstanceByName(IIWA)
    kp, ki, kd = _joint_gains(built.robot_plant, arm, scene.control)
    assert len(kp) == built.robot_plant.num_velocities() == 9  # 7 arm joints, 2 fingers
    np.testing.assert_array_equal(kp, [400.0] * 7 + [2000.0] * 2)
    np.testing.assert_array_equal(kd, [100.0] * 7 + [90.0] * 2)
    np.testing.assert_array_equal(ki, [10.0] * 9)


def test_applied_torque_balances_gravity_when_holding_still():
    # What a wrench estimator relies on: at rest and free of contact, the exported torque is
    # the robot's gravity torque, in the robot-only plant's ordering.
    built = build_scene(load_scene_text(_scene_text("")))
    simulator = make_simulator(built)
    simulator.AdvanceTo(0.3)
    context = simulator.get_context()
    x = built.diagram.GetOutputPort("robot_state").Eval(context)
    tau = built.diagram.GetOutputPort("applied_torque").Eval(context)
    robot_context = built.robot_plant.CreateDefaultContext()
    built.robot_plant.SetPositionsAndVelocities(robot_context, x)
    tau_g = -built.robot_plant.CalcGravityGeneralizedForces(robot_context)
    assert np.abs(tau_g).max() > 10  # the arm does carry its weight
    np.testing.assert_allclose(tau, tau_g, atol=0.2)
    np.testing.assert_allclose(x[:built.robot_plant.num_positions()], built.q_start, atol=1e-3)


PUSH_SCENE = """primitives:
- name: box
  shape: box
  size: [0.06, 0.12, 0.1]
  xyz: [0.23, 0.0, 0.05]
  mass: 0.3
  friction: 0.5
- name: wall
  shape: box
  size: [0.1, 0.4, 0.2]
  xyz: [0.335, 0.0, 0.1]
  welded: true
"""


def _gap_along_x(built, a: str, b: str) -> float:
    """Smallest signed distance (m) between any geometry of model ``a`` and of model ``b``."""
    context = built.diagram.CreateDefaultContext()
    query = built.diagram.GetOutputPort("query_object").Eval(context)
    inspector = query.inspector()
    gaps = []
    for pair in query.ComputeSignedDistancePairwiseClosestPoints(0.2):
        names = {inspector.GetName(inspector.GetFrameId(g)).split("::")[0]
                 for g in (pair.id_A, pair.id_B)}
        if names == {a, b}:
            gaps.append(pair.distance)
    return min(gaps)


def test_push_moves_box_by_step_minus_gap_and_wall_holds():
    # The gripper (0.04 m half-width along x) starts 0.01 m short of the box; the box is
    # 0.025 m short of a welded wall. Two full steps along +x.
    built = build_scene(load_scene_text(_scene_text(PUSH_SCENE, actions=[(1, 0), (1, 0)])))
    gap = _gap_along_x(built, "bubble_gripper", "box")
    wall_gap = _gap_along_x(built, "box", "wall")
    assert 0.005 < gap < 0.02 and 0.02 < wall_gap < 0.03
    records, _ = play(built)
    x0 = records[0].objects["box"][0]
    first_push = records[1].objects["box"][0] - x0
    assert abs(first_push - (0.03 - gap)) < 0.005, (first_push, gap)
    # The second step would push the box 0.03 m further, but the welded wall stops it.
    total = records[2].objects["box"][0] - x0
    assert total < wall_gap + 0.001
    assert total > wall_gap - 0.005
    X_wall = built.welded_bodies["wall"].EvalPoseInWorld(built.plant.CreateDefaultContext())
    np.testing.assert_allclose(X_wall.translation(), [0.335, 0.0, 0.1], atol=1e-12)


def test_friction_override_reaches_the_contact_solver():
    # A box pushed on a frictionless table keeps sliding after the push stops; with the files'
    # friction (table 0.6, box 0.5: combined 0.55) it stops with the gripper.
    box_only = PUSH_SCENE.split("- name: wall")[0]
    moved = {}
    for label, friction in (("files", ""), ("frictionless", "friction:\n  table: 0.0\n")):
        scene = load_scene_text(_scene_text(box_only + friction, actions=[(1, 0), (0, 0)]))
        records, _ = play(build_scene(scene))
        moved[label] = [r.objects["box"][0] - records[0].objects["box"][0] for r in records[1:]]
    still, sliding = moved["files"], moved["frictionless"]
    assert abs(still[1] - still[0]) < 0.001, still  # at rest after the push
    assert sliding[1] - sliding[0] > 0.005, sliding  # still sliding a whole action later
    with pytest.raises(SceneFileError, match=r"friction\.shelf: the scene has no model 'shelf'"):
        build_scene(load_scene_text(_scene_text(box_only + "friction:\n  shelf: 0.2\n")))


@pytest.mark.parametrize(
    "patch, key",
    [
        ("name: FB\nbogus: 1\n", "bogus"),
        ("gripper_start:\n  heigth: 0.1\n", "gripper_start.heigth"),
        ("actions:\n  - [1, 0]\n  - [1, x]\n", "actions[1][1]"),
        ("directives:\n- add_model:\n    name: a\n    fil: b.sdf\n", "directives[0].add_model.fil"),
        ("plant:\n  time_step: fast\n", "plant.time_step"),
        ("plant:\n  time_step: 0.002\n  contact_model: hydro\n", "plant.contact_model"),
        ("tracker:\n  lenght: 0.02\n", "tracker"),
        ("target: nothing\n", "target"),
        ("actions:\n  - [1, 0, 3]\n", "actions[0]"),
        ("friction:\n  table: -0.1\n", "friction.table"),
        ("control:\n  kp: -1.0\n", "control.kp"),
        ("control:\n  finger_ki: -1.0\n", "control.finger_ki"),
        ("sensor_noise:\n  torque_std: -0.5\n", "sensor_noise.torque_std"),
        ("sensor_noise:\n  bubble_std: 0.002\n", "sensor_noise.bubble_std"),
    ],
)
def test_malformed_scene_file_fails_with_one_line(tmp_path, patch, key):
    text = (DIAGRAMS_DIR / "FB.yaml").read_text()
    top = patch.split(":")[0]
    # Replace the top-level entry `top` (up to the next top-level key) with the patch.
    lines, out, skipping = text.splitlines(keepends=True), [], False
    for line in lines:
        starts_key = line[:1].isalpha()
        if starts_key:
            skipping = line.startswith(f"{top}:")
        if not skipping:
            out.append(line)
    path = tmp_path / "bad.yaml"
    path.write_text("".join(out) + patch)
    with pytest.raises(SceneFileError) as info:
        load_scene(path)
    message = str(info.value)
    assert "\n" not in message
    assert message.startswith(f"{path}: {key}: "), message


def test_scene_names_resolve_to_diagrams_and_missing_files_fail():
    assert load_scene(DIAGRAMS_DIR / "TC.yaml").name == "TC"
    with pytest.raises(SceneFileError, match=r"nope\.yaml"):
        load_scene("nope")


@pytest.mark.parametrize("command", ["sim", "run"])
def test_cli_reports_a_bad_scene_in_one_line(command, capsys):
    from stucco_drake.cli import main

    assert main([command, "--scene", "no_such_scene"]) == 2
    error = capsys.readouterr().err.strip()
    assert "no_such_scene.yaml" in error and "\n" not in error


WALL_AHEAD = """primitives:
- name: wall
  shape: box
  size: [0.1, 0.4, 0.2]
  xyz: [0.25, 0.0, 0.1]
  welded: true
"""


def _wall_force(built, context) -> float:
    """x component (N) of the contact force the robot puts on the welded wall."""
    results = built.diagram.GetOutputPort("contact_results").Eval(context)
    inspector = built.diagram.GetOutputPort("query_object").Eval(context).inspector()

    def on_wall(geometry) -> bool:
        return inspector.GetName(inspector.GetFrameId(geometry)).startswith("wall::")

    force = 0.0
    for i in range(results.num_hydroelastic_contacts()):
        info = results.hydroelastic_contact_info(i)
        surface = info.contact_surface()
        sign = 1.0 if on_wall(surface.id_N()) else -1.0 if on_wall(surface.id_M()) else 0.0
        # The spatial force acts on the body of geometry M, at the surface's centroid.
        force -= sign * info.F_Ac_W().translational()[0]
    for i in range(results.num_point_pair_contacts()):
        info = results.point_pair_contact_info(i)
        pair = info.point_pair()
        sign = 1.0 if on_wall(pair.id_B) else -1.0 if on_wall(pair.id_A) else 0.0
        force += sign * info.contact_force()[0]  # the force on body B
    return force


@pytest.mark.parametrize("cap", [None, 30.0])
def test_push_force_cap_holds_a_blocked_gripper_back(cap):
    # The gripper starts 1 cm short of a welded wall and is sent 5 cm into it: capped, it
    # presses with about the cap (the paper's gripper: at most 30 N); uncapped, with whatever
    # the joint controller's position error gives, several times more.
    control = "" if cap is None else f"control:\n  max_push_force: {cap}\n"
    scene = load_scene_text(_scene_text(WALL_AHEAD + control, start=(0.15, 0.0),
                                        actions=[(1, 0), (1, 0)]))
    built = build_scene(scene)
    simulator = make_simulator(built)
    forces = []
    for k in (1, 2):
        simulator.AdvanceTo(k * scene.action_duration)
        forces.append(_wall_force(built, simulator.get_context()))
    if cap is None:
        assert min(forces) > 2.5 * 30.0, forces
    else:
        assert all(0.6 * cap < f < 1.2 * cap for f in forces), forces


def test_object_pushed_off_the_table_is_still_an_object():
    """A free object counts wherever it is (a training trial once pushed one off the table,
    and the log's per-object records then lost it); the table itself never counts."""
    from pydrake.math import RigidTransform

    from stucco_drake.bor.diagram import object_surfaces

    built = build_scene(load_scene("SELECT3"))
    context = built.diagram.CreateDefaultContext()
    plant_context = built.plant.GetMyContextFromRoot(context)
    before = object_surfaces(built, plant_context)
    assert set(built.free_bodies) <= set(before) and "table" not in before
    body = built.free_bodies["heavy_cylinder"]
    built.plant.SetFreeBodyPose(plant_context, body, RigidTransform([1.5, -1.0, -0.6]))
    after = object_surfaces(built, plant_context)
    assert list(after) == list(before)
    # Its surface moved with it: the body's new centre lies inside it, 7.5 cm deep.
    assert after["heavy_cylinder"][0]([[1.5, -1.0, -0.6]])[0] == pytest.approx(-0.075, abs=1e-9)
