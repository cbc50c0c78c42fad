"""The bubble contact sensor in a Drake scene: the gripper on a slide pressing one bubble
against a welded box, the sensor's contact point against Drake's own hydroelastic contact
surface, and a touch too light to count.
"""

from __future__ import annotations

import numpy as np
import pytest
from pydrake.geometry import AddRigidHydroelasticProperties, Box, ProximityProperties
from pydrake.math import RigidTransform, RollPitchYaw
from pydrake.multibody.parsing import Parser
from pydrake.multibody.plant import (
    AddMultibodyPlant,
    CoulombFriction,
    MultibodyPlantConfig,
)
from pydrake.multibody.tree import FixedOffsetFrame, PrismaticJoint
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import ConstantVectorSource

from stucco_drake.robot.models import (
    BUBBLE_GRIPPER_URL,
    bubble_bodies,
    configure_parser,
)
from stucco_drake.systems.bubble_contact_sensor import BubbleContactSensor


def bubble_scene(yaw_deg: float, press: float, gap: float = 0.001):
    """Gripper on a damped x slide (no gravity, fingers locked at 0.03 m) pressing its right
    bubble with ``press`` N against a welded rigid box standing between the fingers, the box
    yawed by ``yaw_deg``, the bubble starting ``gap`` m from it. Returns the simulated pieces
    after 0.4 s."""
    builder = DiagramBuilder()
    config = MultibodyPlantConfig(time_step=1e-3, discrete_contact_approximation="sap",
                                  contact_model="hydroelastic_with_fallback")  # fmt: skip
    plant, scene_graph = AddMultibodyPlant(config, builder)
    plant.mutable_gravity_field().set_gravity_vector(np.zeros(3))
    (gripper,) = configure_parser(Parser(plant)).AddModels(url=BUBBLE_GRIPPER_URL)
    origin = plant.AddFrame(FixedOffsetFrame("slide_origin", plant.world_frame(),
                                             RigidTransform([gap - 0.02, 0, 0])))  # fmt: skip
    slide = plant.AddJoint(PrismaticJoint("slide", origin, plant.GetFrameByName("body", gripper),
                                          [1.0, 0.0, 0.0], damping=200.0))  # fmt: skip
    motor = plant.AddJointActuator("slide_motor", slide)
    X_WBox = RigidTransform(RollPitchYaw(0, 0, np.radians(yaw_deg)), [0.0, 0.0, 0.185])
    props = ProximityProperties()
    AddRigidHydroelasticProperties(0.005, props)
    props.AddProperty("material", "coulomb_friction", CoulombFriction(0.5, 0.5))
    size = np.array([0.02, 0.2, 0.23])
    plant.RegisterCollisionGeometry(plant.world_body(), X_WBox, Box(*size), "box", props)
    plant.Finalize()
    sensor = builder.AddSystem(BubbleContactSensor(plant, scene_graph, 1e-3, bubble_bodies(plant)))
    builder.Connect(plant.get_contact_results_output_port(), sensor.GetInputPort("contact_results"))
    builder.Connect(plant.get_body_poses_output_port(), sensor.GetInputPort("body_poses"))
    u = np.zeros(plant.num_actuators())
    u[motor.input_start()] = -press
    builder.Connect(builder.AddSystem(ConstantVectorSource(u)).get_output_port(),
                    plant.get_actuation_input_port())  # fmt: skip
    simulator = Simulator(builder.Build())
    plant_context = plant.GetMyMutableContextFromRoot(simulator.get_mutable_context())
    for name in ("left_finger_joint", "right_finger_joint"):
        joint = plant.GetJointByName(name, gripper)
        joint.set_translation(plant_context, 0.03)
        joint.Lock(plant_context)
    simulator.AdvanceTo(0.4)
    return plant, sensor, simulator, X_WBox, size


def true_bubble_contact(plant, context, X_WBox, size):
    """Deepest point of the undeformed right bubble beyond the box's +x face, projected onto the
    face: where the first touch happened and, for a small dent, the dent's centre (world, m)."""
    n = X_WBox.rotation().matrix()[:, 0]
    p_face = X_WBox.translation() + 0.5 * size[0] * n
    X_WF = plant.GetBodyByName("right_finger").EvalPoseInWorld(context)
    X_WE = X_WF.multiply(RigidTransform([0.02, 0.0, 0.06]))
    radii = np.array([0.02, 0.04, 0.055])
    d = X_WE.rotation().inverse().multiply(-n)
    support = X_WE.multiply(radii**2 * d / np.sqrt(d @ (radii**2 * d)))
    return support - ((support - p_face) @ n) * n


@pytest.mark.parametrize("yaw_deg", [0.0, 12.0])
def test_bubble_point_matches_true_contact(yaw_deg):
    plant, sensor, simulator, X_WBox, size = bubble_scene(yaw_deg, press=10.0)
    root = simulator.get_context()
    sensor_context = sensor.GetMyContextFromRoot(root)
    flags = sensor.GetOutputPort("bubble_in_contact").Eval(sensor_context)
    points = sensor.GetOutputPort("bubble_contact_points").Eval(sensor_context).reshape(-1, 3)
    depth = sensor.GetOutputPort("bubble_penetration").Eval(sensor_context)
    assert sensor.bubble_names == ["left_finger", "right_finger"]
    assert flags.tolist() == [0.0, 1.0]
    truth = true_bubble_contact(plant, plant.GetMyContextFromRoot(root), X_WBox, size)
    results = plant.get_contact_results_output_port().Eval(plant.GetMyContextFromRoot(root))
    drake_centroid = results.hydroelastic_contact_info(0).contact_surface().centroid()
    error = np.linalg.norm(points[1] - truth)
    print(f"yaw {yaw_deg}: penetration {1e3 * depth[1]:.2f} mm, bubble point error "
          f"{1e3 * error:.2f} mm, vs Drake's area centroid "
          f"{1e3 * np.linalg.norm(points[1] - drake_centroid):.2f} mm")  # fmt: skip
    assert error <= 0.003


def test_light_touch_does_not_fire():
    """0.5 N dents the bubble by about 0.5 mm: in contact, below the 1 mm threshold."""
    _, sensor, simulator, _, _ = bubble_scene(0.0, press=0.5, gap=0.0)
    context = sensor.GetMyContextFromRoot(simulator.get_context())
    depth = sensor.GetOutputPort("bubble_penetration").Eval(context)
    print(f"light touch: penetration {1e3 * depth[1]:.2f} mm")
    assert 0.0 < depth[1] < 1e-3
    assert sensor.GetOutputPort("bubble_in_contact").Eval(context).tolist() == [0.0, 0.0]
