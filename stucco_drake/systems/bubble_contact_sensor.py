"""Soft-bubble contact sensing from the simulated plant's hydroelastic contact surfaces.

On the real robot each bubble's depth camera measures the membrane's imprint; a contact is
reported when enough of it is deformed, at the mean of the deformed pixels (paper Sec. V-E). In
simulation the bubble is a compliant-hydroelastic ellipsoid, and its imprint is the contact
surface Drake computes against whatever it touches. This system reports, per bubble, the
pressure-weighted centroid of that surface when the bubble's penetration (the deepest point of
the surface inside the undeformed ellipsoid) exceeds a threshold.
"""

from __future__ import annotations

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.geometry import Ellipsoid, SceneGraph
from pydrake.math import RigidTransform
from pydrake.multibody.plant import ContactResults, MultibodyPlant
from pydrake.systems.framework import LeafSystem

from stucco_drake.robot.gripper_sdf import ellipsoid_signed_distance


def _surface_moments(surface):
    """Pressure-weighted centroid (world, m), total pressure x area (N) and vertices (world, m)
    of a hydroelastic contact surface, from its faces' centroids, areas and mid-face pressures
    (for a linear field the mean over a face)."""
    if surface.is_triangle():
        mesh, field = surface.tri_mesh_W(), surface.tri_e_MN()
    else:
        mesh, field = surface.poly_mesh_W(), surface.poly_e_MN()
    n = mesh.num_elements()
    centroids = np.array([mesh.element_centroid(e) for e in range(n)]).reshape(n, 3)
    weights = np.array(
        [mesh.area(e) * max(field.EvaluateCartesian(e, centroids[e]), 0.0) for e in range(n)]
    )
    vertices = np.array([mesh.vertex(v) for v in range(mesh.num_vertices())]).reshape(-1, 3)
    total = weights.sum()
    if total <= 0.0:
        return centroids.mean(axis=0), 0.0, vertices
    return weights @ centroids / total, total, vertices


