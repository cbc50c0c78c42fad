"""The second robot: a three-joint SCARA-type arm with a rigid spherical probe.

Its model is ``models/scara_probe/scara_probe.urdf`` (dimensions and their source in that
folder's README). Everything the contact-tracking chain needs to know about a robot that is not
ours comes from here, by the same arguments our iiwa's come from :mod:`stucco_drake.robot.models`
and :mod:`stucco_drake.robot.gripper_sdf`:

- :func:`scara_robot_plant` / :func:`scara_observed_robot_arguments`: the robot-only plant and
  the ``ObservedRobot`` arguments (the ``probe_tip`` frame, all three joints observed).
- :func:`probe_collision_shapes`, :func:`probe_surface_samples`: the contact isolator's
  candidate points, on the model's own collision geometry.
- :func:`probe_grid_sdf`, :func:`probe_penetration`: the tracker's pxpen (a ``GridSdf`` of the
  probe in ``probe_tip``).

Units: m, rad; frame ``probe_tip`` (at the probe's centre, z axis down) unless said otherwise.
"""

from __future__ import annotations

import numpy as np
from pydrake.geometry import Role, Sphere
from pydrake.math import RigidTransform
from pydrake.multibody.parsing import Parser
from pydrake.multibody.plant import AddMultibodyPlantSceneGraph, MultibodyPlant
from pydrake.multibody.tree import ModelInstanceIndex
from pydrake.systems.framework import DiagramBuilder

from stucco_drake.core.penetration import RobotPenetration
from stucco_drake.core.sdf import GridSdf
from stucco_drake.core.shapes import SphereSdf
from stucco_drake.robot.gripper_samples import sample_gripper_surface
from stucco_drake.robot.models import configure_parser, model_url

SCARA_PROBE_URL = model_url("scara_probe/scara_probe.urdf")
#: The frame contacts are expressed at: the probe's centre, z axis pointing down.
PROBE_FRAME = "probe_tip"
#: Model instance name used by :func:`add_scara_probe`'s callers in this package.
SCARA = "scara"


def add_scara_probe(plant: MultibodyPlant, X_WB: RigidTransform | None = None,
                    name: str = SCARA) -> ModelInstanceIndex:  # fmt: skip
    """Adds the arm to the (unfinalized) ``plant`` with its base plate welded at X_WB."""
    parser = configure_parser(Parser(plant))
    parser.SetAutoRenaming(False)
    (instance,) = parser.AddModels(url=SCARA_PROBE_URL)
    if name != plant.GetModelInstanceName(instance):
        plant.RenameModelInstance(instance, name)
    plant.WeldFrames(plant.world_frame(), plant.GetFrameByName("base", instance),
                     X_WB if X_WB is not None else RigidTransform())  # fmt: skip
    return instance


def scara_robot_plant(X_WB: RigidTransform | None = None) -> MultibodyPlant:
    """A continuous, finalized plant of the arm alone (no objects), base welded at X_WB; its
    generalized coordinates are shoulder, elbow, wrist (rad)."""
    plant = MultibodyPlant(0.0)
    add_scara_probe(plant, X_WB)
    plant.Finalize()
    return plant


def scara_observed_robot_arguments(X_WB: RigidTransform | None = None) -> dict:
    """Arguments of ``ObservedRobot`` for the arm: its robot plant (base at X_WB), the
    ``probe_tip`` frame and all three joints observed."""
    plant = scara_robot_plant(X_WB)
    return {"plant": plant, "frame": plant.GetFrameByName(PROBE_FRAME), "joints": (0, 1, 2)}


def probe_collision_shapes() -> list:
    """The arm's proximity shapes in ``probe_tip``, as (kind, dims, X_ES 4x4) like
    :func:`~stucco_drake.robot.gripper_samples.gripper_collision_shapes` ("ellipsoid" with
    three equal semi-axes for a sphere). Read from the model file, so they follow it."""
    builder = DiagramBuilder()
    plant, scene_graph = AddMultibodyPlantSceneGraph(builder, 0.0)
    add_scara_probe(plant)
    plant.Finalize()
    diagram = builder.Build()
    context = diagram.CreateDefaultContext()
    query = scene_graph.get_query_output_port().Eval(scene_graph.GetMyContextFromRoot(context))
    X_EW = plant.GetFrameByName(PROBE_FRAME).CalcPoseInWorld(
        plant.GetMyContextFromRoot(context)).inverse()  # fmt: skip
    shapes = []
    for gid in query.inspector().GetAllGeometryIds(Role.kProximity):
        shape = query.inspector().GetShape(gid)
        if not isinstance(shape, Sphere):
            raise ValueError(f"probe_collision_shapes: expected spheres, got {type(shape)}")
        X_ES = X_EW.multiply(query.GetPoseInWorld(gid)).GetAsMatrix4()
        shapes.append(("ellipsoid", np.full(3, shape.radius()), X_ES))
    return shapes


def probe_radius() -> float:
    """The probe sphere's radius (m), from the model file."""
    ((_, dims, _),) = probe_collision_shapes()
    return float(dims[0])


def probe_surface_samples(rng: np.random.Generator, spacing: float = 0.004):
    """Area-uniform (points, outward normals), (N, 3) each, on the probe's surface in
    ``probe_tip`` (m): the contact isolator's ``samples``. Draws come from ``rng``."""
    return sample_gripper_surface(rng, spacing, shapes=probe_collision_shapes())


def probe_grid_sdf(resolution: float = 0.001, margin: float = 0.01) -> GridSdf:
    """Signed distance of the probe in ``probe_tip`` (m, negative inside) on a grid of
    ``resolution`` over its bounding box grown by ``margin`` (so the grid encloses it)."""
    ((_, dims, X),) = probe_collision_shapes()
    sphere = SphereSdf(float(dims[0]), tuple(X[:3, 3]))
    lower, upper = sphere.bounds(margin)
    return GridSdf.build(sphere, lower, upper, resolution, key="scara_probe_sphere")


def probe_penetration(resolution: float = 0.001) -> RobotPenetration:
    """The tracker's pxpen for the probe (see :func:`probe_grid_sdf`)."""
    return RobotPenetration(probe_grid_sdf(resolution))


__all__ = [
    "PROBE_FRAME",
    "SCARA",
    "SCARA_PROBE_URL",
    "add_scara_probe",
    "probe_collision_shapes",
    "probe_grid_sdf",
    "probe_penetration",
    "probe_radius",
    "probe_surface_samples",
    "scara_observed_robot_arguments",
    "scara_robot_plant",
]
