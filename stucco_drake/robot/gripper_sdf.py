"""The soft-bubble gripper's signed-distance grid: the robot side of the tracker's pxpen.

Everything here is expressed in the gripper's ``gripper_frame`` (the grasp centre, 0.12 m out of
the flange, same axes as the flange), in metres, with the sign convention negative inside. The
distance is that of the union of the gripper's collision shapes (palm, backing plates, bubbles),
taken as the minimum over the shapes: exact outside and on the surface; inside, where shapes
overlap (bubble halves sunk into their plates), it is the depth inside the deepest single shape,
which may be less than the depth inside the union.

Sources of the distance:

- Boxes (and any other shape but the ellipsoid) come from Drake's
  ``QueryObject.ComputeSignedDistanceToPoint`` on a gripper-only scene.
- The bubbles are ellipsoids. Drake 1.51 answers point queries on ellipsoids with an iterative
  (GJK/EPA) estimate that is off by up to several millimetres near the bubble's tips, with the
  wrong sign just inside the surface, and costs about 60 us per point. So their proximity role is
  removed from the query scene and their distance is solved exactly here, in each bubble's frame
  taken from SceneGraph (its shape and pose follow the model file).

Nodes far outside the surface are not queried: they hold a lower bound of the true distance (see
:meth:`GripperDistance.banded`). Grids are cached on disk, keyed by the model files' bytes.
"""

from __future__ import annotations

import hashlib
import os
import re
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path

import numpy as np
from pydrake.geometry import Ellipsoid, Role
from pydrake.math import RigidTransform
from pydrake.multibody.parsing import Parser
from pydrake.multibody.plant import AddMultibodyPlantSceneGraph
from pydrake.systems.framework import DiagramBuilder

from stucco_drake.core.penetration import RobotPenetration
from stucco_drake.core.sdf import GridSdf
from stucco_drake.robot.models import BUBBLE_GRIPPER_URL, MODELS_DIR, PACKAGE_NAME, configure_parser

#: Bump when the way grids are computed changes, so that old cache files are not reused.
_ALGORITHM_VERSION = 1
#: Spacing (m) of the coarse lattice whose exact values bound the far nodes.
_COARSE_SPACING = 0.005
_FINGER_JOINTS = ("left_finger_joint", "right_finger_joint")


def default_cache_dir() -> Path:
    """``$STUCCO_DRAKE_CACHE/sdf`` if that variable is set, else ``~/.cache/stucco_drake/sdf``."""
    root = os.environ.get("STUCCO_DRAKE_CACHE")
    base = Path(root).expanduser() if root else Path.home() / ".cache" / "stucco_drake"
    return base / "sdf"


def _model_files(path: Path, seen: set[Path] | None = None) -> list[Path]:
    """``path`` and every model or mesh file it refers to, recursively."""
    seen = set() if seen is None else seen
    path = path.resolve()
    if path in seen:
        return []
    seen.add(path)
    files = [path]
    if path.suffix.lower() not in (".sdf", ".urdf", ".xml"):
        return files
    text = path.read_text()
    # SDFormat names included models and meshes in <uri>; URDF names meshes in filename="...".
    uris = re.findall(r"<uri>\s*([^<\s]+)\s*</uri>", text) + re.findall(
        r"filename\s*=\s*\"([^\"]+)\"", text
    )
    for uri in uris:
        package = f"package://{PACKAGE_NAME}/"
        if uri.startswith(package):
            target = MODELS_DIR / uri[len(package) :]
        elif "://" in uri:
            raise ValueError(f"{path.name}: cannot hash the model file behind {uri!r}")
        else:
            target = path.parent / uri
        files += _model_files(target, seen)
    return files


def gripper_model_hash() -> str:
    """SHA-256 of the bytes of the gripper's model file and of every file it includes."""
    digest = hashlib.sha256()
    root = MODELS_DIR / BUBBLE_GRIPPER_URL.split(f"package://{PACKAGE_NAME}/", 1)[1]
    for file in _model_files(root):
        digest.update(file.name.encode())
        digest.update(file.read_bytes())
    return digest.hexdigest()


