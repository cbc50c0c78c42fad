"""STUCCO: soft tracking of contact points with a particle filter (paper Algorithms 1-3)."""

from __future__ import annotations

import copy

import numpy as np

from stucco_drake.core.contact_motion import normal_spread, robot_surface_normals
from stucco_drake.core.dynamics import ContactDynamics, TranslationDynamics
from stucco_drake.core.params import SoftTrackingParams
from stucco_drake.core.penetration import RobotPenetration
from stucco_drake.core.resampling import (
    effective_sample_size,
    normalize_log_weights,
    systematic_resample,
)
from stucco_drake.core.segmentation import connected_components
from stucco_drake.core.validation import as_finite_array, as_rotation


class SoftTracker:
    """Belief over contact-point positions and their implicit object associations.

    Each particle holds every contact point p (world, m) with the end-effector pose x at which it
    was sensed. Arrays are ``[n_particles, n_contacts]`` per coordinate and no step loops over
    particles or points in Python. Call :meth:`update` once per action.

    Where the paper's text and the authors' code differ, this class chooses as follows (and
    documents it so results can be compared):

    1. A new contact is inserted at its pre-motion position (p_t - dx, x_t - dx) and then moved
       with everything connected to it, so it lands on (p_t, x_t) (code). The paper's Alg. 1
       appends (p_t, x_t) and would then move it once more by dx.
    2. Each existing point connects with probability exp(-d^2 / l), d its distance to the nearest
       new pre-motion point, and follows that contact's dx (paper, multi-contact extension).
    3. The likelihood counts penetration beyond ``intersection_tolerance`` per pair and measures
       it relative to the best particle, log p_obs = -(eps - min eps)^2 / lambda (code): a
       penetration every particle shares (isolation error) carries no information. Weights are
       kept in log space and accumulate across steps (code).
    4. Resampling (systematic) happens when the effective sample size drops below
       ``resample_ess_fraction`` * N (code; 1.0 reproduces the paper's every-step resampling).
    5. ReplaceBad runs after every update, on every particle (paper), and marks a point bad when
       its summed penetration beyond the tolerance against the particle's configs is positive
       (code's tolerance; the paper says any penetration). The bad pair (p, x) is replaced by
       the nearest good pair of the same particle; a particle with no good pair is left as is.
       In contact all configs are checked; out of contact only x_t is, which is exact because
       the previous ReplaceBad left every other pair consistent. With ``replace_bad`` off
       (not the paper) no pair is replaced: a penetrating point stays and only weighs its
       particle down, at every later step in contact.
    6. The MAP particle is the heaviest one, ties kept with the previous MAP; after resampling it
       is the first copy of that particle, so it also receives ReplaceBad's repairs.
    7. Optionally (``touched_side_margin``, off by default) a point does not follow a contact
       it lies clearly behind, or (``touched_side_softness``) follows it less likely the further
       behind it lies: see :class:`~stucco_drake.core.params.SoftTrackingParams`. The rule
       scales the connection probability and draws nothing, so it changes no draw of the step.
    8. Segmentation is the exact connected components of the MAP particle (paper); the authors'
       code expands only one level from each seed.

    Args:
        penetration: pxpen, the robot's geometry in the end-effector frame: a
            :class:`~stucco_drake.core.penetration.RobotPenetration` (a grid, the fast
            default) or a :class:`~stucco_drake.core.function_penetration.FunctionPenetration`
            (any batched signed-distance function of the user's).
        params: tracker parameters (defaults: paper Table I, simulation).
        dynamics: pxdyn (default: translation with the end effector, paper Sec. V).
    """

    def __init__(
        self,
        penetration: RobotPenetration,
        params: SoftTrackingParams | None = None,
        dynamics: ContactDynamics | None = None,
    ):
        self.params = params or SoftTrackingParams.sim()
        if self.params.touched_side_margin is not None and penetration.robot_sdf is None:
            raise ValueError("SoftTracker: the touched-side rule needs the robot's surface "
                             "normals, a grid pxpen (RobotPenetration)")  # fmt: skip
        self.penetration = penetration
        self.dynamics = dynamics or TranslationDynamics()
        n = self.params.n_particles
        self._n = 0
        self._points = np.zeros((3, n, 0), dtype=np.float32)
        self._configs = np.zeros((3, n, 0), dtype=np.float32)
        self._rotation_index = np.zeros((n, 0), dtype=np.int32)
        self._rotations = np.zeros((0, 3, 3))
        self._log_weights = np.full(n, -np.log(n))
        self._map_index = 0
        self.resampled = False  # whether the last update resampled

    # --------------------------------------------------------------------------- read access
    @property
    def n_contacts(self) -> int:
        """Number of contact points each particle holds."""
        return self._n

    @property
    def points(self) -> np.ndarray:
        """(n_particles, n_contacts, 3) contact points of every particle (m, world)."""
        return np.moveaxis(self._points[:, :, : self._n], 0, -1).astype(np.float64)

    @property
    def configs(self) -> np.ndarray:
        """(n_particles, n_contacts, 3) EE origin paired with each point (m, world)."""
        return np.moveaxis(self._configs[:, :, : self._n], 0, -1).astype(np.float64)

    @property
    def log_weights(self) -> np.ndarray:
        """(n_particles,) normalised log weights."""
        return self._log_weights.copy()

    @property
    def map_index(self) -> int:
        """Index of the maximum a posteriori particle."""
        return self._map_index

    def map_points(self) -> np.ndarray:
        """(n_contacts, 3) the MAP particle's contact points (m, world)."""
        return self.points[self._map_index]

    def segment(self) -> np.ndarray:
        """(n_contacts,) object labels of the MAP particle's points (Algorithm 3)."""
        return connected_components(self.map_points(), self.params.segmentation_radius)

    # --------------------------------------------------------------------------------- update
    def update(
        self,
        rng: np.random.Generator,
        ee_position,
        contact_points=None,
        contact_dx=None,
        ee_rotation=None,
    ) -> None:
        """One step of Algorithm 1, after an action.

        Args:
            rng: the caller's seeded generator; every random draw of the step comes from it.
            ee_position: (3,) x_t, the EE origin after the action (m, world).
            contact_points: (m, 3) contact points detected during the action (m, world); empty
                or None when the action made no contact.
            contact_dx: (m, 3) EE displacement while in contact for each contact point (m, world).
            ee_rotation: (3, 3) R_WE after the action (identity when omitted).
        """
        if not isinstance(rng, np.random.Generator):
            raise ValueError(f"rng: expected numpy.random.Generator, got {type(rng).__name__}")
        position = as_finite_array(ee_position, "ee_position", (3,))
        rotation = np.eye(3) if ee_rotation is None else as_rotation(ee_rotation, "ee_rotation")
        if contact_points is None:
            contact_points = np.zeros((0, 3))
        points = as_finite_array(contact_points, "contact_points", (None, 3))
        dx = (
            np.zeros_like(points)
            if contact_dx is None and len(points) == 0
            else as_finite_array(contact_dx, "contact_dx", (len(points), 3))
        )

        if len(points):
            self._predict(rng, points, dx, position, rotation)
            per_particle, per_point = self._penetration_all_pairs()
        else:
            per_particle, per_point = self._penetration_against(position, rotation)

        eps = per_particle
        self._log_weights = normalize_log_weights(
            self._log_weights - (eps - eps.min()) ** 2 / self.params.penetration_length
        )
        self._map_index = self._heaviest()
        n = self.params.n_particles
        self.resampled = (
            effective_sample_size(self._log_weights) < self.params.resample_ess_fraction * n
        )
        bad = per_point > 0.0
        if self.resampled:
            ancestors = systematic_resample(self._log_weights, rng)
            copies = np.flatnonzero(ancestors == self._map_index)
            # Copies of a particle would get identical repairs: repair each survivor once,
            # before copying it.
            survives = np.zeros(n, dtype=bool)
            survives[ancestors] = True
            self._replace_bad(bad & survives[:, None])
            self._take(ancestors)
            self._log_weights = np.full(n, -np.log(n))
            self._map_index = int(copies[0]) if len(copies) else 0
        else:
            self._replace_bad(bad)

    # ---------------------------------------------------------------------------- the pieces
    def _heaviest(self) -> int:
        best = float(self._log_weights.max())
        if self._log_weights[self._map_index] >= best:
            return self._map_index  # keep the previous MAP on ties
        return int(np.argmax(self._log_weights))

    def _ensure_capacity(self, total: int) -> None:
        capacity = self._points.shape[2]
        if total <= capacity:
            return
        new_capacity = max(total, 2 * capacity, 16)
        grow = new_capacity - capacity
        pad3 = ((0, 0), (0, 0), (0, grow))
        self._points = np.pad(self._points, pad3)
        self._configs = np.pad(self._configs, pad3)
        self._rotation_index = np.pad(self._rotation_index, ((0, 0), (0, grow)))

    def _rotation_slot(self, rotation: np.ndarray) -> int:
        # The first known orientation np.allclose(known, rotation, atol=1e-9) accepts.
        close = (np.abs(self._rotations - rotation) <= 1e-9 + 1e-5 * np.abs(rotation)).all(
            axis=(1, 2)
        )
        if close.any():
            return int(np.argmax(close))
        self._rotations = np.concatenate([self._rotations, rotation[None]])
        return len(self._rotations) - 1

    def _predict(self, rng, points, dx, position, rotation) -> None:
        """Sample connections to the new contacts, move what is connected, then insert them."""
        n, m = self._n, len(points)
        if n:
            existing = self._points[:, :, :n]
            before = (points - dx).astype(np.float32)  # new contacts before this action moved them
            d2 = np.zeros((existing.shape[1], n, m), dtype=np.float32)
            for axis in range(3):
                d2 += (existing[axis][:, :, None] - before[None, None, :, axis]) ** 2
            nearest = np.argmin(d2, axis=2)
            nearest_d2 = np.take_along_axis(d2, nearest[:, :, None], axis=2)[:, :, 0]
            probability = np.exp(-nearest_d2 / self.params.length)
            if self.params.touched_side_margin is not None:
                probability = probability * self._touched_side_factor(
                    existing, before, nearest, nearest_d2, points, position, rotation
                )
            connected = rng.random(nearest.shape) < probability
            self.dynamics.apply(existing, self._configs[:, :, :n], connected, dx[nearest])
        self._ensure_capacity(n + m)
        self._points[:, :, n : n + m] = points.T[:, None, :]
        self._configs[:, :, n : n + m] = position[:, None, None]
        self._rotation_index[:, n : n + m] = self._rotation_slot(rotation)
        self._n = n + m

    def _touched_side_factor(self, existing, before, nearest, nearest_d2, points, position,
                             rotation):  # fmt: skip
        """(n_particles, n) factor on each point's connection probability: 1 where it may lie on
        the object its nearest new contact touched (not more than margin + d * spread behind the
        robot's tangent plane there); beyond that, 0 (hard rule) or a Gaussian of the excess."""
        sdf = self.penetration.robot_sdf
        normals = robot_surface_normals(sdf, points, position, rotation)
        spread = normal_spread(sdf, points, position, rotation, normals=normals,
                               radius=self.params.normal_probe_radius)  # fmt: skip
        normals = normals.astype(np.float32)
        ahead = np.zeros(nearest.shape, dtype=np.float32)
        for axis in range(3):
            ahead += (existing[axis] - before[nearest, axis]) * normals[nearest, axis]
        allowed = self.params.touched_side_margin + spread[nearest] * np.sqrt(nearest_d2)
        excess = -ahead - allowed
        softness = self.params.touched_side_softness
        if softness > 0:
            factor = np.exp(-((np.maximum(excess, 0.0) / softness) ** 2))
        else:
            factor = (excess <= 0).astype(np.float32)
        unknown = ~normals.any(axis=1)[nearest]  # no normal, no rule
        return np.where(unknown, np.float32(1.0), factor)

    def _in_frame(self, rotation: np.ndarray, array: np.ndarray) -> np.ndarray:
        """Coordinates of world vectors ``array[3, ...]`` along the axes of ``rotation``."""
        if np.array_equal(rotation, np.eye(3)):
            return array
        return np.tensordot(rotation.T.astype(np.float32), array, axes=1)

    def _penetration_all_pairs(self):
        """Every config of each particle against every point of it (Alg. 1, in contact), each
        config in its own orientation."""
        n = self._n
        return self.penetration.all_pairs_excess_sums(
            self._points[:, :, :n],
            self._configs[:, :, :n],
            self._rotation_index[:, :n],
            self._rotations,
            self.params.intersection_tolerance,
        )

    def _penetration_against(self, position, rotation):
        """The current config against every point of each particle (Alg. 1, out of contact)."""
        points = self._points[:, :, : self._n]
        config = position.astype(np.float32)[:, None, None]
        return self.penetration.excess_sums(
            self._in_frame(rotation, points),
            self._in_frame(rotation, config),
            self.params.intersection_tolerance,
        )

    def _take(self, ancestors: np.ndarray) -> None:
        self._points = self._points[:, ancestors]
        self._configs = self._configs[:, ancestors]
        self._rotation_index = self._rotation_index[ancestors]

    def _replace_bad(self, bad: np.ndarray) -> None:
        """Algorithm 2: replace each inconsistent pair by the nearest consistent one (nothing
        when ``params.replace_bad`` is off)."""
        particle, point = np.nonzero(bad)
        if particle.size == 0 or not self.params.replace_bad:
            return
        n = self._n
        existing = self._points[:, :, :n]
        d2 = np.zeros((particle.size, n))
        for axis in range(3):
            d2 += (existing[axis, particle, :] - existing[axis, particle, point][:, None]) ** 2
        d2[bad[particle]] = np.inf
        source = np.argmin(d2, axis=1)
        fixable = np.isfinite(d2[np.arange(particle.size), source])
        particle, point, source = particle[fixable], point[fixable], source[fixable]
        self._points[:, particle, point] = self._points[:, particle, source]
        self._configs[:, particle, point] = self._configs[:, particle, source]
        self._rotation_index[particle, point] = self._rotation_index[particle, source]

    def __deepcopy__(self, memo):
        # Drake clones abstract state with deepcopy: copy the belief, share the (large,
        # immutable) robot geometry and the parameters.
        clone = copy.copy(self)
        for name in ("_points", "_configs", "_rotation_index", "_rotations", "_log_weights"):
            setattr(clone, name, getattr(self, name).copy())
        return clone
