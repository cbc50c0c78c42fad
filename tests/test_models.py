"""Tests for the model files under models/ and for stucco_drake.robot.models.

Offline by construction: every Parser goes through ``dut.configure_parser``, which drops Drake's
download-only ``drake_models`` package, so a stray reference to it fails at once (tested below).
This module does not set ``DRAKE_ALLOW_NETWORK``: with the pip wheel of Drake, a value that
leaves out ``package_map`` (such as ``meshcat``) makes every ``Parser()`` construction raise.

The expected numbers are written out here from the published sources, not read from the files.
"""

import time
from itertools import product

import numpy as np
import pytest
from pydrake.geometry import Box, Cylinder, Ellipsoid
from pydrake.math import RigidTransform, RollPitchYaw
from pydrake.multibody.parsing import Parser
from pydrake.multibody.plant import AddMultibodyPlant, MultibodyPlantConfig
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder

from stucco_drake.robot import models as dut

PLANT_CONFIG = dict(
    time_step=1e-3,
    discrete_contact_approximation="sap",
    contact_model="hydroelastic_with_fallback",
)

# Published iiwa14 numbers: link masses [kg] for iiwa_link_0..7, joint effort [N m] and velocity
# [rad/s] limits for joints 1..7, and the kinematic offsets along the arm at q = 0 [m].
IIWA_LINK_MASSES = [5.0, 5.76, 6.35, 3.5, 3.5, 3.5, 1.8, 1.2]
IIWA_EFFORT = [320, 320, 176, 176, 110, 40, 40]
IIWA_VELOCITY = [
    1.4835298641951802,
    1.4835298641951802,
    1.7453292519943295,
    1.3089969389957472,
    2.2689280275926285,
    2.356194490192345,
    2.356194490192345,
]
IIWA_POS_LIMIT = [
    2.96705972839,
    2.09439510239,
    2.96705972839,
    2.09439510239,
    2.96705972839,
    2.09439510239,
    3.05432619099,
]
FLANGE_HEIGHT = 0.1575 + 0.2025 + 0.2045 + 0.2155 + 0.1845 + 0.2155 + 0.081 + 0.045  # 1.306
HOME_Q = [0.0, 0.6, 0.0, -1.6, 0.0, 0.9, 0.0]

# YCB objects: (mass [kg], bounding box x, y, z [m]) with the object standing upright, x along
# its thinnest side. Base values are the YCB set's published ones; variants scale the size by s
# and the mass by s^3 (constant density) unless the STUCCO paper sets the mass.
_YCB_BASE = {
    "002_master_chef_can": (0.414, (0.102, 0.102, 0.140)),
    "003_cracker_box": (0.411, (0.0658, 0.158, 0.2074)),
    "004_sugar_box": (0.514, (0.0391, 0.09, 0.1703)),
    "005_tomato_soup_can": (0.349, (0.064, 0.064, 0.100)),
    "006_mustard_bottle": (0.435, (0.058, 0.095, 0.190)),
    "009_gelatin_box": (0.097, (0.026, 0.087, 0.070)),
    "010_potted_meat_can": (0.370, (0.0526, 0.095, 0.082)),
}
_YCB_VARIANTS = {  # file stem: (base, scale, mass set by the paper or None)
    "003_cracker_box_10kg": ("003_cracker_box", 1.0, 10.0),
    "005_tomato_soup_can_x1_2": ("005_tomato_soup_can", 1.2, None),
    "005_tomato_soup_can_x1_2_2kg": ("005_tomato_soup_can", 1.2, 2.0),
    "005_tomato_soup_can_x2": ("005_tomato_soup_can", 2.0, None),
    "002_master_chef_can_x2": ("002_master_chef_can", 2.0, None),
    "010_potted_meat_can_x1_5": ("010_potted_meat_can", 1.5, None),
    # The paper's simulator scaled geometry, not mass: the retrieval scenes' light clutter.
    "005_tomato_soup_can_x2_light": ("005_tomato_soup_can", 2.0, 0.349),
    "002_master_chef_can_x2_light": ("002_master_chef_can", 2.0, 0.414),
    "010_potted_meat_can_x1_5_light": ("010_potted_meat_can", 1.5, 0.37),
}
YCB_EXPECTED = dict(_YCB_BASE)
for _stem, (_base, _s, _mass) in _YCB_VARIANTS.items():
    _m0, _dims0 = _YCB_BASE[_base]
    YCB_EXPECTED[_stem] = (_m0 * _s**3 if _mass is None else _mass, tuple(_s * d for d in _dims0))