def ellipsoid_signed_distance(points, radii) -> np.ndarray:
    """Exact signed distance (m, negative inside) of ``points[N, 3]`` to an origin-centred,
    axis-aligned ellipsoid with semi-axes ``radii`` (m), in the ellipsoid's frame.

    The nearest surface point is x_i = r_i^2 z_i / (r_i^2 + t) (z = |p| by symmetry), where t is
    the root above -r_min^2 of F(t) = sum (r_i z_i / (r_i^2 + t))^2 - 1. F is convex and
    decreasing there, and t0 = max_i (r_i z_i - r_i^2) has F(t0) >= 0, so Newton's method from
    t0 climbs to the root without overshooting. When a point sits on the smallest axis' mid-plane
    deep inside, F has no root and t = -r_min^2; the nearest point then leaves the mid-plane, and
    its coordinate along the smallest axis comes from the surface equation.
    """
    z = np.abs(np.asarray(points, dtype=np.float64).reshape(-1, 3)).T.copy()  # (3, N): columns
    r = np.asarray(radii, dtype=np.float64)
    k = int(np.argmin(r))
    rz, r2 = r[:, None] * z, (r * r)[:, None]
    t = np.maximum((rz - r2).max(axis=0), -r2[k, 0])
    index, t_active, rz_active = np.arange(z.shape[1]), t.copy(), rz
    for _ in range(100):
        denominator = np.maximum(r2 + t_active, 1e-300)
        q2 = (rz_active / denominator) ** 2
        f = q2.sum(axis=0) - 1.0
        slope = 2.0 * (q2 / denominator).sum(axis=0)  # -F'(t) > 0
        step = np.where(f > 0, f / np.maximum(slope, 1e-300), 0.0)
        t_active += step
        t[index] = t_active
        # A point is done once t moves by less than round-off: its distance is then exact.
        moving = step > 1e-15 * np.maximum(1.0, np.abs(t_active))
        if not moving.any():
            break
        if moving.mean() < 0.5:  # shrink the working set only when it pays for the copy
            index, t_active, rz_active = index[moving], t_active[moving], rz_active[:, moving]
    x = r2 * z / np.maximum(r2 + t, 1e-300)
    inside = np.sum((z / r[:, None]) ** 2, axis=0) < 1.0
    others = [a for a in range(3) if a != k]
    # Inside, take the smallest axis' coordinate from the surface equation: exact at the root and
    # right in the rootless case above, where the formula divides 0 by 0.
    rest = np.sum((x[others][:, inside] / r[others, None]) ** 2, axis=0)
    x[k, inside] = r[k] * np.sqrt(np.clip(1.0 - rest, 0.0, None))
    distance = np.linalg.norm(x - z, axis=0)
    return np.where(inside, -distance, distance)


