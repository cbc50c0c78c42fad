"""Where the bubble gripper can be touched: samples of its surface, and of its convex hull.

- :func:`gripper_collision_shapes`: the gripper's Drake proximity shapes in ``gripper_frame``.
- :func:`sample_gripper_surface`: area-uniform points and outward normals on them.
- :func:`reachable_samples`: which of those a ball of some radius can touch from outside.
- :func:`sample_hull_bridges`: the convex hull's faces where it spans the gripper's concavities.

All in ``gripper_frame`` (m; unit outward normals).
"""

from __future__ import annotations

import numpy as np
import trimesh
from pydrake.geometry import Box, Ellipsoid, Role, Sphere
from pydrake.multibody.parsing import Parser
from pydrake.multibody.plant import AddMultibodyPlantSceneGraph
from pydrake.systems.framework import DiagramBuilder
from scipy.spatial import ConvexHull, cKDTree

from stucco_drake.robot.models import (
    BUBBLE_GRIPPER_URL,
    FLANGE_TO_GRIPPER_FRAME_Z,
    configure_parser,
)

_INSIDE_TOLERANCE = 1e-4  # m: samples deeper than this inside another shape are hidden


# ------------------------------------------------------------------------------ surface samples

def _points_on_triangles(rng: np.random.Generator, triangles, n: int, p):
    """(face index (n,), points (n, 3)): n uniform points on ``triangles`` (m, 3, 3), each
    drawn in a face chosen with probability ``p`` (their areas over the total)."""
    a = triangles[:, 1] - triangles[:, 0]
    b = triangles[:, 2] - triangles[:, 0]
    face = rng.choice(len(triangles), size=n, p=p)
    u, v = rng.random(n), rng.random(n)
    flip = u + v > 1.0  # fold the square onto the triangle: uniform barycentrics
    u[flip], v[flip] = 1.0 - u[flip], 1.0 - v[flip]
    return face, triangles[face, 0] + u[:, None] * a[face] + v[:, None] * b[face]


def gripper_collision_shapes(opening: float = 0.03):
    """The gripper's proximity shapes in ``gripper_frame``: a list of (kind, dims, X_GS 4x4).

    kind is "box" (dims = full sizes, m) or "ellipsoid" (dims = semi-axes, m; spheres too).
    Both fingers are placed at ``opening`` (m, each finger joint's position).
    """
    builder = DiagramBuilder()
    plant, scene_graph = AddMultibodyPlantSceneGraph(builder, 0.0)
    (gripper,) = configure_parser(Parser(plant)).AddModels(url=BUBBLE_GRIPPER_URL)
    plant.WeldFrames(plant.world_frame(), plant.GetFrameByName("gripper_frame", gripper))
    for name in ("left_finger_joint", "right_finger_joint"):
        plant.GetJointByName(name, gripper).set_default_translation(float(opening))
    plant.Finalize()
    diagram = builder.Build()
    context = diagram.CreateDefaultContext()
    query = scene_graph.get_query_output_port().Eval(scene_graph.GetMyContextFromRoot(context))
    inspector = query.inspector()
    shapes = []
    for gid in inspector.GetAllGeometryIds(Role.kProximity):
        shape, X = inspector.GetShape(gid), query.GetPoseInWorld(gid).GetAsMatrix4()
        if isinstance(shape, Box):
            shapes.append(("box", np.array([shape.width(), shape.depth(), shape.height()]), X))
        elif isinstance(shape, Ellipsoid):
            shapes.append(("ellipsoid", np.array([shape.a(), shape.b(), shape.c()]), X))
        elif isinstance(shape, Sphere):
            shapes.append(("ellipsoid", np.full(3, shape.radius()), X))
        else:
            raise ValueError(f"{inspector.GetName(gid)}: cannot sample a {type(shape).__name__}")
    return shapes


def _inside(kind: str, dims, X, points) -> np.ndarray:
    """Depth-tolerant inside test of ``points`` (N, 3) in shape (kind, dims, X)."""
    local = (points - X[:3, 3]) @ X[:3, :3]
    if kind == "box":
        return np.all(np.abs(local) < dims / 2 - _INSIDE_TOLERANCE, axis=1)
    return np.sum((local / (dims - _INSIDE_TOLERANCE)) ** 2, axis=1) < 1.0


