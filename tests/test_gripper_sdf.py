"""The gripper's signed-distance grid against direct distance queries, and its disk cache.

Grids here are coarse (4-5 mm) so that the whole file runs in a few seconds.
"""

import re
import shutil

import numpy as np
import pytest
from pydrake.geometry import Ellipsoid
from pydrake.math import RigidTransform
from pydrake.multibody.plant import AddMultibodyPlantSceneGraph, CoulombFriction
from pydrake.multibody.tree import SpatialInertia
from pydrake.systems.framework import DiagramBuilder

import stucco_drake.robot.gripper_sdf as gripper_sdf
from stucco_drake.core import GridSdf, RobotPenetration
from stucco_drake.robot.gripper_sdf import (
    GripperDistance,
    _model_files,
    default_cache_dir,
    ellipsoid_signed_distance,
    gripper_grid_sdf,
    gripper_model_hash,
    gripper_penetration,
)
from stucco_drake.robot.models import MODELS_DIR

RESOLUTION = 0.004
BAND = max(0.005, 3 * RESOLUTION)  # gripper_grid_sdf's default band at this resolution
RADII = np.array([0.02, 0.04, 0.055])  # the bubble's semi-axes in the model file


@pytest.fixture(scope="module")
def reference() -> GripperDistance:
    return GripperDistance()


@pytest.fixture(scope="module")
def grid(tmp_path_factory) -> GridSdf:
    return gripper_grid_sdf(RESOLUTION, cache_dir=tmp_path_factory.mktemp("sdf"))


def test_grid_matches_direct_queries_within_half_a_cell(grid, reference):
    rng = np.random.default_rng(7)
    points = rng.uniform(grid.lower, grid.upper, size=(500, 3))
    exact, looked_up = reference(points), grid(points)
    # Where every corner of the point's cell is within the exact band, trilinear interpolation
    # of exact node values is off by at most half a cell (at kinks of the distance); the 1e-6 m
    # covers the float32 node storage.
    near = exact < BAND - np.sqrt(3) * RESOLUTION
    assert near.sum() > 200 and (exact < 0).sum() > 50
    assert np.max(np.abs(looked_up - exact)[near]) <= RESOLUTION / 2 + 1e-6
    # Farther out, nodes hold lower bounds of at least the band: never much above the truth.
    far = ~near
    assert np.all(looked_up[far] <= exact[far] + RESOLUTION / 2 + 1e-6)
    assert np.all(looked_up[far] >= np.minimum(exact[far], BAND) - np.sqrt(3) * RESOLUTION)


def test_nodes_are_exact_near_the_surface_and_inside(grid, reference):
    axes = [grid.lower[a] + grid.resolution * np.arange(grid.shape[a]) for a in range(3)]
    nodes = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    exact, stored = reference(nodes), grid.values.reshape(-1)
    near = exact < BAND
    np.testing.assert_allclose(stored[near], exact[near], atol=1e-6)  # float32 storage
    assert np.all(stored[~near] >= BAND - 1e-6) and np.all(stored <= exact + 1e-6)


def test_sign_inside_bubbles_and_well_outside(grid, reference):
    centres = np.array([centre for _, centre, _ in reference.ellipsoids])
    np.testing.assert_allclose(np.abs(centres[:, 0]), reference.opening + 0.02)
    assert np.all(grid(centres) < -0.015)  # 2 cm deep at the centre, less one cell of error
    corners = np.array(np.meshgrid(*zip(grid.lower, grid.upper, strict=True))).reshape(3, -1).T
    inset = corners + np.sign(grid.lower + grid.upper - 2 * corners) * 1e-3
    assert np.all(grid(inset) > 0.005)
    assert np.all(np.isinf(grid(grid.upper + 0.05)))


def test_ellipsoid_distance_is_exact():
    # Closed-form cases: the centre, points out along each axis, a point on the surface.
    points = np.array([[0, 0, 0], [0.05, 0, 0], [0, -0.07, 0], [0, 0, 0.1], [0.02, 0, 0]])
    np.testing.assert_allclose(
        ellipsoid_signed_distance(points, RADII), [-0.02, 0.03, 0.03, 0.045, 0.0], atol=1e-12
    )
    # Against a densely sampled surface: the true distance is at most the sampled one, barely.
    rng = np.random.default_rng(3)
    directions = rng.normal(size=(200_000, 3))
    surface = directions / np.linalg.norm(directions, axis=1, keepdims=True) * RADII
    points = rng.uniform(-0.07, 0.07, size=(200, 3))
    points[:40, 0] = 0.0  # on the thin axis' mid-plane, where the root-finding degenerates
    sampled = np.array([np.min(np.linalg.norm(surface - p, axis=1)) for p in points])
    computed = ellipsoid_signed_distance(points, RADII)
    inside = np.sum((points / RADII) ** 2, axis=1) < 1
    np.testing.assert_array_equal(computed < 0, inside)
    assert np.all(np.abs(computed) <= sampled + 1e-12)
    assert np.all(sampled - np.abs(computed) < 5e-4)


