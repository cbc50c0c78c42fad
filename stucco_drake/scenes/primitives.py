"""Inline primitive objects of a scene file (boxes and cylinders), added as SDFormat models.

Free primitives are compliant hydroelastic (modulus 1e7 Pa, like our YCB models) so that they
rest still on the rigid table; welded ones (walls) are rigid hydroelastic. Inertia is that of a
uniform solid.
"""

from __future__ import annotations

from pydrake.math import RigidTransform, RollPitchYaw
from pydrake.multibody.parsing import Parser
from pydrake.multibody.plant import MultibodyPlant

from stucco_drake.robot.models import configure_parser
from stucco_drake.scenes.scene_file import Primitive

_TEMPLATE = """<?xml version="1.0"?>
<sdf version="1.9" xmlns:drake="http://drake.mit.edu">
  <model name="{name}">
    <link name="base_link">
      <inertial>
        <mass>{mass}</mass>
        <inertia><ixx>{ixx}</ixx><iyy>{iyy}</iyy><izz>{izz}</izz>
          <ixy>0</ixy><ixz>0</ixz><iyz>0</iyz></inertia>
      </inertial>
      <visual name="visual">
        <geometry>{geometry}</geometry>
        <material><diffuse>{rgba}</diffuse></material>
      </visual>
      <collision name="collision">
        <geometry>{geometry}</geometry>
        <drake:proximity_properties>
          {hydro}
          <drake:hunt_crossley_dissipation>1.0</drake:hunt_crossley_dissipation>
          <drake:relaxation_time>0.1</drake:relaxation_time>
          <drake:mu_dynamic>{mu}</drake:mu_dynamic>
          <drake:mu_static>{mu}</drake:mu_static>
        </drake:proximity_properties>
      </collision>
    </link>
  </model>
</sdf>
"""


def primitive_sdf(p: Primitive) -> str:
    """The SDFormat text of primitive ``p`` (body ``base_link`` at the shape's centre)."""
    m = 1.0 if p.welded else p.mass  # a welded body's mass never matters
    if p.shape == "box":
        x, y, z = p.size
        geometry = f"<box><size>{x} {y} {z}</size></box>"
        ixx, iyy, izz = m * (y * y + z * z) / 12, m * (x * x + z * z) / 12, m * (x * x + y * y) / 12
        hint = ""
    else:
        r, h = p.size
        geometry = f"<cylinder><radius>{r}</radius><length>{h}</length></cylinder>"
        ixx = iyy = m * (3 * r * r + h * h) / 12
        izz = m * r * r / 2
        # A compliant cylinder needs a tessellation hint; a quarter radius is fine enough.
        hint = f"<drake:mesh_resolution_hint>{r / 4}</drake:mesh_resolution_hint>"
    if p.welded:
        hydro = "<drake:rigid_hydroelastic/>"
    else:
        hydro = (
            "<drake:compliant_hydroelastic/>"
            f"<drake:hydroelastic_modulus>1.0e7</drake:hydroelastic_modulus>{hint}"
        )
    return _TEMPLATE.format(
        name=p.name, mass=m, ixx=ixx, iyy=iyy, izz=izz, geometry=geometry,
        rgba=" ".join(str(c) for c in p.rgba), hydro=hydro, mu=p.friction,
    )


def add_primitive(plant: MultibodyPlant, p: Primitive):
    """Adds primitive ``p`` to the (unfinalized) plant: welded, or free at its default pose."""
    parser = configure_parser(Parser(plant))
    (instance,) = parser.AddModelsFromString(primitive_sdf(p), "sdf")
    body = plant.GetBodyByName("base_link", instance)
    X_WB = RigidTransform(RollPitchYaw(*p.rpy), p.xyz)
    if p.welded:
        plant.WeldFrames(plant.world_frame(), body.body_frame(), X_WB)
    else:
        plant.SetDefaultFloatingBaseBodyPose(body, X_WB)
    return instance

