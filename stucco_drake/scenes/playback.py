"""Playing a built scene's action sequence, one action at a time, with per-action records.

Units: metres, radians, seconds; poses in the world frame.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable

import numpy as np
from pydrake.systems.analysis import Simulator

from stucco_drake.scenes.builder import BuiltScene, yaw_of


@dataclasses.dataclass
class ActionRecord:
    """State at the end of one action.

    Attributes:
        index: the action's index in the sequence.
        time: simulated time at the end of the action (s).
        goal_xy: the planar goal of the action (m, world).
        gripper_xyz: gripper frame position (m, world).
        gripper_yaw: yaw of the gripper's closing axis (rad, world).
        objects: name -> (x, y, z, yaw) of every free object (m, rad, world).
    """

    index: int
    time: float
    goal_xy: np.ndarray
    gripper_xyz: np.ndarray
    gripper_yaw: float
    objects: dict


def make_simulator(built: BuiltScene) -> Simulator:
    """An initialized Simulator of the built Diagram in its default context."""
    simulator = Simulator(built.diagram)
    simulator.Initialize()
    return simulator


def record(built: BuiltScene, simulator: Simulator, index: int) -> ActionRecord:
    """The :class:`ActionRecord` of the simulator's current state."""
    context = simulator.get_context()
    plant_context = built.plant.GetMyContextFromRoot(context)
    X_WG = built.gripper_frame().CalcPoseInWorld(plant_context)
    objects = {}
    for name, body in built.free_bodies.items():
        X = body.EvalPoseInWorld(plant_context)
        objects[name] = np.array([*X.translation(), yaw_of(X.rotation())])
    return ActionRecord(
        index=index,
        time=context.get_time(),
        goal_xy=built.diagram.GetOutputPort("planar_goal").Eval(context).copy(),
        gripper_xyz=X_WG.translation().copy(),
        gripper_yaw=yaw_of(X_WG.rotation()),
        objects=objects,
    )


def play(built: BuiltScene, n_actions: int | None = None, *, simulator: Simulator | None = None,
         on_action: Callable[[ActionRecord], None] | None = None):
    """Plays the first ``n_actions`` actions (all by default); returns (records, wall seconds).

    The initial record (index -1, before any action) comes first.
    """
    simulator = simulator or make_simulator(built)
    total = len(built.scene.actions)
    n_actions = total if n_actions is None else min(n_actions, total)
    duration = built.scene.action_duration
    records = [record(built, simulator, -1)]
    start = time.perf_counter()
    for k in range(n_actions):
        simulator.AdvanceTo((k + 1) * duration)
        records.append(record(built, simulator, k))
        if on_action is not None:
            on_action(records[-1])
    return records, time.perf_counter() - start
