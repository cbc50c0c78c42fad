"""A signed-distance field sampled on a voxel grid, with trilinear lookups and a disk cache."""

from __future__ import annotations

import hashlib
import json
from collections.abc import Callable
from pathlib import Path

import numpy as np
from scipy.spatial import ConvexHull

from stucco_drake.core.npz import save_npz_atomically

#: Version of the ``.npz`` layout; a cache file of another version is rebuilt.
_FORMAT_VERSION = 1


class GridSdf:
    """Signed distance (metres, negative inside) sampled at the nodes of a regular grid.

    Node (i, j, k) sits at ``lower + resolution * (i, j, k)``, in whatever frame the source
    function used (for the robot: the end-effector frame). Lookups interpolate trilinearly; a
    point outside the grid is taken to be far outside the object and gets ``+inf`` (gradient 0),
    so the grid must be built over a box that encloses the object with some margin.

    Args:
        lower: (3,) the first node's position (m).
        resolution: node spacing (m).
        values: (nx, ny, nz) signed distances at the nodes (m).
        key: a content hash of what the grid was built from, kept for cache checks.
    """

    def __init__(self, lower, resolution: float, values, key: str = ""):
        values = np.asarray(values, dtype=np.float32)
        if values.ndim != 3 or min(values.shape) < 2:
            raise ValueError(
                f"GridSdf values: expected (nx, ny, nz) with each >= 2, got {values.shape}"
            )
        if not np.all(np.isfinite(values)):
            raise ValueError("GridSdf values: contain NaN or infinite entries")
        if not (np.isfinite(resolution) and resolution > 0):
            raise ValueError(f"GridSdf resolution: must be positive, got {resolution!r}")
        self.lower = np.asarray(lower, dtype=np.float64).reshape(3)
        self.resolution = float(resolution)
        self.values = np.ascontiguousarray(values)
        self.key = key
        self.shape = np.array(values.shape)
        self.upper = self.lower + self.resolution * (self.shape - 1)
        # Flat strides of the node array, for gathering the 8 corners with one index each.
        self._strides = np.array([values.shape[1] * values.shape[2], values.shape[2], 1])
        self._flat = self.values.ravel()
        self._bounds_cache: dict[float, tuple[np.ndarray, np.ndarray]] = {}
        self._hull_planes: np.ndarray | None = None

    # ----------------------------------------------------------------------------- construction
    @classmethod
    def build(
        cls,
        signed_distance: Callable[[np.ndarray], np.ndarray],
        lower,
        upper,
        resolution: float,
        key: str = "",
    ) -> GridSdf:
        """Sample ``signed_distance(points[N, 3]) -> [N]`` at every node of the box [lower, upper].

        The grid covers at least the box: its far corner is rounded up to a whole number of cells.
        """
        lower = np.asarray(lower, dtype=np.float64)
        upper = np.asarray(upper, dtype=np.float64)
        if np.any(upper <= lower):
            raise ValueError(
                f"GridSdf.build: upper {upper} must exceed lower {lower} on every axis"
            )
        counts = np.ceil((upper - lower) / resolution - 1e-9).astype(int) + 1
        axes = [lower[a] + resolution * np.arange(counts[a]) for a in range(3)]
        nodes = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
        values = np.asarray(signed_distance(nodes), dtype=np.float64).reshape(tuple(counts))
        return cls(lower, resolution, values, key=key)

    @staticmethod
    def content_key(source_description: str, lower, upper, resolution: float) -> str:
        """Hash of what defines a grid: the source's description, its box and its resolution."""
        payload = json.dumps(
            {
                "source": source_description,
                "lower": [round(float(v), 9) for v in lower],
                "upper": [round(float(v), 9) for v in upper],
                "resolution": round(float(resolution), 9),
                "format": _FORMAT_VERSION,
            },
            sort_keys=True,
        )
        return hashlib.sha256(payload.encode()).hexdigest()[:24]

    @classmethod
    def load_or_build(
        cls,
        signed_distance: Callable[[np.ndarray], np.ndarray],
        lower,
        upper,
        resolution: float,
        source_description: str,
        cache_dir: str | Path,
    ) -> GridSdf:
        """Load ``<cache_dir>/<content key>.npz`` if present, else build it and save it there.

        ``source_description`` must change whenever the geometry does (for a robot model: a hash
        of its model files), since it is the only thing that tells two cached grids apart.
        """
        key = cls.content_key(source_description, lower, upper, resolution)
        path = Path(cache_dir) / f"{key}.npz"
        if path.is_file():
            try:
                grid = cls.load(path)
            except ValueError:
                grid = None  # a damaged or outdated file is rebuilt, never trusted
            if grid is not None and grid.key == key:
                return grid
        grid = cls.build(signed_distance, lower, upper, resolution, key=key)
        grid.save(path)
        return grid

    def save(self, path: str | Path) -> None:
        """Write the grid to ``path`` (.npz), atomically."""
        save_npz_atomically(
            path,
            compressed=True,
            lower=self.lower,
            resolution=self.resolution,
            values=self.values,
            key=np.array(self.key),
            format=np.array(_FORMAT_VERSION),
        )

    @classmethod
    def load(cls, path: str | Path) -> GridSdf:
        """Read a grid written by :meth:`save`."""
        try:
            with np.load(path) as data:
                if int(data["format"]) != _FORMAT_VERSION:
                    raise ValueError(f"GridSdf.load: {path} has format {int(data['format'])}")
                return cls(
                    data["lower"], float(data["resolution"]), data["values"], key=str(data["key"])
                )
        except (OSError, KeyError, EOFError) as error:
            raise ValueError(f"GridSdf.load: cannot read {path} ({error})") from None

    # ---------------------------------------------------------------------------------- lookups
    def _cells(self, points: np.ndarray):
        """Base corner flat index, fractional offsets and inside-mask of each point."""
        u = (points - self.lower) / self.resolution
        inside = np.all((u >= 0.0) & (u <= self.shape - 1), axis=-1)
        base = np.clip(np.floor(u), 0, self.shape - 2).astype(np.int64)
        frac = u - base
        flat = base @ self._strides
        return flat, frac, inside

    def __call__(self, points) -> np.ndarray:
        """Signed distance at ``points[..., 3]`` (m); ``+inf`` outside the grid."""
        points = np.asarray(points, dtype=np.float64)
        flat, frac, inside = self._cells(points)
        sy, sz = self._strides[1], self._strides[2]
        v = self._flat
        fx, fy, fz = frac[..., 0], frac[..., 1], frac[..., 2]
        sx = self._strides[0]
        c00 = v[flat] * (1 - fz) + v[flat + sz] * fz
        c01 = v[flat + sy] * (1 - fz) + v[flat + sy + sz] * fz
        c10 = v[flat + sx] * (1 - fz) + v[flat + sx + sz] * fz
        c11 = v[flat + sx + sy] * (1 - fz) + v[flat + sx + sy + sz] * fz
        c0 = c00 * (1 - fy) + c01 * fy
        c1 = c10 * (1 - fy) + c11 * fy
        result = c0 * (1 - fx) + c1 * fx
        return np.where(inside, result, np.inf)

    def at_cell_coordinates(self, u, v, w) -> np.ndarray:
        """Signed distance at grid coordinates (cells from ``lower``, float32 arrays per axis).

        The hot path of the penetration check: structure-of-arrays and float32 (point and
        config coordinates are float32 already), same interpolant as :meth:`__call__`.
        """
        sx, sy, sz = (int(k) for k in self._strides)
        flat = np.zeros(u.shape, dtype=np.int64)
        fractions = []
        inside = np.ones(u.shape, dtype=bool)
        for coordinate, stride, count in zip((u, v, w), (sx, sy, sz), self.shape, strict=True):
            inside &= (coordinate >= 0) & (coordinate <= count - 1)
            base = np.clip(np.floor(coordinate), 0, count - 2)
            fractions.append(coordinate - base)
            flat += base.astype(np.int64) * stride
        fx, fy, fz = fractions
        values = self._flat

        def lerp_z(offset):
            lo = values[flat + offset]
            return lo + (values[flat + offset + sz] - lo) * fz

        c0 = lerp_z(0)
        c0 += (lerp_z(sy) - c0) * fy
        c1 = lerp_z(sx)
        c1 += (lerp_z(sx + sy) - c1) * fy
        result = c0 + (c1 - c0) * fx
        result[~inside] = np.inf
        return result

    def gradient(self, points) -> np.ndarray:
        """Gradient of the trilinear interpolant at ``points[..., 3]`` (unitless); 0 outside."""
        points = np.asarray(points, dtype=np.float64)
        flat, frac, inside = self._cells(points)
        sx, sy, sz = self._strides
        v = self._flat
        corner = {
            (a, b, c): v[flat + a * sx + b * sy + c * sz]
            for a in (0, 1)
            for b in (0, 1)
            for c in (0, 1)
        }
        fx, fy, fz = frac[..., 0], frac[..., 1], frac[..., 2]

        def lerp(lo, hi, t):
            return lo * (1 - t) + hi * t

        def plane(axis_value: int, axis: int):
            # Bilinear interpolation over the two axes other than ``axis`` on one face.
            if axis == 0:
                return lerp(
                    lerp(corner[axis_value, 0, 0], corner[axis_value, 0, 1], fz),
                    lerp(corner[axis_value, 1, 0], corner[axis_value, 1, 1], fz),
                    fy,
                )
            if axis == 1:
                return lerp(
                    lerp(corner[0, axis_value, 0], corner[0, axis_value, 1], fz),
                    lerp(corner[1, axis_value, 0], corner[1, axis_value, 1], fz),
                    fx,
                )
            return lerp(
                lerp(corner[0, 0, axis_value], corner[0, 1, axis_value], fy),
                lerp(corner[1, 0, axis_value], corner[1, 1, axis_value], fy),
                fx,
            )

        grad = np.stack([plane(1, a) - plane(0, a) for a in range(3)], axis=-1) / self.resolution
        return np.where(inside[..., None], grad, 0.0)

    def hull_planes(self) -> np.ndarray:
        """(m, 4) facets [n, d] of the convex hull of the solid (the nodes with distance <= 0):
        outward unit normals n and offsets d, so n . p + d is how far p lies past each facet's
        plane (m, the grid's frame). Computed once."""
        if self._hull_planes is None:
            nodes = np.argwhere(self.values <= 0.0)
            if len(nodes) < 4:
                raise ValueError("GridSdf.hull_planes: fewer than 4 nodes inside the solid")
            self._hull_planes = ConvexHull(self.lower + self.resolution * nodes).equations
        return self._hull_planes

    def bounds(self, level: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
        """Axis-aligned box containing every point whose interpolated distance is below ``level``.

        The interpolant is below ``level`` only inside a cell with a node below ``level``, so the
        box of those nodes grown by one cell is conservative. Empty (lower > upper) if none is.
        """
        level = float(level)
        if level not in self._bounds_cache:  # a scan of the whole grid: do it once per level
            nodes = np.argwhere(self.values < level)
            if len(nodes) == 0:
                box = np.full(3, np.inf), np.full(3, -np.inf)
            else:
                lo = self.lower + self.resolution * (nodes.min(axis=0) - 1)
                hi = self.lower + self.resolution * (nodes.max(axis=0) + 1)
                box = np.maximum(lo, self.lower), np.minimum(hi, self.upper)
            self._bounds_cache[level] = box
        lo, hi = self._bounds_cache[level]
        return lo.copy(), hi.copy()