class GripperDistance:
    """Signed distance (m, negative inside) to the bubble gripper, in ``gripper_frame``.

    Builds a gripper-only Drake scene: the gripper's ``gripper_frame`` welded to the world (so
    world coordinates are gripper-frame coordinates) and both fingers at ``opening``.

    Args:
        opening: each finger joint's position (m): the distance from the gripper's mid-plane to
            that bubble's inner apex, so the bubbles are 2 * opening apart. ``None`` takes the
            model's default finger positions (0 m, bubbles touching, in the current model).
    """

    def __init__(self, opening: float | None = None):
        builder = DiagramBuilder()
        plant, scene_graph = AddMultibodyPlantSceneGraph(builder, 0.0)
        (gripper,) = configure_parser(Parser(plant)).AddModels(url=BUBBLE_GRIPPER_URL)
        plant.WeldFrames(
            plant.world_frame(), plant.GetFrameByName("gripper_frame", gripper), RigidTransform()
        )
        joints = [plant.GetJointByName(name, gripper) for name in _FINGER_JOINTS]
        if opening is None:
            defaults = {j.get_default_translation() for j in joints}
            if len(defaults) != 1:
                raise ValueError(f"finger defaults differ ({defaults}): pass an opening")
            opening = defaults.pop()
        opening = float(opening)
        for joint in joints:
            lo, hi = joint.position_lower_limit(), joint.position_upper_limit()
            if not lo <= opening <= hi:
                raise ValueError(f"opening {opening} m outside {joint.name()} limits [{lo}, {hi}]")
            joint.set_default_translation(opening)
        plant.Finalize()
        self.opening = opening
        self._diagram = builder.Build()
        context = self._diagram.CreateDefaultContext()
        sg_context = scene_graph.GetMyContextFromRoot(context)
        query = scene_graph.get_query_output_port().Eval(sg_context)
        inspector = query.inspector()
        ids = inspector.GetAllGeometryIds(Role.kProximity)
        lows, highs = [], []
        #: (X_FG as a 3x3 rotation, centre (3,), radii (3,)) of each bubble in gripper_frame.
        self.ellipsoids: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []
        for gid in ids:
            obb = inspector.GetObbInGeometryFrame(gid)
            if obb is None:
                raise ValueError(f"{inspector.GetName(gid)}: unbounded shape, cannot be gridded")
            X_FB = query.GetPoseInWorld(gid).multiply(obb.pose())
            half = np.abs(X_FB.rotation().matrix()) @ obb.half_width()
            lows.append(X_FB.translation() - half)
            highs.append(X_FB.translation() + half)
            shape = inspector.GetShape(gid)
            if isinstance(shape, Ellipsoid):
                X_FG = query.GetPoseInWorld(gid)
                radii = np.array([shape.a(), shape.b(), shape.c()])
                self.ellipsoids.append((X_FG.rotation().matrix(), X_FG.translation(), radii))
                # Drake's own ellipsoid answer is replaced by the exact one (module docstring).
                scene_graph.RemoveRole(sg_context, plant.get_source_id(), gid, Role.kProximity)
        self.lower, self.upper = np.min(lows, axis=0), np.max(highs, axis=0)
        self._query = scene_graph.get_query_output_port().Eval(sg_context)
        self._n_drake = len(ids) - len(self.ellipsoids)
        # Drake silently skips shapes it cannot measure: make sure every one answers.
        answered = len(self._query.ComputeSignedDistanceToPoint(np.zeros(3)))
        if answered != self._n_drake:
            raise RuntimeError(f"Drake measured {answered} of {self._n_drake} gripper shapes")

    def description(self) -> str:
        """What the distance depends on, for cache keys: model bytes, opening, code versions."""
        try:
            drake = version("drake")
        except PackageNotFoundError:  # a Drake not installed from a wheel
            drake = "unknown"
        return (
            f"bubble_gripper model={gripper_model_hash()} opening={self.opening!r} "
            f"algorithm={_ALGORITHM_VERSION} coarse={_COARSE_SPACING!r} drake={drake}"
        )

    def drake_distance(self, points, threshold: float = np.inf) -> np.ndarray:
        """Min over Drake's shapes of the signed distance (m) at ``points[N, 3]``, one query each.

        With a finite ``threshold``, shapes farther than it may be skipped, so a value above
        ``threshold`` (or ``inf`` when none is near) only says the distance exceeds it.
        """
        points = np.ascontiguousarray(np.asarray(points, dtype=np.float64).reshape(-1, 3))
        if self._n_drake == 0:
            return np.full(len(points), np.inf)
        query = self._query.ComputeSignedDistanceToPoint  # bound once: the loop is the cost
        return np.array(
            [min((r.distance for r in query(p, threshold)), default=np.inf) for p in points]
        )

    def ellipsoid_distance(self, points, band: float = np.inf) -> np.ndarray:
        """Min over the bubbles of the signed distance (m) at ``points[N, 3]``.

        Exact where below ``band`` (m); elsewhere the distance to the bubble's bounding box, a
        lower bound of at least ``band``, which saves solving for points far from a bubble.
        """
        points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        result = np.full(len(points), np.inf)
        for rotation, centre, radii in self.ellipsoids:
            local = (points - centre) @ rotation  # p_G = R_FG^T (p_F - p_FG), row-wise
            # The bounding box contains the bubble, so it is nearer to any point outside it.
            bound = np.linalg.norm(np.maximum(np.abs(local) - radii, 0.0), axis=1)
            near = bound < band
            bound[near] = ellipsoid_signed_distance(local[near], radii)
            np.minimum(result, bound, out=result)
        return result

    def __call__(self, points) -> np.ndarray:
        """Signed distance (m, negative inside) of the gripper at ``points[N, 3]``, every shape
        measured at every point: the reference the grid is checked against."""
        return np.minimum(self.drake_distance(points), self.ellipsoid_distance(points))

    def banded(self, axes, band: float) -> np.ndarray:
        """Distance at the nodes of the grid ``axes`` (3 increasing 1-D arrays, m), (nx, ny, nz).

        Exact (as :meth:`__call__`) at every node where the distance is below ``band`` (m), so at
        every node inside; elsewhere a lower bound that is at least ``band``. Drake is queried on
        a coarse lattice first, then only at the nodes that the lattice cannot rule out: Drake's
        part d is 1-Lipschitz, so at a node p it is at least L(p) = max over the corners c of p's
        coarse cell of d(c) - |p - c|, and where L(p) >= min(bubble distance, band) a query
        cannot lower the result below ``band``.
        """
        shape = tuple(len(a) for a in axes)
        grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1)
        ellipsoid = self.ellipsoid_distance(grid.reshape(-1, 3), band).reshape(shape)
        picks, ends, offsets = [], [], []  # per axis: coarse nodes, each node's cell, offsets
        for a, n in enumerate(shape):
            step = max(1, round(_COARSE_SPACING / (axes[a][1] - axes[a][0])))
            pick = np.unique(np.r_[np.arange(0, n, step), n - 1])
            cell = np.clip(np.searchsorted(pick, np.arange(n), side="right") - 1, 0, len(pick) - 2)
            picks.append(pick)
            ends.append((cell, cell + 1))
            offsets.append([axes[a] - axes[a][pick[e]] for e in (cell, cell + 1)])
        coarse_shape = tuple(len(p) for p in picks)
        coarse = self.drake_distance(grid[np.ix_(*picks)].reshape(-1, 3)).reshape(coarse_shape)
        lower = np.full(shape, -np.inf)
        for corner in np.ndindex(2, 2, 2):
            dx, dy, dz = (offsets[a][corner[a]] for a in range(3))
            reach = np.sqrt(dx[:, None, None] ** 2 + dy[None, :, None] ** 2 + dz[None, None] ** 2)
            values = coarse[np.ix_(*(ends[a][corner[a]] for a in range(3)))]
            np.maximum(lower, values - reach, out=lower)
        drake = lower.copy()  # the bound stands wherever no query is needed
        need = lower < np.minimum(ellipsoid, band)
        measured = self.drake_distance(grid[need], threshold=band)
        # Above the threshold Drake may have skipped a nearer shape: keep only the bound then.
        drake[need] = np.where(measured <= band, measured, np.maximum(lower[need], band))
        return np.minimum(ellipsoid, drake)