ALL_MODEL_FILES = sorted(
    p.relative_to(dut.MODELS_DIR).as_posix()
    for p in dut.MODELS_DIR.rglob("*")
    if p.suffix in (".sdf", ".urdf")
)


def _make_plant(**config_overrides):
    builder = DiagramBuilder()
    plant, scene_graph = AddMultibodyPlant(
        MultibodyPlantConfig(**{**PLANT_CONFIG, **config_overrides}), builder
    )
    parser = dut.configure_parser(Parser(plant))
    return builder, plant, scene_graph, parser


def _body_aabb(plant, scene_graph, body):
    """Axis-aligned bounds (lo, hi) in the body frame of the body's proximity geometries."""
    inspector = scene_graph.model_inspector()
    corners = []
    for gid in plant.GetCollisionGeometriesForBody(body):
        shape = inspector.GetShape(gid)
        if isinstance(shape, Box):
            half = np.array([shape.width(), shape.depth(), shape.height()]) / 2
        elif isinstance(shape, Cylinder):
            half = np.array([shape.radius(), shape.radius(), shape.length() / 2])
        elif isinstance(shape, Ellipsoid):
            half = np.array([shape.a(), shape.b(), shape.c()])
        else:
            raise AssertionError(f"unexpected shape {type(shape).__name__}")
        X_BG = inspector.GetPoseInFrame(gid)
        for signs in product((-1, 1), repeat=3):
            corners.append(X_BG @ (half * np.array(signs)))
    corners = np.array(corners)
    return corners.min(axis=0), corners.max(axis=0)


def _arm_with_gripper(**config_overrides):
    builder, plant, scene_graph, parser = _make_plant(**config_overrides)
    iiwa, gripper = dut.add_iiwa14_with_bubble_gripper(parser)
    plant.WeldFrames(plant.world_frame(), plant.GetFrameByName("iiwa_link_0", iiwa))
    plant.Finalize()
    return builder, plant, scene_graph, iiwa, gripper


# ------------------------------------------------------------------------------------- package


def test_models_dir_and_urls():
    assert (dut.MODELS_DIR / "package.xml").is_file()
    assert dut.model_url("ycb/003_cracker_box.sdf") == (
        "package://stucco_drake_models/ycb/003_cracker_box.sdf"
    )
    with pytest.raises(FileNotFoundError):
        dut.model_url("ycb/no_such_object.sdf")
    with pytest.raises(ValueError):
        dut.model_url("../pyproject.toml")


def test_configure_parser_registers_package_once_and_blocks_drake_models():
    parser = _make_plant()[3]
    dut.configure_parser(parser)  # idempotent
    package_map = parser.package_map()
    assert package_map.GetPath(dut.PACKAGE_NAME) == str(dut.MODELS_DIR)
    assert not package_map.Contains("drake_models")
    start = time.perf_counter()
    with pytest.raises(RuntimeError, match="unknown package 'drake_models'"):
        parser.AddModels(url="package://drake_models/ycb/sdf/003_cracker_box.sdf")
    assert time.perf_counter() - start < 0.1  # no download attempt


@pytest.mark.parametrize("relative", ALL_MODEL_FILES)
def test_every_model_file_parses(relative):
    builder, plant, scene_graph, parser = _make_plant()
    instances = parser.AddModels(url=dut.model_url(relative))
    assert instances
    plant.Finalize()
    diagram = builder.Build()
    diagram.CreateDefaultContext()
    assert scene_graph.model_inspector().num_geometries() > 0


def test_model_list_is_complete():
    expected = {
        "iiwa14/iiwa14.urdf",
        "bubble_gripper/bubble_gripper.sdf",
        "scara_probe/scara_probe.urdf",
        "table.sdf",
        "wall.sdf",
    } | {f"ycb/{stem}.sdf" for stem in YCB_EXPECTED}
    assert set(ALL_MODEL_FILES) == expected


# ------------------------------------------------------------------------------- arm + gripper


