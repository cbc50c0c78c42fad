"""The second robot's station: the SCARA probe arm, a table and movable boxes, planar pushes.

:func:`build_probe_station` builds a Diagram like :func:`~stucco_drake.scenes.build_scene`
does for our iiwa, from a :class:`ProbeScene` instead of a scene file: a discrete SAP plant
with the arm (``models/scara_probe``), the table and the scene's boxes; an
InverseDynamicsController on the robot-only plant tracking the joint command of the same
:class:`~stucco_drake.systems.planar_controller.PlanarEndEffectorController` (the probe held
at its height and yaw, moved by planar steps of at most 3 cm) and a
:class:`~stucco_drake.systems.planar_controller.PlanarActionSequence` playing the actions.

Exported ports (robot vectors in the robot-only plant's order: shoulder, elbow, wrist):
    ``robot_state`` [q; v] (rad, rad/s); ``applied_torque`` the plant's net actuation of the
    arm (N m); ``action_index``; ``plant_state``; ``contact_results``; ``body_poses``.

:func:`free_space_statistics` is the detector's calibration for this arm (paper Eq. 1): the
same station without boxes, random planar steps, the estimator's ``ee_wrench`` fitted.

Units: m, rad, s, kg; world frame z up, table top at z = 0.
"""

from __future__ import annotations

import dataclasses

import numpy as np
from pydrake.math import RigidTransform, RollPitchYaw
from pydrake.multibody.parsing import Parser
from pydrake.multibody.plant import AddMultibodyPlant, MultibodyPlant, MultibodyPlantConfig
from pydrake.systems.analysis import Simulator
from pydrake.systems.controllers import InverseDynamicsController
from pydrake.systems.framework import Diagram, DiagramBuilder
from pydrake.systems.primitives import LogVectorOutput

from stucco_drake.core.detection import ResidualStatistics, fit_residual_statistics
from stucco_drake.robot.models import TABLE_URL, configure_parser
from stucco_drake.robot.scara_probe import (
    PROBE_FRAME,
    SCARA,
    add_scara_probe,
    scara_observed_robot_arguments,
    scara_robot_plant,
)
from stucco_drake.scenes.primitives import add_primitive
from stucco_drake.scenes.scene_file import ControlParams, Primitive
from stucco_drake.systems.contact_detector import DEFAULT_FLOOR_STD
from stucco_drake.systems.observed_robot import ObservedRobot
from stucco_drake.systems.planar_controller import (
    ArmKinematics,
    PlanarActionSequence,
    PlanarEndEffectorController,
    gripper_rotation,
    solve_start_ik,
)
from stucco_drake.systems.wrench_estimator import ExternalWrenchEstimator


def _box(name, size, xy, rgba) -> Primitive:
    """A free box standing on the table (centre at half its height), 0.8 kg, friction 0.6."""
    return Primitive(name=name, shape="box", size=list(size), xyz=[*xy, size[2] / 2],
                     mass=0.8, friction=0.6, rgba=rgba)  # fmt: skip


#: Three boxes 0.08 m tall (the probe's centre is 0.04 m up: it meets their faces halfway).
#: Where they end up, their contacts lie beyond STUCCO's segmentation radius (0.135 m at
#: Table I's l = 0.02) from each other's, so a perfect tracker segments them apart.
PUSH_BOXES = (
    _box("box_a", (0.06, 0.06, 0.08), (0.28, 0.0), [0.85, 0.55, 0.2, 1.0]),
    _box("box_b", (0.06, 0.08, 0.08), (0.28, 0.17), [0.3, 0.6, 0.85, 1.0]),
    _box("box_c", (0.08, 0.06, 0.08), (0.24, -0.15), [0.4, 0.75, 0.35, 1.0]),
)
#: The prescribed pushes, in units of the 0.03 m step (world x, y); the probe starts at
#: (0.21, 0) and its surface reaches 0.025 m beyond its centre. box_a is pushed twice, on two
#: faces: its first contacts must follow it when the second push moves it sideways.
PUSH_ACTIONS = (
    (1, 0), (1, 0),  # 0-1: push box_a 4.5 cm along +x from its -x face
    (-1, 0), (0, 1), (0, 1), (0, 1),  # 2-5: back off, along +y to (0.24, 0.09)
    (1, 0), (1, 0), (1, 0),  # 6-8: past box_a's +y side to x = 0.33
    (0, -1), (0, -1),  # 9-10: push box_a 2.5 cm along -y from its +y face
    (0, 1), (-1, 0), (-1, 0), (-1, 0), (-1, 0),  # 11-15: back off to (0.21, 0.06)
    (0, 1), (0, 1), (0, 1),  # 16-18: along +y to y = 0.15
    (1, 0), (1, 0),  # 19-20: push box_b 4.5 cm along +x
    (-1, 0), (-1, 0),  # 21-22: back off to x = 0.21
    (0, -1), (0, -1), (0, -1), (0, -1), (0, -1), (0, -1), (0, -1), (0, -1),  # 23-30: y = -0.09
    (0, -1), (0, -1),  # 31-32: push box_c 5.5 cm along -y
    (0, 1),  # 33: back off
)  # fmt: skip


