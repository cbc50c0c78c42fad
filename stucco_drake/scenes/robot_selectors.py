"""Matrices between the simulation plant's vectors and the robot-only plant's.

The scene Diagram (:mod:`stucco_drake.scenes.builder`) simulates the robot among the objects in
one plant and controls it on a plant of the robot alone; these 0/1 matrices take the robot's
state out of the simulation plant and put the controller's torques into its actuation,
matching joints by model instance name and joint name.
"""

from __future__ import annotations

import numpy as np
from pydrake.multibody.plant import MultibodyPlant


def robot_joints(plant: MultibodyPlant, models: tuple[str, ...]) -> list:
    """The joints with velocities of the model instances named ``models`` in ``plant``."""
    instances = [plant.GetModelInstanceByName(n) for n in models]
    joints = []
    for instance in instances:
        for index in plant.GetJointIndices(instance):
            joint = plant.get_joint(index)
            if joint.num_velocities() > 0:
                joints.append(joint)
    return joints


def state_selector(plant: MultibodyPlant, robot_plant: MultibodyPlant,
                   models: tuple[str, ...]) -> np.ndarray:  # fmt: skip
    """S with x_robot = S x_plant over the robot plant's joints of ``models``, matching
    joints by model instance and name."""
    S = np.zeros((robot_plant.num_multibody_states(), plant.num_multibody_states()))
    nq_r, nq = robot_plant.num_positions(), plant.num_positions()
    for rj in robot_joints(robot_plant, models):
        name = robot_plant.GetModelInstanceName(rj.model_instance())
        instance = plant.GetModelInstanceByName(name)
        sj = plant.GetJointByName(rj.name(), instance)
        for i in range(rj.num_positions()):
            S[rj.position_start() + i, sj.position_start() + i] = 1.0
        for i in range(rj.num_velocities()):
            S[nq_r + rj.velocity_start() + i, nq + sj.velocity_start() + i] = 1.0
    return S


def actuation_selector(plant: MultibodyPlant, robot_plant: MultibodyPlant) -> np.ndarray:
    """B with u_plant = B tau_robot: each actuator takes its joint's generalized force."""
    B = np.zeros((plant.num_actuated_dofs(), robot_plant.num_velocities()))
    for index in plant.GetJointActuatorIndices():
        actuator = plant.get_joint_actuator(index)
        joint = actuator.joint()
        instance = robot_plant.GetModelInstanceByName(
            plant.GetModelInstanceName(joint.model_instance())
        )
        rj = robot_plant.GetJointByName(joint.name(), instance)
        B[actuator.input_start(), rj.velocity_start()] = 1.0
    if np.linalg.matrix_rank(B) != robot_plant.num_velocities():
        raise ValueError("every robot joint must have an actuator")
    return B