def test_arm_and_gripper_structure():
    _, plant, _, iiwa, gripper = _arm_with_gripper()
    assert plant.num_positions(iiwa) == 7
    assert plant.num_positions(gripper) == 2
    assert plant.num_actuators() == 9
    assert plant.num_actuated_dofs(iiwa) == 7
    assert plant.num_actuated_dofs(gripper) == 2
    for i in range(7):
        joint = plant.GetJointByName(f"iiwa_joint_{i + 1}", iiwa)
        assert joint.type_name() == "revolute"
        np.testing.assert_allclose(joint.position_lower_limits(), [-IIWA_POS_LIMIT[i]], atol=1e-9)
        np.testing.assert_allclose(joint.position_upper_limits(), [IIWA_POS_LIMIT[i]], atol=1e-9)
        np.testing.assert_allclose(joint.velocity_upper_limits(), [IIWA_VELOCITY[i]], atol=1e-9)
        np.testing.assert_allclose(joint.default_damping_vector(), [0.0])
        actuator = plant.GetJointActuatorByName(f"iiwa_actuator_{i + 1}", iiwa)
        assert actuator.joint().index() == joint.index()
        assert actuator.effort_limit() == IIWA_EFFORT[i]
    # Joint 1 is +-170 deg.
    assert plant.GetJointByName("iiwa_joint_1").position_upper_limits()[0] == pytest.approx(
        np.radians(170.0), abs=1e-6
    )
    for side in ("left", "right"):
        joint = plant.GetJointByName(f"{side}_finger_joint", gripper)
        assert joint.type_name() == "prismatic"
        np.testing.assert_allclose(joint.position_lower_limits(), [0.0])
        np.testing.assert_allclose(joint.position_upper_limits(), [0.055])
        assert plant.GetJointActuatorByName(f"{side}_finger_joint", gripper).effort_limit() == 40


def test_arm_mass_is_sum_of_published_link_masses():
    _, plant, _, iiwa, gripper = _arm_with_gripper()
    context = plant.CreateDefaultContext()
    arm_mass = plant.CalcTotalMass(context, [iiwa])
    assert arm_mass == pytest.approx(sum(IIWA_LINK_MASSES), abs=1e-6)  # 30.61 kg
    assert plant.CalcTotalMass(context, [gripper]) == pytest.approx(1.0 + 2 * 0.15, abs=1e-6)


def test_flange_and_gripper_frame_at_zero_configuration():
    _, plant, _, iiwa, gripper = _arm_with_gripper()
    context = plant.CreateDefaultContext()
    X_WF = plant.GetFrameByName("iiwa_link_ee", iiwa).CalcPoseInWorld(context)
    np.testing.assert_allclose(X_WF.translation(), [0, 0, FLANGE_HEIGHT], atol=1e-3)
    assert FLANGE_HEIGHT == pytest.approx(1.306)
    # At q = 0 the flange's z axis points straight up.
    np.testing.assert_allclose(X_WF.rotation().matrix(), np.eye(3), atol=1e-9)
    X_FG = plant.GetFrameByName("gripper_frame", gripper).CalcPose(
        context, plant.GetFrameByName("iiwa_link_ee", iiwa)
    )
    np.testing.assert_allclose(
        X_FG.translation(), [0, 0, dut.FLANGE_TO_GRIPPER_FRAME_Z], atol=1e-12
    )
    assert dut.FLANGE_TO_GRIPPER_FRAME_Z == 0.12


def test_gripper_frame_is_midway_between_bubbles():
    _, plant, scene_graph, _, gripper = _arm_with_gripper()
    context = plant.CreateDefaultContext()
    inspector = scene_graph.model_inspector()
    q_right, q_left = 0.04, 0.04
    plant.SetPositions(context, gripper, [q_right, q_left])
    X_WG = plant.GetFrameByName("gripper_frame", gripper).CalcPoseInWorld(context)
    apexes = []
    for side in ("left", "right"):
        body = plant.GetBodyByName(f"{side}_finger", gripper)
        (bubble,) = [
            g
            for g in plant.GetCollisionGeometriesForBody(body)
            if isinstance(inspector.GetShape(g), Ellipsoid)
        ]
        shape = inspector.GetShape(bubble)
        assert (shape.a(), shape.b(), shape.c()) == (0.02, 0.04, 0.055)
        props = inspector.GetProximityProperties(bubble)
        assert props.GetProperty("hydroelastic", "hydroelastic_modulus") == 1e5
        assert props.HasProperty("hydroelastic", "resolution_hint")
        # Inner apex of the bubble: its centre minus one semi-axis along the finger's +x.
        X_WB = body.EvalPoseInWorld(context) @ inspector.GetPoseInFrame(bubble)
        apexes.append(X_WB @ np.array([-shape.a(), 0, 0]))
    p_GA = [X_WG.inverse() @ p for p in apexes]  # apexes in gripper_frame
    np.testing.assert_allclose(p_GA[0], [-q_left, 0, 0], atol=1e-12)
    np.testing.assert_allclose(p_GA[1], [q_right, 0, 0], atol=1e-12)