@dataclasses.dataclass(frozen=True)
class ProbeScene:
    """What :func:`build_probe_station` builds.

    Attributes:
        boxes: the movable objects (primitives standing on the table).
        actions: planar steps (dx, dy) in units of ``control.max_step``, world frame.
        base: the arm's base plate pose [x, y, yaw] on the table (m, rad). The pushes keep
            the probe 0.21-0.35 m from it, the elbow 0.4 rad or more from its limit and from
            the straight arm (a joint at its limit feels the plant's limit force, which the
            observer would read as a contact).
        start_xy: where the probe's centre starts (m, world); yaw: its held yaw (rad).
        nominal_q: seed of the start IK (rad; elbow bent, away from the straight arm).
        action_duration: seconds per action; time_step: the plant's (s).
        control: joint gains and planar control (the iiwa scenes' defaults, no push cap;
            its ``nominal_q`` is the iiwa's and unused here).
    """

    boxes: tuple = PUSH_BOXES
    actions: tuple = PUSH_ACTIONS
    base: tuple = (0.0, 0.0, 0.0)
    start_xy: tuple = (0.21, 0.0)
    yaw: float = 0.0
    nominal_q: tuple = (-0.9, 1.8, -0.9)
    action_duration: float = 0.5
    time_step: float = 0.002
    control: ControlParams = dataclasses.field(default_factory=ControlParams)

    def base_pose(self) -> RigidTransform:
        x, y, yaw = self.base
        return RigidTransform(RollPitchYaw(0.0, 0.0, yaw), [x, y, 0.0])


@dataclasses.dataclass
class ProbeStation:
    """The built station and handles into it (see the module docstring for its ports).

    Attributes:
        diagram, plant, scene_graph: the Diagram, its simulation plant and SceneGraph.
        robot_plant: the robot-only plant the controller uses; robot: the arm's instance in
            ``plant``; objects: box name -> body of ``plant``.
        height: the probe centre's held height (m); q_start: the start joint positions (rad).
    """

    scene: ProbeScene
    diagram: Diagram
    plant: MultibodyPlant
    scene_graph: object
    robot_plant: MultibodyPlant
    robot: object
    objects: dict
    height: float
    q_start: np.ndarray


def _start(robot_plant: MultibodyPlant, scene: ProbeScene) -> tuple[float, np.ndarray]:
    """(held height (m), start joint positions (rad)) of the probe at ``scene.start_xy``."""
    kin = ArmKinematics(robot_plant, robot_plant.GetModelInstanceByName(SCARA),
                        robot_plant.GetFrameByName(PROBE_FRAME))  # fmt: skip
    kin.set_positions(np.asarray(scene.nominal_q, dtype=float))
    height = float(kin.pose().translation()[2])  # fixed by the kinematics (vertical axes)
    X_start = RigidTransform(gripper_rotation(scene.yaw), [*scene.start_xy, height])
    q = solve_start_ik(kin, np.zeros(3), X_start, np.asarray(scene.nominal_q, dtype=float))
    return height, q


def build_probe_station(scene: ProbeScene | None = None) -> ProbeStation:
    """Builds ``scene`` (default :class:`ProbeScene`) into a Diagram (module docstring)."""
    scene = scene or ProbeScene()
    h = float(scene.time_step)
    builder = DiagramBuilder()
    config = MultibodyPlantConfig(time_step=h, discrete_contact_approximation="sap",
                                  contact_model="hydroelastic_with_fallback",
                                  use_sampled_output_ports=False)  # fmt: skip
    plant, scene_graph = AddMultibodyPlant(config, builder)
    robot = add_scara_probe(plant, scene.base_pose())
    (table,) = configure_parser(Parser(plant)).AddModels(url=TABLE_URL)
    plant.WeldFrames(plant.world_frame(), plant.GetFrameByName("base_link", table))
    instances = {box.name: add_primitive(plant, box) for box in scene.boxes}
    plant.Finalize()
    objects = {name: plant.GetBodyByName("base_link", i) for name, i in instances.items()}

    robot_plant = scara_robot_plant(scene.base_pose())
    height, q_start = _start(robot_plant, scene)
    robot_plant.SetDefaultPositions(q_start)
    plant.SetDefaultPositions(robot, q_start)
    c = scene.control
    gains = [np.full(3, g) for g in (c.kp, c.ki, c.kd)]
    idc = builder.AddNamedSystem("joint_controller",
                                 InverseDynamicsController(robot_plant, *gains, False))  # fmt: skip
    builder.Connect(plant.get_state_output_port(robot), idc.get_input_port_estimated_state())
    builder.Connect(idc.get_output_port_control(), plant.get_actuation_input_port(robot))
    ctrl = builder.AddNamedSystem("planar_controller", PlanarEndEffectorController(
        robot_plant, robot_plant.GetModelInstanceByName(SCARA),
        robot_plant.GetFrameByName(PROBE_FRAME), height=height, yaw=scene.yaw,
        q_start=q_start, q_nominal=q_start, hold_positions=q_start, start_xy=scene.start_xy,
        period=c.ik_period, action_duration=scene.action_duration,
        move_fraction=c.move_fraction, gain=c.ik_gain, max_step=c.max_step,
    ))  # fmt: skip
    builder.Connect(plant.get_state_output_port(robot), ctrl.GetInputPort("robot_state"))
    builder.Connect(ctrl.GetOutputPort("desired_state"), idc.get_input_port_desired_state())
    steps = np.clip(np.asarray(scene.actions, dtype=float).reshape(-1, 2), -1, 1) * c.max_step
    sequence = builder.AddNamedSystem(
        "action_sequence", PlanarActionSequence(steps, scene.action_duration))  # fmt: skip
    builder.Connect(sequence.GetOutputPort("planar_step"), ctrl.GetInputPort("planar_step"))
    for name, port in (
        ("robot_state", plant.get_state_output_port(robot)),
        ("applied_torque", plant.get_net_actuation_output_port(robot)),
        ("action_index", sequence.GetOutputPort("action_index")),
        ("plant_state", plant.get_state_output_port()),
        ("contact_results", plant.get_contact_results_output_port()),
        ("body_poses", plant.get_body_poses_output_port()),
    ):
        builder.ExportOutput(port, name)
    diagram = builder.Build()
    diagram.set_name("probe_station")
    return ProbeStation(scene, diagram, plant, scene_graph, robot_plant, robot, objects,
                        height, q_start)  # fmt: skip