def _grid_axes(nodes: np.ndarray):
    """The three axes of a meshgrid-ordered (ij) node list, or None if it is not one."""
    axes = [np.unique(nodes[:, a]) for a in range(3)]
    if np.prod([len(a) for a in axes]) != len(nodes) or min(len(a) for a in axes) < 2:
        return None
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    return axes if np.array_equal(grid, nodes) else None


def gripper_grid_sdf(
    resolution: float = 0.002,
    opening: float | None = None,
    cache_dir: str | Path | None = None,
    margin: float = 0.01,
    band: float | None = None,
) -> GridSdf:
    """The gripper's signed-distance grid in ``gripper_frame`` (m, negative inside), cached.

    Args:
        resolution: node spacing (m).
        opening: each finger's joint position (m; see :class:`GripperDistance`); ``None`` = the
            model's default (0 m, bubbles touching).
        cache_dir: where grids are kept; default :func:`default_cache_dir`.
        margin: the grid box is the gripper's bounding box grown by this much (m) on each side;
            beyond it lookups give ``+inf`` (no contact).
        band: nodes closer than this (m) to the surface, and all nodes inside, hold the exact
            distance; farther ones a lower bound of at least ``band``. Default max(5 mm, 3 cells).

    The cache file is keyed by a hash of the gripper's model files, the opening, the box, the
    resolution, the band and the code and Drake versions: change any one and it is rebuilt.
    """
    band = max(0.005, 3.0 * resolution) if band is None else float(band)
    distance = GripperDistance(opening)
    lower, upper = distance.lower - margin, distance.upper + margin

    def evaluate(nodes: np.ndarray) -> np.ndarray:
        axes = _grid_axes(nodes)
        if axes is None:  # not a regular grid: no coarse lattice to bound with
            return distance(nodes)
        return distance.banded(axes, band).reshape(-1)

    return GridSdf.load_or_build(
        evaluate,
        lower,
        upper,
        resolution,
        source_description=f"{distance.description()} band={band!r}",
        cache_dir=default_cache_dir() if cache_dir is None else cache_dir,
    )


def gripper_penetration(
    resolution: float = 0.002,
    opening: float | None = None,
    cache_dir: str | Path | None = None,
    **grid_options,
) -> RobotPenetration:
    """pxpen for the bubble gripper: a :class:`RobotPenetration` on :func:`gripper_grid_sdf`.

    Its end-effector frame E is ``gripper_frame``; depths are in metres.
    """
    return RobotPenetration(gripper_grid_sdf(resolution, opening, cache_dir, **grid_options))
