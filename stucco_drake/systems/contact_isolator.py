"""Contact isolation on the bubble gripper: where on its surface did the detected contact happen?

- The candidate points come from :mod:`stucco_drake.robot.gripper_samples` (the gripper's
  surface where objects can reach it, and its convex hull's bridging faces).
- :class:`GripperPoseFromState`: forward kinematics of the measured arm state to the pose vector
  the isolator reads.
- :class:`ContactIsolator`: per step, bubble contact points when a bubble sensor fires (the
  paper's real-robot order, Sec. V-E), else the contact particle filter of
  :mod:`stucco_drake.core.contact_isolation` on the estimated end-effector wrench, optionally
  averaged over the contact's steps, with a flag for CPF isolations the wrench cannot decide
  (:func:`line_of_action_ambiguity`).

Pose convention (port ``gripper_pose``): a 7-vector [x, y, z, qw, qx, qy, qz], the position (m)
of the origin of ``gripper_frame`` in world and the unit quaternion of its orientation R_WG
(Drake's w-first order). The quaternion is normalised on read.
"""

from __future__ import annotations

import dataclasses

import numpy as np
from pydrake.common.eigen_geometry import Quaternion
from pydrake.common.value import AbstractValue
from pydrake.math import RigidTransform
from pydrake.systems.framework import LeafSystem, ValueProducer

from stucco_drake.core.contact_isolation import ContactParticleFilter
from stucco_drake.robot.gripper_samples import (
    reachable_samples,
    sample_gripper_surface,
    sample_hull_bridges,
)
from stucco_drake.systems.observed_robot import ObservedRobot
from stucco_drake.systems.ports import eval_finite

#: contact_source values.
SOURCE_NONE, SOURCE_CPF, SOURCE_BUBBLE = 0.0, 1.0, 2.0
#: Default of ContactIsolator's average_wrench. Off: with 0.1 N m joint torque noise the mean
#: halves the rig's isolation error (tests/test_contact_isolation.py), but in the noise-free
#: scenes, where patches move on the gripper as objects slide, it made errors worse
#: (tests/test_sensing_in_scene.py cases: e.g. two-patch pushes 8.6 -> 24 mm median).
AVERAGE_WRENCH_DEFAULT = False
# ------------------------------------------------------------------------------- pose helpers
def pose_vector(X: RigidTransform) -> np.ndarray:
    """[x, y, z, qw, qx, qy, qz] of a RigidTransform (m; unit quaternion)."""
    return np.r_[X.translation(), X.rotation().ToQuaternion().wxyz()]


def pose_from_vector(vector) -> RigidTransform:
    """Inverse of :func:`pose_vector`; the quaternion is normalised first."""
    q = np.asarray(vector[3:7], dtype=float)
    return RigidTransform(Quaternion(q / np.linalg.norm(q)), np.asarray(vector[:3], dtype=float))


class GripperPoseFromState(LeafSystem):
    """Pose of the robot's end-effector frame from the measured joint state, by forward
    kinematics.

    Input ``state`` (2 n): the observed joints' [q; v] (see :class:`ObservedRobot`); output
    ``gripper_pose`` (7): the pose of ``robot.frame`` in world (the module's pose convention).
    Joints not observed are held at the robot's positions.
    """

    def __init__(self, robot: ObservedRobot):
        super().__init__()
        self.robot = robot
        self._state = self.DeclareVectorInputPort("state", 2 * robot.n)
        self.DeclareVectorOutputPort("gripper_pose", 7, self.calc_gripper_pose)

    def calc_gripper_pose(self, context, output):
        robot = self.robot
        robot.set_state(self._state.Eval(context)[: robot.n])
        output.SetFromVector(pose_vector(robot.frame.CalcPoseInWorld(robot.context)))