def test_ellipsoid_distance_agrees_with_drake_away_from_its_weak_spots():
    """Drake's ellipsoid point query is iterative; it agrees with ours for typical points."""
    builder = DiagramBuilder()
    plant, scene_graph = AddMultibodyPlantSceneGraph(builder, 0.0)
    body = plant.AddRigidBody("bubble", SpatialInertia.SolidSphereWithMass(0.1, 0.05))
    plant.RegisterCollisionGeometry(
        body, RigidTransform(), Ellipsoid(*RADII), "bubble", CoulombFriction(1, 1)
    )
    plant.WeldFrames(plant.world_frame(), body.body_frame())
    plant.Finalize()
    diagram = builder.Build()
    context = scene_graph.GetMyContextFromRoot(diagram.CreateDefaultContext())
    query = scene_graph.get_query_output_port().Eval(context)
    points = np.random.default_rng(5).uniform(-0.07, 0.07, size=(300, 3))
    drake = np.array([query.ComputeSignedDistanceToPoint(p)[0].distance for p in points])
    assert np.median(np.abs(drake - ellipsoid_signed_distance(points, RADII))) < 1e-5


def test_cache_loads_and_rebuilds_on_a_changed_key(tmp_path, monkeypatch):
    builds = []
    original = GridSdf.build.__func__

    def counting_build(cls, *args, **kwargs):
        builds.append(args[3])  # the resolution
        return original(cls, *args, **kwargs)

    monkeypatch.setattr(GridSdf, "build", classmethod(counting_build))
    first = gripper_grid_sdf(0.005, cache_dir=tmp_path)
    again = gripper_grid_sdf(0.005, cache_dir=tmp_path)
    assert len(builds) == 1 and len(list(tmp_path.glob("*.npz"))) == 1
    np.testing.assert_array_equal(first.values, again.values)
    assert first.key == again.key
    wider = gripper_grid_sdf(0.005, opening=0.03, cache_dir=tmp_path)
    finer = gripper_grid_sdf(0.0045, cache_dir=tmp_path)
    assert len(builds) == 3 and len({first.key, wider.key, finer.key}) == 3
    assert wider.upper[0] - wider.lower[0] > first.upper[0] - first.lower[0] + 0.05
    # Under the environment variable's cache root, nothing is found: it builds again.
    monkeypatch.setenv("STUCCO_DRAKE_CACHE", str(tmp_path / "root"))
    assert default_cache_dir() == tmp_path / "root" / "sdf"
    gripper_grid_sdf(0.005)
    assert len(builds) == 4 and len(list((tmp_path / "root" / "sdf").glob("*.npz"))) == 1


def test_model_files_follow_includes_and_meshes(tmp_path):
    (tmp_path / "top.sdf").write_text("<sdf><include><uri>part.urdf</uri></include></sdf>")
    (tmp_path / "part.urdf").write_text('<robot><mesh filename="shell.obj"/></robot>')
    (tmp_path / "shell.obj").write_text("v 0 0 0")
    files = _model_files(tmp_path / "top.sdf")
    assert [f.name for f in files] == ["top.sdf", "part.urdf", "shell.obj"]


def test_model_hash_follows_the_model_bytes_not_their_location(tmp_path, monkeypatch):
    """The grid cache's key holds this hash, so it must change with any byte of the gripper's
    model or of a file the model includes, and only with those: not with where the files lie
    (a clone elsewhere shares the cache) nor with model files the gripper does not use."""
    original = gripper_model_hash()
    assert re.fullmatch("[0-9a-f]{64}", original)  # a SHA-256 in hex
    copy = tmp_path / "models"
    shutil.copytree(MODELS_DIR, copy)
    monkeypatch.setattr(gripper_sdf, "MODELS_DIR", copy)
    assert gripper_model_hash() == original  # the same bytes elsewhere
    model = copy / "bubble_gripper" / "bubble_gripper.sdf"
    text = model.read_text()
    radii = "<radii>0.02 0.04 0.055</radii>"
    assert text.count(radii) == 4  # the four bubble halves
    model.write_text(text.replace(radii, "<radii>0.021 0.04 0.055</radii>", 1))  # 1 mm thicker
    edited = gripper_model_hash()
    assert edited != original
    assert f"model={edited} " in GripperDistance().description()  # what keys the grid cache
    # A file the model includes counts as the model: change only it and the hash changes.
    part = copy / "bubble_gripper" / "part.sdf"
    part.write_text('<sdf version="1.9"><model name="part"/></sdf>')
    model.write_text(text.replace("</sdf>", "<include><uri>part.sdf</uri></include></sdf>"))
    with_part = gripper_model_hash()
    assert with_part != original
    part.write_text('<sdf version="1.9"><model name="part2"/></sdf>')
    assert gripper_model_hash() not in (with_part, original)
    # Back to the original bytes: the original hash, whatever other model files say.
    model.write_text(text)
    (copy / "table.sdf").write_text((copy / "table.sdf").read_text() + "<!-- edited -->\n")
    assert gripper_model_hash() == original


def test_opening_outside_the_finger_limits_is_refused():
    with pytest.raises(ValueError, match="outside"):
        GripperDistance(0.06)  # beyond the finger joints' 0.055 m limit


def test_penetration_of_a_bubble_centre(tmp_path):
    penetration = gripper_penetration(0.005, cache_dir=tmp_path)
    assert isinstance(penetration, RobotPenetration)
    # Gripper at the world origin: the right bubble's centre is 2 cm deep, far points are free.
    depth = penetration(np.zeros(3), np.array([[0.02, 0.0, 0.0], [0.5, 0.0, 0.0]]))
    assert depth[0] == pytest.approx(0.02, abs=0.0025) and depth[1] == 0.0
