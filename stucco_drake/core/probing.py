"""Touching the target last: guarded probes of its likeliest pose, chosen from the belief.

A prescribed push script can move the target after its last sensed contact (a box turned by
the gripper sliding past it), and then no estimator can recover the final pose from the
contacts. A probe touches the target where the current pose hypotheses put one of its faces:
the gripper travels, around the hypothesised target, to a stand-off point in front of the
face, steps towards it until the detector reports contact (or it has gone well past where the
face should be), and backs off. Each probe is planned from the latest hypotheses, so a touch
that finds the face elsewhere corrects the next one. A contact while travelling (the target
where it was not believed to be, or clutter) is backed off from at once and the probe planned
again, so that the gripper does not drag what it bumped.

Which faces: first (``discriminate``, the default) those where the distinct likeliest
hypotheses predict different outcomes, the most informative first
(:mod:`~stucco_drake.core.probe_choice`); then a box's long face nearest the gripper at two
points (its yaw and one coordinate), then the nearer short face at its centre (the other
coordinate; or that first, ``end_face_first``); a cylinder from the two directions 45 degrees
either side of the gripper's. Probes whose stand-off point lies outside
the workspace, or (by default) that the gripper cannot reach in a straight line clear of the
hypothesised target, are skipped.

Everything is planar: points (x, y) in the world frame W (m), yaw about world z (rad). The
gripper's footprint is given as points in W axes about its origin (its yaw is fixed).
"""

from __future__ import annotations

import copy
import dataclasses
from collections.abc import Callable

import numpy as np

from stucco_drake.core.hypothesis_weights import distinct_rivals
from stucco_drake.core.probe_choice import face_probe_points, most_informative
from stucco_drake.core.probe_params import ProbeParams
from stucco_drake.core.probe_paths import rotation_2d, travel_waypoints
from stucco_drake.core.shapes import BoxSdf, CylinderSdf


@dataclasses.dataclass(frozen=True)
class Probe:
    """One touch: the face point to touch and the face's outward normal (both in W)."""

    point: np.ndarray
    normal: np.ndarray


def outline_box(pose, shape: BoxSdf | CylinderSdf) -> tuple[np.ndarray, np.ndarray, float]:
    """(centre (2,), half extents (2,), yaw) of the target's planar bounding box at ``pose``
    (x, y, yaw) in W; a cylinder's is the square about its circle."""
    pose = np.asarray(pose, dtype=np.float64)
    centre = pose[:2] + rotation_2d(pose[2]) @ np.asarray(shape.center, dtype=np.float64)[:2]
    if isinstance(shape, BoxSdf):
        half = np.asarray(shape.half_extents, dtype=np.float64)[:2]
    elif isinstance(shape, CylinderSdf):
        half = np.full(2, float(shape.radius))
    else:
        raise TypeError(f"unsupported target shape {type(shape).__name__}")
    return centre, half, float(pose[2])


def plan_probes(pose, shape: BoxSdf | CylinderSdf, gripper_xy, params: ProbeParams) -> list[Probe]:
    """The touches of the target at ``pose`` (x, y, yaw) seen from the gripper at
    ``gripper_xy``, in the order they are made (see the module's docstring)."""
    centre, half, yaw = outline_box(pose, shape)
    towards = np.asarray(gripper_xy, dtype=np.float64) - centre
    if isinstance(shape, CylinderSdf):
        base = np.arctan2(towards[1], towards[0])
        probes = []
        for angle in params.cylinder_angles:
            normal = np.array([np.cos(base + angle), np.sin(base + angle)])
            probes.append(Probe(centre + shape.radius * normal, normal))
        return probes
    R = rotation_2d(yaw)
    local = R.T @ towards
    long_axis = int(np.argmax(half))
    short_axis = 1 - long_axis
    # The long faces' normals lie along the short axis; take the one facing the gripper.
    long_normal = np.zeros(2)
    long_normal[short_axis] = 1.0 if local[short_axis] >= 0 else -1.0
    probes = []
    for fraction in params.long_face_offsets:
        along = np.zeros(2)
        along[long_axis] = fraction * half[long_axis]
        point = along + long_normal * half[short_axis]
        probes.append(Probe(centre + R @ point, R @ long_normal))
    end_normal = np.zeros(2)
    end_normal[long_axis] = 1.0 if local[long_axis] >= 0 else -1.0
    end = Probe(centre + R @ (end_normal * half[long_axis]), R @ end_normal)
    return [end, *probes] if params.end_face_first else [*probes, end]