def test_wrist_and_gripper_collisions_are_filtered():
    _, plant, scene_graph, iiwa, gripper = _arm_with_gripper()
    inspector = scene_graph.model_inspector()

    def geometries(instance, names):
        return [
            g
            for n in names
            for g in plant.GetCollisionGeometriesForBody(plant.GetBodyByName(n, instance))
        ]

    wrist = geometries(iiwa, ["iiwa_link_5", "iiwa_link_6", "iiwa_link_7"])
    hand = geometries(gripper, ["body", "left_finger", "right_finger"])
    upper_arm = geometries(iiwa, ["iiwa_link_0", "iiwa_link_1", "iiwa_link_2", "iiwa_link_3"])
    for a, b in product(wrist + hand, wrist + hand):
        if a != b:
            assert inspector.CollisionFiltered(a, b)
    # Real self-contact still counts: the upper arm can hit the hand and link 5.
    for a, b in product(upper_arm, hand + wrist[:1]):
        assert not inspector.CollisionFiltered(a, b)


def test_no_self_collision_at_home_configuration():
    builder, plant, scene_graph, iiwa, gripper = _arm_with_gripper(use_sampled_output_ports=False)
    diagram = builder.Build()
    context = diagram.CreateDefaultContext()
    plant_context = plant.GetMyContextFromRoot(context)
    plant.get_actuation_input_port().FixValue(plant_context, np.zeros(plant.num_actuators()))
    plant.SetPositions(plant_context, iiwa, HOME_Q)
    plant.SetPositions(plant_context, gripper, [0.03, 0.03])
    # The gripper points down at the home configuration.
    X_WG = plant.GetFrameByName("gripper_frame", gripper).CalcPoseInWorld(plant_context)
    assert X_WG.rotation().matrix()[2, 2] < -0.99
    query = scene_graph.get_query_output_port().Eval(scene_graph.GetMyContextFromRoot(context))
    assert query.ComputePointPairPenetration() == []
    contact = plant.get_contact_results_output_port().Eval(plant_context)
    assert contact.num_point_pair_contacts() == 0
    assert contact.num_hydroelastic_contacts() == 0
    # Smallest clearance between robot geometries that may collide, for the record: > 5 cm.
    distances = [p.distance for p in query.ComputeSignedDistancePairwiseClosestPoints()]
    assert min(distances) > 0.05


# -------------------------------------------------------------------------- objects and scene


@pytest.mark.parametrize("stem", sorted(YCB_EXPECTED))
def test_ycb_mass_and_dimensions(stem):
    _, plant, scene_graph, parser = _make_plant()
    (instance,) = parser.AddModels(url=dut.model_url(f"ycb/{stem}.sdf"))
    plant.Finalize()
    body = plant.GetBodyByName("base_link", instance)
    mass, dims = YCB_EXPECTED[stem]
    assert body.default_mass() == pytest.approx(mass, abs=1e-6)
    lo, hi = _body_aabb(plant, scene_graph, body)
    np.testing.assert_allclose(hi - lo, dims, atol=1e-3)
    np.testing.assert_allclose((hi + lo) / 2, [0, 0, 0], atol=1e-3)  # origin at the centre
    spatial_inertia = body.default_spatial_inertia()
    assert spatial_inertia.IsPhysicallyValid()
    inspector = scene_graph.model_inspector()
    for gid in plant.GetCollisionGeometriesForBody(body):
        props = inspector.GetProximityProperties(gid)
        assert props.GetProperty("hydroelastic", "hydroelastic_modulus") == 1e7
        friction = props.GetProperty("material", "coulomb_friction")
        assert friction.dynamic_friction() == 0.5


def test_table_top_and_wall_dimensions():
    _, plant, scene_graph, parser = _make_plant()
    (table,) = parser.AddModels(url=dut.TABLE_URL)
    (wall,) = parser.AddModels(url=dut.WALL_URL)
    plant.Finalize()
    lo, hi = _body_aabb(plant, scene_graph, plant.GetBodyByName("base_link", table))
    np.testing.assert_allclose(hi - lo, [1.6, 1.6, 0.05], atol=1e-9)
    assert hi[2] == pytest.approx(0.0, abs=1e-12)  # top surface at z = 0 of the model frame
    lo, hi = _body_aabb(plant, scene_graph, plant.GetBodyByName("base_link", wall))
    np.testing.assert_allclose(hi - lo, [1.4, 0.2, 0.3], atol=1e-9)
    np.testing.assert_allclose((hi + lo) / 2, [0, 0, 0], atol=1e-12)