# --------------------------------------------------------------------------------- ambiguity
def line_of_action_ambiguity(cpf: ContactParticleFilter, torque, force, index: int, cost: float,
                             *, radius: float = 0.015, link: float = 0.01,
                             tolerance: float | None = None) -> tuple[float, int]:  # fmt: skip
    """How far the isolated point's equally good alternatives lie, in G.

    A single-contact wrench fixes only the force's line of action; where that line enters the
    gripper surface at several admissible places (e.g. into one finger's outer plate and into
    the other finger's inner bubble face), those places explain the wrench equally well and the
    CPF's pick among them is a coin toss. This scores the samples within ``radius`` (m) of the
    line of action of ``force`` (the isolation's fitted force, N) and ``torque`` (N m), keeps
    the admissible ones whose cost is within ``cpf.torque_std + |force| * tolerance`` (N m) of
    the isolation's ``cost`` (``tolerance``, m, absorbs the sample spacing; default the
    filter's median nearest-sample distance), and links kept samples closer than ``link`` (m)
    into locations.

    Returns:
        (rival, n_locations): the largest distance (m) from the isolated sample ``index`` to a
        kept sample of another location (0 when there is only the isolated point's location),
        and the number of locations (1: unambiguous; 0 when nothing is admissible).
    """
    torque, force = np.asarray(torque, dtype=float), np.asarray(force, dtype=float)
    f2 = float(force @ force)
    if f2 < 1e-12 or not np.isfinite(cost):
        return 0.0, 0
    if tolerance is None:
        tolerance = _median_spacing(cpf)
    u = force / np.sqrt(f2)
    offset = cpf.points - np.cross(force, torque) / f2
    along = offset @ u
    near = np.einsum("ij,ij->i", offset, offset) - along**2 <= radius**2
    near[index] = True
    candidates = np.flatnonzero(near)
    costs, _ = cpf.costs(candidates, torque, force)
    good = candidates[costs <= cost + cpf.torque_std + np.sqrt(f2) * tolerance]
    good = np.union1d(good, [index])
    points = cpf.points[good]
    # Single-linkage components of the kept samples (a few hundred at most: dense is fine).
    linked = np.sum((points[:, None] - points[None]) ** 2, axis=2) <= link**2
    label = np.full(len(points), -1)
    n_locations = 0
    for first in range(len(points)):
        if label[first] >= 0:
            continue
        frontier = [first]
        label[first] = n_locations
        while frontier:
            reached = np.flatnonzero(linked[frontier].any(axis=0) & (label < 0))
            label[reached] = n_locations
            frontier = reached.tolist()
        n_locations += 1
    others = label != label[np.searchsorted(good, index)]
    distance = np.linalg.norm(points - cpf.points[index], axis=1)
    rival = float(distance[others].max()) if others.any() else 0.0
    return rival, n_locations


def _median_spacing(cpf: ContactParticleFilter) -> float:
    """Median distance (m) from a sample to its nearest other sample."""
    if cpf.neighbours.shape[1] < 2:
        return 0.0
    return float(np.median(np.linalg.norm(cpf.points[cpf.neighbours[:, 1]] - cpf.points, axis=1)))


# ----------------------------------------------------------------------------------- isolator
@dataclasses.dataclass(frozen=True)
class _IsolatorState:
    """What the isolator keeps between steps (replaced, never mutated, by each update)."""

    step: int = 0
    particles: np.ndarray | None = None  # CPF particles of the contact under way
    point_W: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros(3))
    point_G: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros(3))
    points_W: tuple = ()
    cost: float = 0.0
    source: float = SOURCE_NONE
    # What line_of_action_ambiguity needs, for a CPF point: (torque (N m) and fitted force (N)
    # in G, sample index). The spread is computed only when its output is asked for.
    line_of_action: tuple | None = None
    # Sum of the CPF contact's wrenches [torque (N m); force (N)] in G and their count, for the
    # running mean (average_wrench); None outside a CPF contact.
    wrench_sum: np.ndarray | None = None
    wrench_count: int = 0

    def __deepcopy__(self, memo):
        # Immutable (each update builds a new one), so Drake's clone at every step may share it.
        return self