def _path_length(points) -> float:
    return float(np.sum(np.linalg.norm(np.diff(np.asarray(points), axis=0), axis=1)))


def _shorter(step: np.ndarray, length: float) -> np.ndarray:
    """``step`` shortened to at most ``length`` (same direction)."""
    norm = float(np.linalg.norm(step))
    return step if norm <= length else step * (length / norm)


def footprint_support(footprint: np.ndarray, direction: np.ndarray) -> float:
    """How far (m) the gripper's footprint (m, 2) reaches from its origin along ``direction``."""
    return float(np.max(np.asarray(footprint) @ np.asarray(direction, dtype=np.float64)))


class FaceProbePolicy:
    """Plans and plays the probes, one planar step per action (see the module's docstring).

    Call :meth:`next_step` at the start of every action with where the gripper is, whether
    the action just finished sensed contact, and the likeliest target pose now (or pose
    hypotheses, whose ``pose`` is taken, or None, or a function returning any of them, called
    only when a probe is planned: hypotheses are costly); it
    returns the step (2,) (m, W) or None when probing is over. The probes are re-planned from
    the pose given at the start of each, and the k-th probe of that plan is made.

    Args:
        shape: the target's known geometry in its own frame.
        footprint: (m, 2) points of the gripper's planar footprint about its origin (W axes).
        max_step: per-axis clip of a step (m), the controller's.
        params: the probes' settings.
        in_workspace: whether a planar point (W) is one the gripper may be sent to.
    """

    def __init__(self, shape: BoxSdf | CylinderSdf, footprint, max_step: float,
                 params: ProbeParams | None = None,
                 in_workspace: Callable[[np.ndarray], bool] | None = None):  # fmt: skip
        self.shape, self.params = shape, params or ProbeParams()
        self.footprint = np.asarray(footprint, dtype=np.float64).reshape(-1, 2)
        self.max_step = float(max_step)
        self.in_workspace = in_workspace or (lambda xy: True)
        self.radius = float(np.max(np.linalg.norm(self.footprint, axis=1)))
        self.actions = 0
        self.touches = 0
        self.probes_done = 0
        self.discriminated = 0  # probes chosen for their information gain
        self._made: list[Probe] = []
        self._informative = False  # whether the current probe was chosen for its gain
        self.bumps = 0
        # Actions by phase: "travel", "approach", "retreat" (from a touch), "bump" (back from
        # a travel's contact).
        self.phase_actions: dict[str, int] = {}
        self._probe_bumps = 0
        self._phase, self._probe, self._waypoints = "plan", None, []
        self._last_phase, self._last_xy, self._last_step = "", None, np.zeros(2)

    def copy(self) -> FaceProbePolicy:
        """A copy whose play does not change this one (the settings, shape and footprint are
        shared, read only)."""
        other = copy.copy(self)
        other._waypoints = list(self._waypoints)
        other.phase_actions = dict(self.phase_actions)
        return other

    def next_step(self, gripper_xy, in_contact: bool, pose) -> np.ndarray | None:
        """The next action's step (m, W), or None when done (see the class docstring)."""
        xy = np.asarray(gripper_xy, dtype=np.float64)
        if self.actions >= self.params.max_actions:
            return None
        step = self._decide(xy, bool(in_contact), pose)
        self._last_xy = xy
        if step is None:
            return None
        self.actions += 1
        self.phase_actions[self._last_phase] = self.phase_actions.get(self._last_phase, 0) + 1
        self._last_step = np.clip(step, -self.max_step, self.max_step)
        return self._last_step

    def _decide(self, xy, in_contact: bool, pose):
        for _ in range(8):  # phase changes within one decision; a handful suffice
            if self._phase == "plan":
                pose = pose() if callable(pose) else pose
                hypotheses = pose if hasattr(pose, "costs") else None
                pose = getattr(pose, "pose", pose)  # pose hypotheses: their likeliest
                if pose is None or not self._plan(xy, pose, hypotheses):
                    return None
            elif self._phase == "travel":
                if in_contact and self._last_phase == "travel":
                    # Something is in the way (the target where it was not believed to be, or
                    # clutter): back off and plan this probe again from the updated belief.
                    return self._emit("bump", self._bump())
                step = self._travel(xy)
                if step is not None:
                    return self._emit("travel", step)
            elif self._phase == "approach":
                if in_contact and self._last_phase == "approach":
                    self.touches += 1
                    self._phase = "retreat"
                    continue
                step = self._approach(xy)
                if step is not None:
                    return self._emit("approach", step)
            else:  # retreat
                self._finish_probe()
                self._probe_bumps = 0
                self._phase = "plan"
                return self._emit("retreat", self._probe.normal * self.params.back_off)
        return None

    def _bump(self) -> np.ndarray:
        """The step back along the last travel step; the probe is given up after
        ``max_bumps`` bumps."""
        self.bumps += 1
        self._probe_bumps += 1
        if self._probe_bumps > self.params.max_bumps:
            self._finish_probe()
            self._probe_bumps = 0
        self._phase = "plan"
        direction = self._last_step / max(float(np.linalg.norm(self._last_step)), 1e-9)
        return -direction * self.params.back_off

    def _emit(self, phase: str, step: np.ndarray) -> np.ndarray:
        self._last_phase = phase
        return step

    def _finish_probe(self) -> None:
        """Counts the current probe as made (touched, passed, or given up)."""
        self.probes_done += 1
        self.discriminated += int(self._informative)
        if self._probe is not None:
            self._made.append(self._probe)

    def _made_near(self, probe: Probe) -> bool:
        """Whether a probe of nearly the same face point (2 cm, 30 degrees) was made."""
        return any(np.linalg.norm(probe.point - made.point) < 0.02
                   and float(probe.normal @ made.normal) > np.cos(np.radians(30.0))
                   for made in self._made)  # fmt: skip

    def _route(self, xy, pose, probe: Probe):
        """(approach start, travel waypoints) of ``probe`` of the target at ``pose``, or None
        when the gripper cannot make it (not direct, or out of the workspace)."""
        p = self.params
        centre, half, yaw = outline_box(pose, self.shape)
        # Travel ends outside the box grown by the footprint (its radius, or its extent along
        # the box's axes); the approach starts there, along the face's normal.
        margin, reach = self._margins(yaw, probe.normal)
        far = probe.point + probe.normal * (reach + p.clearance + p.standoff)
        grown = half + margin + p.clearance
        waypoints = travel_waypoints(xy, far, centre, grown, yaw)
        # Leaving the box's margin first (just backed off from a face) still counts as
        # direct: the exit is through the side the gripper is on.
        local = rotation_2d(yaw).T @ (xy - centre)
        exits = int(np.all(np.abs(local) < grown + 2e-3))
        direct = len(waypoints) <= 1 + exits or not p.direct_only
        if direct and all(self.in_workspace(w) for w in waypoints):
            return far, waypoints
        return None

    def _margins(self, yaw: float, normal: np.ndarray) -> tuple[np.ndarray, float]:
        """(margin (2,) along the box's axes at ``yaw``, reach along ``normal``) by which the
        footprint keeps its origin from the box (m): the radius, or with ``extent_margin``
        the footprint's largest extent either way along each axis and along the normal. The
        origin outside the box grown by the extents is outside the box's
        Minkowski sum with the footprint (that sum lies within its bounding box in the box's
        frame), so the footprint clears the box either way."""
        if not self.params.extent_margin:
            return np.full(2, self.radius), self.radius
        along = self.footprint @ rotation_2d(yaw)  # (m, 2) footprint in the box's axes
        return np.max(np.abs(along), axis=0), float(np.max(np.abs(self.footprint @ normal)))

    def _plan_informative(self, xy, pose, hypotheses) -> bool:
        """Sets up the probe the hypotheses disagree on most (``discriminate``); False when
        none gains ``min_gain``."""
        p = self.params
        if hypotheses is None or len(hypotheses.poses) < 2 or self.probes_done >= p.max_probes:
            return False
        rivals = distinct_rivals(hypotheses.poses, hypotheses.costs, p.max_rivals)
        poses = np.asarray(hypotheses.poses)[rivals]
        candidates = []
        for source in (pose, *poses):
            for probe in self._candidates(source, xy):
                route = None if self._made_near(probe) else self._route(xy, source, probe)
                if route is not None:
                    candidates.append((probe, *route))
        if p.face_step is not None:  # of equal gains, the nearest
            candidates.sort(key=lambda c: _path_length([xy, *c[2]]))
        felt = getattr(hypotheses, "felt", None) if p.felt_obstacles else None
        best = most_informative(candidates, poses, np.asarray(hypotheses.costs)[rivals],
                                self.shape, self.footprint, temperature=p.rival_temperature,
                                tolerance=p.outcome_tolerance, overshoot=p.overshoot,
                                start=xy, felt=felt, least_gain=p.min_gain,
                                steps=((p.travel_step, p.approach_step) if p.gain_per_action
                                       else None))  # fmt: skip
        if best is None:
            return False
        self._probe, self._waypoints, self._phase = best[1], best[2], "travel"
        self._informative = True
        return True

    def _candidates(self, pose, xy) -> list[Probe]:
        """The touches of the target at ``pose`` a discriminating probe is chosen among."""
        if self.params.face_step is None or isinstance(self.shape, CylinderSdf):
            return plan_probes(pose, self.shape, xy, self.params)
        centre, half, yaw = outline_box(pose, self.shape)
        points, normals = face_probe_points(centre, half, yaw, self.footprint,
                                            self.params.face_step)  # fmt: skip
        return [Probe(point, normal) for point, normal in zip(points, normals, strict=True)]

    def _plan(self, xy, pose, hypotheses=None) -> bool:
        """Sets up the next probe that can be made; False when none is left."""
        p = self.params
        if p.discriminate and self._plan_informative(xy, pose, hypotheses):
            return True
        self._informative = False
        while True:
            probes = plan_probes(pose, self.shape, xy, p)
            index = self.probes_done - self.discriminated
            if index >= len(probes) or (p.discriminate and self.probes_done >= p.max_probes):
                return False
            probe = probes[index]
            route = self._route(xy, pose, probe)
            if route is not None:
                self._probe, self._waypoints, self._phase = probe, route[1], "travel"
                return True
            self.probes_done += 1

    def _travel(self, xy):
        """The step towards the next waypoint, or None once the last is reached (the approach
        follows) or the gripper is stuck (the probe is given up)."""
        if self._last_phase == "travel" and self._last_xy is not None:
            moved = float(np.linalg.norm(xy - self._last_xy))
            if moved < 0.2 * float(np.linalg.norm(self._last_step)):
                self._finish_probe()
                self._phase = "plan"
                self._last_phase = ""
                return None
        while self._waypoints and np.linalg.norm(self._waypoints[0] - xy) < \
                self.params.arrive_tolerance:  # fmt: skip
            self._waypoints.pop(0)
        if not self._waypoints:
            self._phase = "approach"
            return None
        return _shorter(self._waypoints[0] - xy, self.params.travel_step)

    def _gap(self, xy) -> float:
        """Distance (m) from the gripper's footprint to the probed face's plane, along its
        normal (negative once past it)."""
        n = self._probe.normal
        return float((xy - self._probe.point) @ n) - footprint_support(self.footprint, -n)

    def _approach(self, xy):
        """The step towards the face: by up to ``travel_step`` to ``standoff`` from it, then
        by ``approach_step``; None (and the retreat) once ``overshoot`` past it."""
        p, n = self.params, self._probe.normal
        gap = self._gap(xy)
        if gap < -p.overshoot:
            self._phase = "retreat"
            return None
        if gap > p.standoff + p.approach_step:
            return -n * min(gap - p.standoff, p.travel_step)
        return -n * p.approach_step
