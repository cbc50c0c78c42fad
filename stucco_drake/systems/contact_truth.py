"""Ground truth for scoring: which object a robot touches, and where, from contact results.

Two views of the simulated plant's own contact results, for any robot (the robot's model
instances and the objects' bodies are arguments; nothing here names our iiwa):

- :class:`RobotObjectContacts` (not a system): a
  :class:`~stucco_drake.systems.action_contacts_assembler.TruthLabeller` over the full plant
  state, asked once per completed action (the assembler's ``action_truth``).
- :class:`RobotContactTruth`: a LeafSystem with one vector per step (force, strongest contact,
  object), to log where per-step truth is needed (detection and isolation scores).

Units: m, N, world frame.
"""

from __future__ import annotations

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.multibody.plant import ContactResults, MultibodyPlant
from pydrake.multibody.tree import BodyIndex
from pydrake.systems.framework import Diagram, LeafSystem

from stucco_drake.systems.action_contacts_assembler import TruthContact, nearest_truth


def _geometry_owners(plant: MultibodyPlant, robot_instances, objects: dict):
    """(robot geometry ids, {geometry id: object name}) of ``plant``'s collision geometries."""
    names = {body.index(): name for name, body in objects.items()}
    robot, owners = set(), {}
    for i in range(plant.num_bodies()):
        body = plant.get_body(BodyIndex(i))
        for gid in plant.GetCollisionGeometriesForBody(body):
            if body.model_instance() in robot_instances:
                robot.add(gid)
            elif body.index() in names:
                owners[gid] = names[body.index()]
    return robot, owners


class RobotObjectContacts:
    """The robot's contacts with objects at a plant state, from the plant's contact results.

    :meth:`contacts` puts a state into a scratch context of ``diagram`` (the Diagram that holds
    ``plant``) and reads the plant's own contact results there, one :class:`TruthContact` per
    contact between a robot body and an object body (m, world; a hydroelastic surface's
    centroid or a point contact's point). Where the contacts are depends on the configuration
    alone, so the scratch context gives the same contacts as the simulation's own at that
    state; the assembler asks once per completed action, not every step.

    Args:
        plant: the simulated plant (robot and objects); ``diagram`` the Diagram holding it.
        robot_instances: the robot's model instances (its bodies' contacts count).
        objects: object name -> body (the names the truth reports).
    """

    def __init__(self, plant: MultibodyPlant, diagram: Diagram, robot_instances, objects: dict):
        self._robot_geometry, self._object_geometry = _geometry_owners(
            plant, set(robot_instances), objects)  # fmt: skip
        self._plant = plant
        self._context = diagram.CreateDefaultContext()
        self._plant_context = plant.GetMyMutableContextFromRoot(self._context)
        self.state_size = plant.num_multibody_states()

    def _pair(self, a, b) -> str | None:
        if a in self._robot_geometry:
            return self._object_geometry.get(b)
        if b in self._robot_geometry:
            return self._object_geometry.get(a)
        return None

    def contacts(self, plant_state) -> list[TruthContact]:
        """The robot-object contacts at ``plant_state`` (the plant's [q; v])."""
        self._plant.SetPositionsAndVelocities(self._plant_context, plant_state)
        results = self._plant.get_contact_results_output_port().Eval(self._plant_context)
        found = []
        for i in range(results.num_hydroelastic_contacts()):
            surface = results.hydroelastic_contact_info(i).contact_surface()
            name = self._pair(surface.id_M(), surface.id_N())
            if name is not None:
                found.append(TruthContact(name, np.array(surface.centroid())))
        for i in range(results.num_point_pair_contacts()):
            info = results.point_pair_contact_info(i)
            name = self._pair(info.point_pair().id_A, info.point_pair().id_B)
            if name is not None:
                found.append(TruthContact(name, np.array(info.contact_point())))
        return found

    def label(self, points, plant_state) -> tuple:
        """The true contact nearest each of ``points`` (n, 3) at ``plant_state``."""
        return nearest_truth(np.asarray(points, dtype=float), self.contacts(plant_state))


#: Layout of :class:`RobotContactTruth`'s ``truth`` vector.
TRUTH_FORCE, TRUTH_COUNT, TRUTH_STRONGEST = slice(0, 3), 3, 4
TRUTH_POINT, TRUTH_OBJECT, TRUTH_SIZE = slice(5, 8), 8, 9


class RobotContactTruth(LeafSystem):
    """Per-step ground truth from the simulation's own contact results.

    Input ``contact_results``: the plant's. Output ``truth`` (9,), laid out by the module's
    ``TRUTH_*`` slices: the total force the objects apply to the robot (3, N, world), the
    number of robot-object contacts, the strongest contact's force magnitude (N), its point
    (3, m, world: a hydroelastic centroid or a point contact's point; NaN without contact) and
    its object's index in ``objects`` (-1 without contact).

    Args:
        plant: the simulated plant; robot_instances: the robot's model instances;
        objects: object name -> body (their order gives the indices).
    """

    def __init__(self, plant: MultibodyPlant, robot_instances, objects: dict):
        super().__init__()
        self.object_names = list(objects)
        robot, owners = _geometry_owners(plant, set(robot_instances), objects)
        index = {name: k for k, name in enumerate(self.object_names)}
        self._robot = robot
        self._object = {gid: index[name] for gid, name in owners.items()}
        self._results = self.DeclareAbstractInputPort(
            "contact_results", AbstractValue.Make(ContactResults()))  # fmt: skip
        self.DeclareVectorOutputPort("truth", TRUTH_SIZE, self.calc_truth)

    def _on_robot(self, a, b, force):
        """(object index, force on the robot) of a pair whose ``force`` acts on ``a``."""
        if a in self._robot and b in self._object:
            return self._object[b], force
        if b in self._robot and a in self._object:
            return self._object[a], -force
        return None

    def calc_truth(self, context, output):
        results = self._results.Eval(context)
        found = []
        for i in range(results.num_hydroelastic_contacts()):
            info = results.hydroelastic_contact_info(i)
            surface = info.contact_surface()
            # F_Ac_W acts on the body of geometry M.
            pair = self._on_robot(surface.id_M(), surface.id_N(), info.F_Ac_W().translational())
            if pair is not None:
                found.append((*pair, np.array(surface.centroid())))
        for i in range(results.num_point_pair_contacts()):
            info = results.point_pair_contact_info(i)
            # contact_force() acts on body B.
            pair = self._on_robot(info.point_pair().id_B, info.point_pair().id_A,
                                  info.contact_force())  # fmt: skip
            if pair is not None:
                found.append((*pair, np.array(info.contact_point())))
        out = np.full(TRUTH_SIZE, np.nan)
        out[TRUTH_FORCE] = sum((f for _, f, _ in found), np.zeros(3))
        out[TRUTH_COUNT], out[TRUTH_STRONGEST], out[TRUTH_OBJECT] = len(found), 0.0, -1.0
        if found:
            k, f, p = max(found, key=lambda item: float(np.linalg.norm(item[1])))
            out[TRUTH_STRONGEST], out[TRUTH_POINT], out[TRUTH_OBJECT] = np.linalg.norm(f), p, k
        output.SetFromVector(out)


__all__ = ["TRUTH_SIZE", "RobotContactTruth", "RobotObjectContacts"]
