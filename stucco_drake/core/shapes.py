"""Analytic signed-distance functions of primitive shapes, in the shape's own frame.

Each is a callable ``sdf(points[..., 3]) -> distance[...]`` (metres, negative inside) with
``bounds(level)``, an axis-aligned box that contains every point whose distance is below
``level``. They describe synthetic robots and objects in tests and the built-in demo scene, and
are the ground truth that :class:`~stucco_drake.core.sdf.GridSdf` is checked against (and the
second robot's spherical probe, :mod:`stucco_drake.robot.scara_probe`).
"""

from __future__ import annotations

import dataclasses

import numpy as np


@dataclasses.dataclass(frozen=True)
class BoxSdf:
    """Box centred at ``center`` with ``half_extents``, axis-aligned in its frame (metres)."""

    half_extents: tuple[float, float, float]
    center: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def __call__(self, points) -> np.ndarray:
        q = np.abs(np.asarray(points, dtype=np.float64) - self.center) - self.half_extents
        outside = np.linalg.norm(np.maximum(q, 0.0), axis=-1)
        inside = np.minimum(q.max(axis=-1), 0.0)
        return outside + inside

    def bounds(self, level: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
        half = np.asarray(self.half_extents) + level
        return np.asarray(self.center) - half, np.asarray(self.center) + half


@dataclasses.dataclass(frozen=True)
class CylinderSdf:
    """Cylinder with its axis along z, centred at ``center`` (metres)."""

    radius: float
    half_height: float
    center: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def __call__(self, points) -> np.ndarray:
        p = np.asarray(points, dtype=np.float64) - self.center
        radial = np.hypot(p[..., 0], p[..., 1]) - self.radius
        axial = np.abs(p[..., 2]) - self.half_height
        outside = np.hypot(np.maximum(radial, 0.0), np.maximum(axial, 0.0))
        inside = np.minimum(np.maximum(radial, axial), 0.0)
        return outside + inside

    def bounds(self, level: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
        half = np.array([self.radius, self.radius, self.half_height]) + level
        return np.asarray(self.center) - half, np.asarray(self.center) + half


@dataclasses.dataclass(frozen=True)
class SphereSdf:
    """Sphere of ``radius`` centred at ``center`` (metres): exact distance |p - c| - r."""

    radius: float
    center: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def __call__(self, points) -> np.ndarray:
        p = np.asarray(points, dtype=np.float64) - self.center
        return np.linalg.norm(p, axis=-1) - self.radius

    def bounds(self, level: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
        half = np.full(3, self.radius + level)
        return np.asarray(self.center) - half, np.asarray(self.center) + half
