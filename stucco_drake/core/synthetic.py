"""A built-in planar pushing world: a disc end effector shoving boxes by pure translation.

It exercises the tracker without a simulator, in the regime the paper's pxdyn assumes: a box
touched by the end effector translates with it (sticking contact, no rotation), and shoves the
boxes it runs into the same way. Contact points are exact (on the box surface at the EE's
height), so any tracking error is the tracker's own or its motion model's.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from stucco_drake.core.shapes import BoxSdf, CylinderSdf
from stucco_drake.core.validation import as_finite_array

#: Largest EE motion (m) between contact checks within an action.
_SUBSTEP = 5e-4


@dataclasses.dataclass
class ActionObservation:
    """What the tracker sees after one action, plus the ground truth that scores it.

    Attributes:
        ee_position: (3,) EE origin after the action (m, world).
        contact_points: (m, 3) latest contact point with each touched box (m, world).
        contact_dx: (m, 3) EE displacement while in contact with that box (m, world).
        contact_objects: (m,) index of the box each contact belongs to.
    """

    ee_position: np.ndarray
    contact_points: np.ndarray
    contact_dx: np.ndarray
    contact_objects: np.ndarray


class PlanarPushWorld:
    """Axis-aligned boxes on a plane, pushed by a disc-shaped end effector.

    Args:
        box_centers: (k, 2) box centres (m).
        box_half_extents: (k, 2) box half sizes (m).
        ee_start: (2,) EE centre (m).
        ee_radius: disc radius (m).
        height: the EE's and the contacts' height above the plane (m).
    """

    def __init__(self, box_centers, box_half_extents, ee_start, ee_radius=0.02, height=0.05):
        self.box_centers = as_finite_array(box_centers, "box_centers", (None, 2)).copy()
        self.box_half_extents = as_finite_array(
            box_half_extents, "box_half_extents", (len(self.box_centers), 2)
        )
        self.ee = as_finite_array(ee_start, "ee_start", (2,)).copy()
        self.ee_radius = float(ee_radius)
        self.height = float(height)
        if np.any(self._distances(self.ee) < self.ee_radius):
            raise ValueError("ee_start: the end effector starts inside a box")
        if self._overlaps().any():
            raise ValueError("box_centers: boxes overlap at the start")

    # -------------------------------------------------------------------------------- geometry
    def _closest(self, point):
        """Closest point of each box to ``point`` (k, 2)."""
        lo = self.box_centers - self.box_half_extents
        hi = self.box_centers + self.box_half_extents
        return np.clip(point, lo, hi)

    def _distances(self, point):
        return np.linalg.norm(self._closest(point) - point, axis=1)

    def robot_sdf(self) -> CylinderSdf:
        """The EE's geometry in its own frame: a vertical cylinder (pxpen's source)."""
        return CylinderSdf(radius=self.ee_radius, half_height=0.05)

    def object_surfaces(self) -> list[BoxSdf]:
        """Signed-distance functions of the boxes at their current poses (tall, as in CE)."""
        return [
            BoxSdf(half_extents=(hx, hy, 1.0), center=(cx, cy, self.height))
            for (cx, cy), (hx, hy) in zip(self.box_centers, self.box_half_extents, strict=True)
        ]

    @property
    def ee_position(self) -> np.ndarray:
        return np.array([self.ee[0], self.ee[1], self.height])

    # ---------------------------------------------------------------------------------- motion
    def step(self, delta) -> ActionObservation:
        """Move the EE by ``delta`` (2,) m, pushing every box it touches along with it."""
        delta = as_finite_array(delta, "delta", (2,))
        n_sub = max(1, int(np.ceil(np.linalg.norm(delta) / _SUBSTEP)))
        sub = delta / n_sub
        k = len(self.box_centers)
        moved = np.zeros((k, 2))
        last_point = np.full((k, 2), np.nan)
        for _ in range(n_sub):
            # Boxes touching the disc (within round-off) and lying ahead of the motion stick.
            closest = self._closest(self.ee)
            offset = closest - self.ee
            touching = (np.linalg.norm(offset, axis=1) <= self.ee_radius + 1e-9) & (
                offset @ sub > 0
            )
            travel = self._free_travel(sub, ~touching)
            self.ee += travel * sub
            self._push(touching, travel * sub)
            moved[touching] += travel * sub
            remaining = (1.0 - travel) * sub
            if travel < 1.0:  # touched a new box mid-substep: it moves for the rest of it
                offset = self._closest(self.ee) - self.ee
                touching = (np.linalg.norm(offset, axis=1) <= self.ee_radius + 1e-9) & (
                    offset @ sub > 0
                )
                self.ee += remaining
                self._push(touching, remaining)
                moved[touching] += remaining
            contact = self._distances(self.ee) <= self.ee_radius + 1e-9
            last_point[contact] = self._closest(self.ee)[contact]
        touched = np.flatnonzero(~np.isnan(last_point[:, 0]) & (np.abs(moved).sum(1) > 0))
        points = np.column_stack([last_point[touched], np.full(len(touched), self.height)])
        dx = np.column_stack([moved[touched], np.zeros(len(touched))])
        return ActionObservation(self.ee_position, points, dx, touched)

    def _free_travel(self, sub, candidates) -> float:
        """Fraction of ``sub`` the disc can move before touching one of ``candidates`` boxes."""
        lo, hi = 0.0, 1.0
        if not np.any(self._distances(self.ee + sub)[candidates] < self.ee_radius):
            return 1.0
        for _ in range(40):  # bisection on first contact
            mid = (lo + hi) / 2
            if np.any(self._distances(self.ee + mid * sub)[candidates] < self.ee_radius):
                hi = mid
            else:
                lo = mid
        return lo

    def _overlaps(self) -> np.ndarray:
        lo = self.box_centers - self.box_half_extents
        hi = self.box_centers + self.box_half_extents
        overlap = np.all(
            (lo[:, None] < hi[None, :] - 1e-9) & (lo[None, :] < hi[:, None] - 1e-9), axis=2
        )
        np.fill_diagonal(overlap, False)
        return overlap

    def _push(self, pushed: np.ndarray, displacement: np.ndarray) -> None:
        """Translate the pushed boxes, and every box they run into, by ``displacement``."""
        pushed = pushed.copy()
        self.box_centers[pushed] += displacement
        while True:  # a pushed box shoves what it overlaps, transitively
            hit = self._overlaps()[pushed].any(axis=0) & ~pushed
            if not hit.any():
                return
            self.box_centers[hit] += displacement
            pushed |= hit


def random_clutter(
    rng: np.random.Generator, n_boxes: int = 8, extent: float = 0.35, ee_radius: float = 0.05
) -> PlanarPushWorld:
    """Boxes (4-10 cm half sizes) scattered without overlap in [-extent, extent]^2, EE at -x."""
    centers, halves = [], []
    while len(centers) < n_boxes:
        center = rng.uniform(-extent, extent, 2)
        half = rng.uniform(0.04, 0.10, 2)
        clear = all(
            np.any(np.abs(center - c) > half + h + 0.01)
            for c, h in zip(centers, halves, strict=True)
        )
        if clear and np.any(np.abs(center - (-extent - 0.15, 0.0)) > half + ee_radius + 0.01):
            centers.append(center)
            halves.append(half)
    return PlanarPushWorld(centers, halves, (-extent - 0.15, 0.0), ee_radius=ee_radius)


def rummage(world: PlanarPushWorld, rng: np.random.Generator):
    """Endless greedy rummaging: steps of up to 3 cm towards randomly chosen boxes, with jitter.

    Goals are box centres (at the time of choosing), so the EE keeps finding the clutter even
    after it has pushed it around; a goal is dropped once reached or with probability 0.05.
    """

    def new_goal():
        return world.box_centers[rng.integers(len(world.box_centers))] + rng.normal(0, 0.03, 2)

    goal = new_goal()
    while True:
        if np.linalg.norm(goal - world.ee) < 0.03 or rng.random() < 0.05:
            goal = new_goal()
        step = np.clip(goal - world.ee, -0.03, 0.03) + rng.uniform(-0.01, 0.01, 2)
        yield world.step(np.clip(step, -0.03, 0.03))


def _steps_to(world: PlanarPushWorld, target, max_step: float = 0.03):
    """Deltas (2,) of at most ``max_step`` per axis that bring the EE centre to ``target``."""
    target = np.asarray(target, dtype=float)
    while np.linalg.norm(target - world.ee) > 1e-9:
        yield np.clip(target - world.ee, -max_step, max_step)


def separation_scenario():
    """The paper's key case: two boxes first touched close together, then pushed apart.

    Box A (above, index 0) and box B (below, index 1), 10 cm squares 4.5 cm apart, are probed from
    the gap between them: eight rounds of nudging A up and B down by 1 cm each, at different
    depths of the gap, make every early contact lie within a few centimetres of the other box's
    contacts. Two sweeps along the widened gap with 2 mm clearance then show that free space
    separates them. Returns the world and a generator of its actions (each an observation).
    """
    radius = 0.02
    world = PlanarPushWorld(
        [(0.15, 0.0725), (0.15, -0.0725)], [(0.05, 0.05), (0.05, 0.05)], (0.0, 0.0), radius
    )

    def faces():
        return (
            world.box_centers[0, 1] - world.box_half_extents[0, 1],
            world.box_centers[1, 1] + world.box_half_extents[1, 1],
        )

    def actions():
        for delta in _steps_to(world, (0.11, 0.0)):
            yield world.step(delta)
        for x in (0.11, 0.15, 0.19, 0.13, 0.17, 0.12, 0.18, 0.14):
            a_face, b_face = faces()
            for target in (
                (x, (a_face + b_face) / 2),
                (x, a_face - radius - 0.002),
                (x, a_face - radius + 0.01),  # one action: 2 mm free, 1 cm push
                (x, (a_face + b_face) / 2),
                (x, b_face + radius + 0.002),
                (x, b_face + radius - 0.01),
                (x, (a_face + b_face) / 2),
            ):  # both faces have moved 1 cm out
                for delta in _steps_to(world, target):
                    yield world.step(delta)
        a_face, b_face = faces()
        for target in (
            (0.21, (a_face + b_face) / 2),
            (0.21, a_face - radius - 0.002),
            (0.09, a_face - radius - 0.002),
            (0.09, b_face + radius + 0.002),
            (0.21, b_face + radius + 0.002),
        ):
            for delta in _steps_to(world, target):
                yield world.step(delta)

    return world, actions()