def sample_gripper_surface(rng: np.random.Generator, spacing: float = 0.004,
                           opening: float = 0.03, shapes=None):  # fmt: skip
    """Area-uniform samples (about one per ``spacing``^2 m^2) of the gripper's outer surface.

    Each shape is meshed with trimesh (ellipsoids from a subdivided icosphere, then pushed onto
    the exact surface), its faces are drawn in proportion to area and a uniform point is drawn
    in each. Samples hidden inside another shape (bubble halves in their plates) and on the
    palm's mounting face (against the flange) are dropped. Returns (points, normals), (N, 3)
    each, in ``gripper_frame`` (m; unit outward normals).
    """
    shapes = gripper_collision_shapes(opening) if shapes is None else shapes
    all_points, all_normals = [], []
    for kind, dims, X in shapes:
        if kind == "box":
            mesh = trimesh.creation.box(extents=dims)
        else:
            sphere = trimesh.creation.icosphere(subdivisions=4)
            mesh = trimesh.Trimesh(sphere.vertices * dims, sphere.faces)
        n = max(1, round(mesh.area / spacing**2))
        face, local = _points_on_triangles(rng, mesh.triangles, n, mesh.area_faces / mesh.area)
        if kind == "box":
            normal = mesh.face_normals[face]
        else:
            # Radially onto the exact ellipsoid; its normal is the gradient p / r^2.
            local = local / np.sqrt(np.sum((local / dims) ** 2, axis=1))[:, None]
            normal = local / dims**2
            normal /= np.linalg.norm(normal, axis=1, keepdims=True)
        all_points.append(local @ X[:3, :3].T + X[:3, 3])
        all_normals.append(normal @ X[:3, :3].T)
    points, normals = np.concatenate(all_points), np.concatenate(all_normals)
    shape_of = np.repeat(np.arange(len(shapes)), [len(p) for p in all_points])
    keep = np.ones(len(points), dtype=bool)
    for s, (kind, dims, X) in enumerate(shapes):
        keep &= ~((shape_of != s) & _inside(kind, dims, X, points))
    # The palm's top face is bolted to the flange: nothing can touch it.
    keep &= ~((np.abs(points[:, 2] + FLANGE_TO_GRIPPER_FRAME_Z) < 1e-6) & (normals[:, 2] < -0.9))
    return points[keep], normals[keep]


def reachable_samples(points, normals, radius: float, surface, tolerance: float = 1e-3):
    """Mask (N,) of the samples a ball of ``radius`` (m) can touch from outside the gripper.

    The ball touching a sample sits on its outward normal, centred at p + radius n; the sample
    is reachable when no point of ``surface`` ((M, 3), dense samples of the gripper's real
    surface, same frame) lies inside that ball by more than ``tolerance`` (m). It drops
    samples at the bottom of concavities narrower than the ball: the crevice between two
    closed bubbles, the corner where a bubble meets its plate. An object there would be
    touching the sides first, and a filter that may put the contact there explains a push on
    one finger's outside by the other finger's inner face (the same line of action): on the
    Drake BC scene, 4 of 30 contacts (seed 0) landed 5 cm off, in that crevice.
    """
    centres = np.asarray(points) + radius * np.asarray(normals)
    inside = cKDTree(surface).query_ball_point(centres, radius - tolerance, return_length=True)
    return inside == 0


def sample_hull_bridges(rng: np.random.Generator, spacing: float = 0.004,
                        opening: float = 0.03, shapes=None):  # fmt: skip
    """Area-uniform samples of the gripper's convex hull where it bridges the gripper's
    concavities, (points, normals) as :func:`sample_gripper_surface` (``gripper_frame``, m;
    unit outward normals).

    Why: a convex object pressed against the gripper across a concavity (the crevice between
    the two bubbles, the gap between open fingers, the step from palm to fingers) touches it
    at several places at once, e.g. a box face pushed by both fingers' sides. The wrench then
    defines only the centre of pressure, which lies between the touches, on the hull face
    that bridges them, and on the object's surface. Among the real surface's samples the
    filter finds none there and puts the contact in the crevice on the line of action,
    centimetres inside the object. Adding the bridging samples gives it the right answer.

    The hull is that of the shapes' mesh vertices (ellipsoids as in
    :func:`sample_gripper_surface`); its facets are drawn in proportion to area, with the
    facet normal; samples within ``spacing`` of the real surface (where the hull coincides with
    it) or on its top against the flange are dropped.
    """
    shapes = gripper_collision_shapes(opening) if shapes is None else shapes
    vertices = []
    for kind, dims, X in shapes:
        if kind == "box":
            local = trimesh.creation.box(extents=dims).vertices
        else:
            sphere = trimesh.creation.icosphere(subdivisions=4).vertices
            local = sphere * dims / np.sqrt(np.sum(sphere**2, axis=1))[:, None]
        vertices.append(local @ X[:3, :3].T + X[:3, 3])
    hull = ConvexHull(np.concatenate(vertices))
    tri = hull.points[hull.simplices]
    area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    n = max(1, round(area.sum() / spacing**2))
    face, points = _points_on_triangles(rng, tri, n, area / area.sum())
    normals = hull.equations[face, :3]
    surface, _ = sample_gripper_surface(rng, spacing / 2, opening, shapes)
    distance, _ = cKDTree(surface).query(points)
    # The flange covers the hull's top as it covers the palm's mounting face.
    mounting = (points[:, 2] < spacing - FLANGE_TO_GRIPPER_FRAME_Z) & (normals[:, 2] < -0.9)
    keep = (distance > spacing) & ~mounting
    return points[keep], normals[keep]