def test_objects_resting_on_table_stay_still():
    builder, plant, _, parser = _make_plant()
    (table,) = parser.AddModels(url=dut.TABLE_URL)
    plant.WeldFrames(plant.world_frame(), plant.GetFrameByName("base_link", table))
    placements = {  # stem: (x, y, yaw); z = half the height puts the object on the table
        "003_cracker_box": (0.1, 0.0, 0.3),
        "005_tomato_soup_can": (-0.15, 0.1, 0.0),
        "003_cracker_box_10kg": (0.4, -0.2, 1.2),
        "005_tomato_soup_can_x1_2_2kg": (-0.3, -0.3, 0.0),
    }
    bodies = {}
    for stem, (x, y, yaw) in placements.items():
        (instance,) = parser.AddModels(url=dut.model_url(f"ycb/{stem}.sdf"))
        body = plant.GetBodyByName("base_link", instance)
        z = YCB_EXPECTED[stem][1][2] / 2
        plant.SetDefaultFloatingBaseBodyPose(
            body, RigidTransform(RollPitchYaw(0, 0, yaw), [x, y, z])
        )
        bodies[stem] = body
    plant.Finalize()
    diagram = builder.Build()
    simulator = Simulator(diagram)
    plant_context = plant.GetMyContextFromRoot(simulator.get_mutable_context())
    X_start = {stem: body.EvalPoseInWorld(plant_context) for stem, body in bodies.items()}
    simulator.AdvanceTo(1.0)
    for stem, body in bodies.items():
        X_end = body.EvalPoseInWorld(plant_context)
        moved = np.linalg.norm(X_end.translation() - X_start[stem].translation())
        R_rel = X_start[stem].rotation().inverse() @ X_end.rotation()
        turned = np.degrees(np.arccos(np.clip((np.trace(R_rel.matrix()) - 1) / 2, -1, 1)))
        assert moved < 1e-3, f"{stem} moved {moved * 1e3:.3f} mm"
        assert turned < 0.5, f"{stem} turned {turned:.3f} deg"
    contact = plant.get_contact_results_output_port().Eval(plant_context)
    assert contact.num_hydroelastic_contacts() == len(bodies)  # each object on the table
    assert contact.num_point_pair_contacts() == 0


def test_bubbles_squeeze_an_object_through_hydroelastic_contact():
    """A gelatin box (0.026 m thick) between bubbles 0.02 m apart: 3 mm of squeeze per side."""
    builder, plant, scene_graph, parser = _make_plant(use_sampled_output_ports=False)
    (gripper,) = parser.AddModels(url=dut.BUBBLE_GRIPPER_URL)
    plant.WeldFrames(
        plant.world_frame(), plant.GetFrameByName("body", gripper), RigidTransform([0, 0, 0.5])
    )
    (box,) = parser.AddModels(url=dut.model_url("ycb/009_gelatin_box.sdf"))
    plant.Finalize()
    diagram = builder.Build()
    context = diagram.CreateDefaultContext()
    plant_context = plant.GetMyContextFromRoot(context)
    plant.get_actuation_input_port().FixValue(plant_context, np.zeros(plant.num_actuators()))
    plant.SetPositions(plant_context, gripper, [0.01, 0.01])
    X_WG = plant.GetFrameByName("gripper_frame", gripper).CalcPoseInWorld(plant_context)
    plant.SetFreeBodyPose(plant_context, plant.GetBodyByName("base_link", box), X_WG)
    contact = plant.get_contact_results_output_port().Eval(plant_context)
    assert contact.num_point_pair_contacts() == 0
    assert contact.num_hydroelastic_contacts() == 2
    inspector = scene_graph.model_inspector()
    forces, centroids = [], []
    for i in range(2):
        info = contact.hydroelastic_contact_info(i)
        surface = info.contact_surface()
        names = {inspector.GetName(surface.id_M()), inspector.GetName(surface.id_N())}
        assert names == {"bubble_gripper::bubble_collision", "009_gelatin_box::collision"}
        forces.append(info.F_Ac_W().translational())
        centroids.append(surface.centroid() - X_WG.translation())
    # The patches sit on the box's faces at x = +-0.013 m and squeeze along the closing axis;
    # friction on them carries the box's weight (0.097 kg x 9.81 = 0.95 N) within 2 %.
    np.testing.assert_allclose(sorted(c[0] for c in centroids), [-0.013, 0.013], atol=1e-3)
    for force in forces:
        assert abs(force[0]) > 0.5  # newtons
        assert abs(force[1]) < 1e-6
    assert sum(abs(f[2]) for f in forces) == pytest.approx(0.097 * 9.81, rel=0.02)