def make_station_simulator(diagram: Diagram, time_step: float) -> Simulator:
    """A Simulator whose integrator (the joint controller's integral term) takes fixed steps
    of the plant's time step, so that runs repeat exactly (as the BOR episodes do)."""
    simulator = Simulator(diagram)
    integrator = simulator.get_mutable_integrator()
    integrator.set_fixed_step_mode(True)
    integrator.set_maximum_step_size(float(time_step))
    simulator.Initialize()
    return simulator


def random_planar_steps(rng: np.random.Generator, n: int, *, box: float = 2.0) -> tuple:
    """``n`` random steps (units of the max step, each axis uniform in [-1, 1]) whose running
    sum stays within +-``box`` steps of the start on each axis (a step that would leave is
    reversed): free-space motion around the start, for calibration."""
    position, steps = np.zeros(2), []
    for step in rng.uniform(-1.0, 1.0, (n, 2)):
        step = np.where(np.abs(position + step) > box, -step, step)
        position += step
        steps.append(tuple(float(s) for s in step))
    return tuple(steps)


def free_space_statistics(scene: ProbeScene | None = None, *, gain: float = 50.0,
                          seed: int = 0, n_actions: int = 16, start_xy=(0.27, 0.0),
                          warmup: float = 0.2) -> ResidualStatistics:  # fmt: skip
    """The detector's free-space wrench statistics for the probe arm (paper Eq. 1).

    Runs ``scene`` without its boxes from ``start_xy`` (m; the middle of the pushes' area,
    so the random walk stays clear of the joint limits) through ``n_actions`` random planar
    steps (:func:`random_planar_steps`, seeded with ``seed``), logs an
    :class:`ExternalWrenchEstimator`'s ``ee_wrench`` (observer ``gain`` 1/s, as the chain's)
    every step after ``warmup`` s, and fits it with the iiwa's floor std (0.05 N m, 0.3 N).
    """
    scene = dataclasses.replace(
        scene or ProbeScene(), boxes=(), start_xy=tuple(start_xy),
        actions=random_planar_steps(np.random.default_rng(seed), n_actions))  # fmt: skip
    station = build_probe_station(scene)
    h = float(scene.time_step)
    builder = DiagramBuilder()
    sub = builder.AddSystem(station.diagram)
    robot = ObservedRobot(**scara_observed_robot_arguments(scene.base_pose()))
    estimator = builder.AddSystem(ExternalWrenchEstimator(
        h, robot, gain=gain, sampled_plant_outputs=False))  # fmt: skip
    builder.Connect(sub.GetOutputPort("robot_state"), estimator.GetInputPort("state"))
    builder.Connect(sub.GetOutputPort("applied_torque"), estimator.GetInputPort("applied_torque"))
    logger = LogVectorOutput(estimator.GetOutputPort("ee_wrench"), builder, h)
    diagram = builder.Build()
    simulator = make_station_simulator(diagram, h)
    simulator.AdvanceTo(n_actions * scene.action_duration)
    log = logger.FindLog(simulator.get_context())
    samples = log.data().T[log.sample_times() >= warmup]
    return fit_residual_statistics(samples, DEFAULT_FLOOR_STD)


__all__ = [
    "PUSH_ACTIONS",
    "PUSH_BOXES",
    "ProbeScene",
    "ProbeStation",
    "build_probe_station",
    "free_space_statistics",
    "make_station_simulator",
    "random_planar_steps",
]