class BubbleContactSensor(LeafSystem):
    """Contact point per soft bubble, from the plant's contact results.

    The bubbles are the ellipsoid collision geometries of the caller's ``bodies`` (the robot's
    tactile links, e.g. a bubble gripper's two fingers), in that order. Per update (every
    ``time_step`` s), for each bubble: its hydroelastic contact surfaces are gathered; its
    penetration is the largest depth of their vertices inside the undeformed ellipsoid (exact
    ellipsoid distance); when that exceeds ``deformation_threshold`` (m) the bubble fires, at
    the pressure-weighted centroid of its surfaces (several surfaces are merged by their
    pressure x area). A bubble in point contact (hydroelastic fallback) uses the point pair's
    contact point and depth.

    Noise (optional): Gaussian noise of std ``noise_std`` (m) on each reported point, drawn from
    numpy Generators keyed by (``noise_seed``, update count).

    Args:
        plant, scene_graph: the simulated plant (robot and objects) and its SceneGraph.
        time_step: update period (s); use the plant's time step.
        bodies: the plant's bodies whose ellipsoid collision geometries are bubbles.

    Input ports:
        contact_results: the plant's ``ContactResults`` (``get_contact_results_output_port``).
        body_poses: the plant's body poses (``get_body_poses_output_port``), for the bubbles'
            current poses.

    Output ports (from discrete state; no direct feedthrough):
        bubble_in_contact: (n,) 1.0 for each bubble that fires.
        bubble_contact_points: (3 n,) each bubble's point in world (m), zeros when not firing.
        bubble_penetration: (n,) each bubble's penetration (m), 0 without contact.
    """

    def __init__(self, plant: MultibodyPlant, scene_graph: SceneGraph, time_step: float,
                 bodies, *, deformation_threshold: float = 1e-3, noise_std: float = 0.0,
                 noise_seed: int | None = None):  # fmt: skip
        super().__init__()
        if noise_std < 0 or (noise_std > 0 and noise_seed is None):
            raise ValueError("BubbleContactSensor: noise_std must be >= 0; noise needs a seed")
        inspector = scene_graph.model_inspector()
        bubbles = []
        for body in bodies:
            body_index = body.index()
            for gid in plant.GetCollisionGeometriesForBody(body):
                shape = inspector.GetShape(gid)
                if isinstance(shape, Ellipsoid):
                    radii = np.array([shape.a(), shape.b(), shape.c()])
                    X_BG = inspector.GetPoseInFrame(gid)
                    bubbles.append((gid, int(body_index), X_BG, radii, body.name()))
        if not bubbles:
            names = [body.name() for body in bodies]
            raise ValueError(f"BubbleContactSensor: no ellipsoid geometry on bodies {names}")
        self.bubble_names = [b[4] for b in bubbles]
        self.num_bubbles = len(bubbles)
        self._bubbles = bubbles
        self._index = {b[0]: i for i, b in enumerate(bubbles)}
        self._threshold = float(deformation_threshold)
        self._noise_std, self._noise_seed = float(noise_std), noise_seed
        n = len(bubbles)
        self._results = self.DeclareAbstractInputPort(
            "contact_results", AbstractValue.Make(ContactResults())
        )
        self._poses = self.DeclareAbstractInputPort(
            "body_poses", AbstractValue.Make([RigidTransform()])
        )
        # State: [update count, flags (n), points (3n), penetrations (n)].
        self._xd = self.DeclareDiscreteState(1 + 5 * n)
        self._n = n
        self._parts = {"bubble_in_contact": slice(1, 1 + n),
                       "bubble_contact_points": slice(1 + n, 1 + 4 * n),
                       "bubble_penetration": slice(1 + 4 * n, 1 + 5 * n)}  # fmt: skip
        for name, calc in (
            ("bubble_in_contact", self.calc_bubble_in_contact),
            ("bubble_contact_points", self.calc_bubble_contact_points),
            ("bubble_penetration", self.calc_bubble_penetration),
        ):
            part = self._parts[name]
            self.DeclareVectorOutputPort(name, part.stop - part.start, calc,
                                         prerequisites_of_calc={self.xd_ticket()})  # fmt: skip
        self.DeclarePeriodicDiscreteUpdateEvent(time_step, 0.0, self._update)

    def _state_part(self, context, name: str) -> np.ndarray:
        return context.get_discrete_state(self._xd).get_value()[self._parts[name]]

    def calc_bubble_in_contact(self, context, output):
        output.SetFromVector(self._state_part(context, "bubble_in_contact"))

    def calc_bubble_contact_points(self, context, output):
        output.SetFromVector(self._state_part(context, "bubble_contact_points"))

    def calc_bubble_penetration(self, context, output):
        output.SetFromVector(self._state_part(context, "bubble_penetration"))

    def measure(self, results: ContactResults, poses) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(penetration (n,), point (n, 3), pressure x area (n,)) of each bubble, no noise.

        ``poses`` returns the plant's body poses (list by BodyIndex); it is called only when a
        bubble has a hydroelastic contact (most steps have none)."""
        n = self._n
        depth, moment, weight = np.zeros(n), np.zeros((n, 3)), np.zeros(n)
        body_poses = None
        for i in range(results.num_hydroelastic_contacts()):
            surface = results.hydroelastic_contact_info(i).contact_surface()
            for gid in (surface.id_M(), surface.id_N()):
                b = self._index.get(gid)
                if b is None:
                    continue
                _, body, X_BG, radii, _ = self._bubbles[b]
                if body_poses is None:
                    body_poses = poses()
                centroid, total, vertices = _surface_moments(surface)
                X_GW = body_poses[body].multiply(X_BG).inverse()
                local = vertices @ X_GW.rotation().matrix().T + X_GW.translation()
                depth[b] = max(depth[b], -ellipsoid_signed_distance(local, radii).min())
                # A surface with no pressure still counts, with a token weight.
                w = max(total, 1e-12)
                moment[b] += w * centroid
                weight[b] += w
        for i in range(results.num_point_pair_contacts()):
            info = results.point_pair_contact_info(i)
            pair = info.point_pair()
            for gid in (pair.id_A, pair.id_B):
                b = self._index.get(gid)
                if b is not None and pair.depth > depth[b]:
                    depth[b] = pair.depth
                    w = max(np.linalg.norm(info.contact_force()), 1e-12)
                    moment[b] += w * info.contact_point()
                    weight[b] += w
        points = np.where(weight[:, None] > 0, moment / np.maximum(weight, 1e-300)[:, None], 0.0)
        return depth, points, weight

    def _update(self, context, discrete_state):
        old = context.get_discrete_state(self._xd).get_value()
        step = int(old[0]) + 1
        depth, points, _ = self.measure(self._results.Eval(context),
                                        lambda: self._poses.Eval(context))
        fires = depth > self._threshold
        if self._noise_std > 0:
            rng = np.random.default_rng([self._noise_seed, step])
            points = points + self._noise_std * rng.standard_normal(points.shape)
        points[~fires] = 0.0
        new = np.concatenate([[step], fires.astype(float), points.ravel(), depth])
        discrete_state.get_mutable_vector(self._xd).SetFromVector(new)


__all__ = ["BubbleContactSensor"]