class ContactIsolator(LeafSystem):
    """Contact point(s) in world for each detected contact step: bubbles first, else the CPF.

    Per update (every ``time_step`` s): when ``in_contact`` is 0, no contact. Otherwise, when a
    bubble input fires, the contact points are the firing bubbles' points (the CPF is skipped
    and its particles dropped). Otherwise the CPF isolates one point from ``ee_wrench``
    (rotated into ``gripper_frame``), reusing its particles while the contact lasts when
    ``reuse_particles`` is on; a wrench force below ``min_force`` (N) is too weak to isolate and
    gives no contact. Draws come from numpy Generators keyed by (``seed``, update count).

    With ``average_wrench`` the CPF reads the running mean of the wrench (in ``gripper_frame``)
    over the steps of the contact under way instead of the last one; the mean restarts with
    each contact (any step without a CPF isolation ends it). For a contact point fixed on the
    gripper every wrench satisfies tau = c x f, and so does their mean, whatever the force
    does; averaging only removes estimator noise (and lags if the point slides on the gripper).

    Each CPF isolation is checked for ambiguity (:func:`line_of_action_ambiguity`): when
    its line of action enters the gripper at separate, equally good places more than
    ``ambiguity_distance`` apart, the point is a guess between them and ``contact_ambiguous``
    says so. (Alternatives closer than that are not flagged: the error they allow is small.)

    Args:
        time_step: update period (s).
        seed: the CPF's random seed (also seeds the surface sampling unless ``samples`` given).
        samples: (points, normals) in ``gripper_frame``; default :func:`sample_gripper_surface`
            with ``spacing`` and ``opening``, plus :func:`sample_hull_bridges` with ``hull``.
        hull: isolate where objects can touch (default): drop the surface samples that a
            ball of ``min_object_radius`` (m) cannot reach (:func:`reachable_samples`) and add
            the convex hull's bridging faces (:func:`sample_hull_bridges`). On the Drake FB
            scene (seed 0) the first pushes of the box face touch it with both fingers' sides
            at once; on the surface alone the CPF put those contacts 13-15 mm inside the box
            (in the crevice between the bubbles), with the hull 0-3 mm from its face. False:
            every sample of the real surface (a probe could touch anywhere).
        n_bubbles: number of bubble sensors wired in (0: CPF only; the ports are then absent).
        filter_kwargs: settings for :class:`~stucco_drake.core.contact_isolation.
            ContactParticleFilter` (stds, particle counts, friction angle).
        average_wrench: isolate from the contact's running-mean wrench (see above).
        ambiguity_distance: an equally good alternative location farther than this (m) from
            the isolated point makes the isolation ambiguous.

    Input ports:
        ee_wrench: (6,) [torque (N m); force (N)] on the gripper at the origin of
            ``gripper_frame``, expressed in world (the wrench estimator's output).
        gripper_pose: (7,) see the module's pose convention.
        in_contact: (1,) detection flag (> 0.5 means contact).
        bubble_in_contact: (n_bubbles,) flags, only with n_bubbles > 0.
        bubble_contact_points: (3 n_bubbles,) world points (m), only with n_bubbles > 0.

    Output ports (from state; no direct feedthrough):
        has_contact: (1,) 1.0 when this step produced a contact point.
        contact_point: (3,) the (first) contact point in world (m); zeros without contact.
        contact_point_gripper: (3,) the same point in ``gripper_frame`` (m).
        isolation_cost: (1,) CPF torque residual (N m); 0 for bubble points.
        contact_source: (1,) 0 none, 1 CPF, 2 bubble.
        contact_spread: (1,) for a CPF point, the distance (m) from the isolated sample to the
            farthest sample of another location on the gripper that explains the wrench as
            well (see :func:`line_of_action_ambiguity`); 0 when there is no such location, for
            bubble points and without contact. On this gripper 5-12 cm when the line of action
            runs along the closing axis through both fingers.
        contact_ambiguous: (1,) 1.0 when contact_spread > ``ambiguity_distance``.
        contact_points: abstract list of (3,) world points (m), all points of this step.
    """

    def __init__(self, time_step: float, *, seed: int, samples=None, spacing: float = 0.004,
                 opening: float = 0.03, n_bubbles: int = 0, min_force: float = 1.0,
                 reuse_particles: bool = True, filter_kwargs: dict | None = None,
                 average_wrench: bool = AVERAGE_WRENCH_DEFAULT,
                 ambiguity_distance: float = 0.03, hull: bool = True,
                 min_object_radius: float = 0.02):  # fmt: skip
        super().__init__()
        if not (np.isfinite(time_step) and time_step > 0):
            raise ValueError(f"ContactIsolator: time_step must be > 0, got {time_step}")
        self._seed = int(seed)
        if samples is None:
            rng = np.random.default_rng([self._seed, 1])
            samples = sample_gripper_surface(rng, spacing, opening)
            if hull:
                surface, _ = sample_gripper_surface(rng, spacing / 2, opening)
                keep = reachable_samples(*samples, min_object_radius, surface)
                bridges = sample_hull_bridges(rng, spacing, opening)
                samples = tuple(np.concatenate([a[keep], b])
                                for a, b in zip(samples, bridges, strict=True))  # fmt: skip
        self.filter = ContactParticleFilter(*samples, **(filter_kwargs or {}))
        self._min_force = float(min_force)
        self._reuse = bool(reuse_particles)
        self._average = bool(average_wrench)
        self._ambiguity_distance = float(ambiguity_distance)
        self._spacing = _median_spacing(self.filter)
        self._n_bubbles = int(n_bubbles)
        self._wrench = self.DeclareVectorInputPort("ee_wrench", 6)
        self._pose = self.DeclareVectorInputPort("gripper_pose", 7)
        self._flag = self.DeclareVectorInputPort("in_contact", 1)
        if self._n_bubbles:
            self._bubble_flags = self.DeclareVectorInputPort("bubble_in_contact", n_bubbles)
            self._bubble_points = self.DeclareVectorInputPort(
                "bubble_contact_points", 3 * n_bubbles
            )
        self._state = self.DeclareAbstractState(AbstractValue.Make(_IsolatorState()))
        ticket = {self.abstract_state_ticket(self._state)}
        for name, size, calc in (
            ("has_contact", 1, self.calc_has_contact),
            ("contact_point", 3, self.calc_contact_point),
            ("contact_point_gripper", 3, self.calc_contact_point_gripper),
            ("isolation_cost", 1, self.calc_isolation_cost),
            ("contact_source", 1, self.calc_contact_source),
        ):
            self.DeclareVectorOutputPort(name, size, calc, prerequisites_of_calc=ticket)
        # The spread is costly and only diagnostic: computed once per state, when asked for.
        self._spread_cache = self.DeclareCacheEntry(
            "contact spread", ValueProducer(
                allocate=lambda: AbstractValue.Make(0.0),
                calc=lambda c, v: v.set_value(self._spread(self._get(c)))),
            prerequisites_of_calc=ticket)  # fmt: skip
        spread_ticket = {self._spread_cache.ticket()}
        self.DeclareVectorOutputPort("contact_spread", 1, self.calc_contact_spread,
                                     prerequisites_of_calc=spread_ticket)  # fmt: skip
        self.DeclareVectorOutputPort("contact_ambiguous", 1, self.calc_contact_ambiguous,
                                     prerequisites_of_calc=spread_ticket)  # fmt: skip
        self.DeclareAbstractOutputPort(
            "contact_points", lambda: AbstractValue.Make([np.zeros(3)]),
            self.calc_contact_points, prerequisites_of_calc=ticket)  # fmt: skip
        self.DeclarePeriodicUnrestrictedUpdateEvent(time_step, 0.0, self._update)

    def _get(self, context) -> _IsolatorState:
        return context.get_abstract_state(self._state).get_value()

    # ---------------------------------------------------------------------------------- outputs
    def calc_has_contact(self, context, output):
        output.SetFromVector([float(self._get(context).source != SOURCE_NONE)])

    def calc_contact_point(self, context, output):
        output.SetFromVector(np.asarray(self._get(context).point_W, dtype=float))

    def calc_contact_point_gripper(self, context, output):
        output.SetFromVector(np.asarray(self._get(context).point_G, dtype=float))

    def calc_isolation_cost(self, context, output):
        output.SetFromVector([float(self._get(context).cost)])

    def calc_contact_source(self, context, output):
        output.SetFromVector([float(self._get(context).source)])

    def calc_contact_spread(self, context, output):
        output.SetFromVector([self._spread_cache.Eval(context)])

    def calc_contact_ambiguous(self, context, output):
        output.SetFromVector([float(self._spread_cache.Eval(context) > self._ambiguity_distance)])

    def calc_contact_points(self, context, output):
        output.set_value(list(self._get(context).points_W))

    def _read(self, context, port) -> np.ndarray:
        return eval_finite("ContactIsolator", context, port)

    def _spread(self, state: _IsolatorState) -> float:
        """The isolation's contact_spread (m): 0 unless a CPF point (see the class doc)."""
        if state.line_of_action is None:
            return 0.0
        torque, force, index = state.line_of_action
        rival, _ = line_of_action_ambiguity(self.filter, torque, force, index, state.cost,
                                            tolerance=self._spacing)  # fmt: skip
        return rival

    def _update(self, context, state):
        old = self._get(context)
        step = old.step + 1
        new = _IsolatorState(step=step)
        flag = self._read(context, self._flag)[0] > 0.5
        if not flag:
            # Out of contact nothing else is read (the pose's kinematics and the wrench wait
            # for a contact); the step still counts, it keys the CPF's draws.
            state.get_mutable_abstract_state(self._state).set_value(new)
            return
        wrench = self._read(context, self._wrench)
        X_WG = pose_from_vector(self._read(context, self._pose))
        if self._n_bubbles:
            flags = self._read(context, self._bubble_flags) > 0.5
            points = self._read(context, self._bubble_points).reshape(-1, 3)
            if flags.any():
                first = points[np.argmax(flags)]
                new = dataclasses.replace(
                    new, point_W=first.copy(), point_G=X_WG.inverse().multiply(first),
                    points_W=tuple(p.copy() for p in points[flags]), source=SOURCE_BUBBLE,
                )  # fmt: skip
                flag = False  # bubbles answered: no CPF
        if flag:
            R_GW = X_WG.rotation().inverse()
            torque, force = R_GW.multiply(wrench[:3]), R_GW.multiply(wrench[3:])
            if np.linalg.norm(force) >= self._min_force:
                rng = np.random.default_rng([self._seed, step])
                ongoing = old.source == SOURCE_CPF
                previous = old.particles if (self._reuse and ongoing) else None
                total, count = np.r_[torque, force], 1
                if self._average and ongoing and old.wrench_sum is not None:
                    total, count = old.wrench_sum + total, old.wrench_count + 1
                    torque, force = total[:3] / count, total[3:] / count
                result, particles = self.filter.step(torque, force, rng, previous)
                if np.isfinite(result.cost):
                    point_W = X_WG.multiply(result.point)
                    new = dataclasses.replace(
                        new, particles=particles, point_W=point_W, point_G=result.point,
                        points_W=(point_W,), cost=result.cost, source=SOURCE_CPF,
                        line_of_action=(torque, result.force, result.index),
                        wrench_sum=total,
                        wrench_count=count,
                    )  # fmt: skip
        state.get_mutable_abstract_state(self._state).set_value(new)


__all__ = [
    "AVERAGE_WRENCH_DEFAULT",
    "SOURCE_BUBBLE",
    "SOURCE_CPF",
    "SOURCE_NONE",
    "ContactIsolator",
    "GripperPoseFromState",
    "line_of_action_ambiguity",
    "pose_from_vector",
    "pose_vector",
]
