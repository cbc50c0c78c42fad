"""Rummaging chosen from the belief: explore until something is felt, probe the likeliest
target pose, stop once the target is known.

A prescribed script is written for one layout, and a coverage sweep (:mod:`.coverage`) pushes
through everything whatever it feels. This policy explores the same lanes, but guarded: a push
that senses contact ends there (the gripper backs off instead of shoving on), and the belief is
asked what was felt. When the target-pose hypotheses put the target somewhere, a round of
guarded face probes (:class:`~.probing.FaceProbePolicy`) touches it where they say; when their
confidence (the posterior probability that the grasp closes with margin) passes
``stop_confidence``, and the last probe round touched the target where they put it, the
policy stops and the robot grasps (the hypotheses only explain what was felt: until a
prediction of theirs has been touched, a target never touched may be what they miss).
Otherwise it goes on with the next lane; a lane through the likeliest target is still pushed,
guarded: it touches the target's near face again (at 30 N the gripper does not shove a 10 kg
target away), more evidence where it is least certain. It also stops when the lanes or the
action budget run out.

Two things keep it from wearing itself out on clutter. The gripper travels between lanes a
little behind its start, clear of what stands just in front of it, and a travel that keeps
bumping into something gives up every lane beyond it on that side (they are reached the same
way). And a lane whose felt object the belief still does not place with some confidence, once
touched again or probed, is pushed through to its far end, contacts ignored: a guarded push
never gets past clutter standing in front of the target, a shove moves it aside. With
``shove_first`` that push comes as soon as the touches beside are spent, before any probe, from
where the gripper backed off: what stands flush beside a heavy target is shoved along, and the
target is probed after.

Planar points (x, y) in the world frame W (m); the gripper's yaw is fixed.
"""

from __future__ import annotations

import copy
from collections.abc import Callable

import numpy as np

from stucco_drake.core.coverage import coverage_waypoints
from stucco_drake.core.flank import plan_flank
from stucco_drake.core.probing import FaceProbePolicy, outline_box
from stucco_drake.core.rummage_params import RummageParams
from stucco_drake.core.shapes import BoxSdf, CylinderSdf

GRAVITY = 9.81  # m/s^2


def _belief_of(belief) -> tuple[np.ndarray | None, float]:
    """(likeliest pose or None, confidence) of the pose hypotheses ``belief`` (an object with
    ``pose`` and ``confidence``, None, or a function returning either)."""
    belief = belief() if callable(belief) else belief
    if belief is None:
        return None, 0.0
    return np.asarray(belief.pose, dtype=np.float64), float(belief.confidence)


class BeliefRummagingPolicy:
    """Plays the rummaging one planar step per action (see the module's docstring).

    Call :meth:`next_step` at the start of every action with where the gripper is, whether
    the action just finished sensed contact, and the pose hypotheses (an object with ``pose``
    (x, y, yaw) and ``confidence``, None, or a function returning either: called only after a
    contact, when a probe is planned or the confidence is needed). It returns the step (2,)
    (m, W), or None once the policy stops.

    Args:
        shape: the target's known geometry in its own frame.
        footprint: (m, 2) points of the gripper's planar footprint about its origin (W axes).
        max_step: per-axis clip of a step (m), the controller's.
        start_xy: where the gripper starts (the lanes start and end at its x).
        params: the settings.
        in_workspace: whether a planar point (W) is one the gripper may be sent to.
        target_mass: the target's known mass (kg), needed by ``shove_gave_way_below``.
    """

    def __init__(self, shape: BoxSdf | CylinderSdf, footprint, max_step: float, start_xy,
                 params: RummageParams | None = None,
                 in_workspace: Callable[[np.ndarray], bool] | None = None,
                 target_mass: float | None = None):  # fmt: skip
        self.shape, self.params = shape, params or RummageParams()
        if self.params.shove_gave_way_below is not None and target_mass is None:
            raise ValueError("shove_gave_way_below: the policy needs the target's mass")
        self.target_weight = None if target_mass is None else float(target_mass) * GRAVITY
        self.footprint = np.asarray(footprint, dtype=np.float64).reshape(-1, 2)
        self.max_step = float(max_step)
        self.reach = float(outline_box(np.zeros(3), shape)[1].max())  # the flank's (m)
        self.in_workspace = in_workspace or (lambda xy: True)
        width = float(np.ptp(self.footprint[:, 1]))
        self.lanes = coverage_waypoints(start_xy, self.params.coverage, width,
                                        self.in_workspace, self.params.transit_back,
                                        ).reshape(-1, 3, 2)  # fmt: skip
        self.actions = self.rounds = self.touches = self.contacts = self.bumps = 0
        self.shoves = 0
        # (action, confidence) each time the belief was asked.
        self.trace: list[tuple[int, float]] = []
        # Actions by what they were for: "push" (a lane's or a touch beside's, guarded),
        # "shove" (pushed through), "travel", "back_off" (from a push's or a travel's
        # contact), "press" (see press_step) and "probe" (a probe round's, its
        # travel included).
        self.action_kinds: dict[str, int] = {}
        self._phases_done: dict[str, int] = {}  # the finished probe rounds' actions by phase
        self._kind = "travel"
        self._lane_rounds = 0
        self._skipped: set[int] = set()
        self._shoved = False
        self._shove_stops_from: float | None = None  # (N) where the shove under way ends
        self._flank_plan, self._flank_tries = None, 0  # the flank touch under way
        self._verified = self._stopping = False
        self.confidence, self.pose = 0.0, None
        self._lane, self._lane_bumps, self._retouches = -1, 0, 0
        self._touch_y, self._contact_xy = 0.0, None
        self._peak_force = float("nan")  # the last action's (N), see felt_force
        # The touch beside under way while it is reached by the near way (its y and push
        # end), to be reached by the lanes' x instead if that way bumps.
        self._near_retouch: tuple[float, float] | None = None
        # The waypoints ahead: (kind, point), kind "push" (a contact there is felt) or "move".
        self._queue: list[tuple[str, np.ndarray]] = []
        self._stopped = False
        self._probe: FaceProbePolicy | None = None
        self._last_step, self._moving, self._last_xy = np.zeros(2), False, None
        self._next_lane()

    def copy(self) -> BeliefRummagingPolicy:
        """A copy whose play does not change this one (settings, shape, footprint and lanes
        shared, read only)."""
        other = copy.copy(self)
        other._queue = list(self._queue)
        other._skipped = set(self._skipped)
        other.trace = list(self.trace)
        other.action_kinds = dict(self.action_kinds)
        other._phases_done = dict(self._phases_done)
        other._probe = None if self._probe is None else self._probe.copy()
        return other

    def next_step(self, gripper_xy, in_contact: bool, belief) -> np.ndarray | None:
        """The next action's step (m, W), or None once stopped (see the class docstring)."""
        if self.actions >= self.params.max_actions or self._stopped:
            return None
        xy = np.asarray(gripper_xy, dtype=np.float64)
        step = self._decide(xy, bool(in_contact), belief)
        self._last_xy = xy
        if step is None:
            self._stopped = True  # for good
            return None
        self.actions += 1
        self.action_kinds[self._kind] = self.action_kinds.get(self._kind, 0) + 1
        self._last_step = np.clip(step, -self.max_step, self.max_step)
        return self._last_step

    @property
    def probe_phases(self) -> dict[str, int]:
        """The probe rounds' actions by phase (:attr:`FaceProbePolicy.phase_actions`), the
        round under way included."""
        phases = dict(self._phases_done)
        for phase, count in (self._probe.phase_actions if self._probe else {}).items():
            phases[phase] = phases.get(phase, 0) + count
        return phases

    def sensed(self, points) -> None:
        """The contact points (m, W) of the latest action whose contacts are known (they come
        an action late: an action's contacts are formed after the next one is decided); an
        empty set keeps the last non-empty one's."""
        points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        if len(points):
            self._contact_xy = points[:, :2].mean(axis=0)

    def felt_force(self, peak_force: float) -> None:
        """The peak force (N) of the action that just ended (NaN: not measured), given
        before :meth:`next_step`; read by the ``shove_*`` settings."""
        self._peak_force = float(peak_force)

    def _shove_cause(self, pressed: bool) -> str | None:
        """Why the lane is pushed through at once after the touch (or press) just made, or
        None: not shoved yet, the felt object placed below ``push_through_below``, and its
        force (NaN compares False) either "resisted" (``shove_resisted_from``) or, after a
        press, "gave_way" more easily than the target could (``shove_gave_way_below``)."""
        p, force = self.params, self._peak_force
        if self._shoved or self.confidence >= p.push_through_below:
            return None
        if p.shove_resisted_from is not None and force >= p.shove_resisted_from:
            return "resisted"
        if pressed and self._gave_way():
            return "gave_way"
        return None

    def _gave_way(self) -> bool:
        """Whether the last action's force (NaN: False) stayed below what the target needs
        to slide (``shove_gave_way_below``; False when that is off)."""
        fraction = self.params.shove_gave_way_below
        return fraction is not None and self._peak_force < fraction * self.target_weight

    def _press(self) -> np.ndarray:
        """One more action along the push that felt something (see ``press_step``); the
        next decision reads its force."""
        self._queue = [("pressed", np.zeros(2))]
        self._kind, self._moving = "press", False
        push = self._last_step / max(float(np.linalg.norm(self._last_step)), 1e-9)
        return push * self.params.press_step

    def _believe(self, belief) -> float:
        self.pose, self.confidence = _belief_of(belief)
        self.trace.append((self.actions, self.confidence))
        return self.confidence

    def _known(self, belief) -> bool:
        """Whether to stop: the belief's confidence (asked) passes ``stop_confidence`` and,
        with ``verified_stop``, the last probe round touched the target."""
        confident = self._believe(belief) >= self.params.stop_confidence
        return confident and (self._verified or not self.params.verified_stop)

    def _may_probe(self) -> bool:
        p = self.params
        if p.shove_first and not self._shoved and self.confidence < p.push_through_below:
            return False  # the lane is pushed through first
        return (self.pose is not None and self.rounds < p.max_rounds
                and self._lane_rounds < p.lane_rounds)

    def _end_round(self) -> None:
        """Counts the probe round under way as done."""
        self.touches += self._probe.touches
        self._verified = self._probe.touches > 0
        self.bumps += self._probe.bumps
        self._phases_done = self.probe_phases
        self.rounds += 1
        self._lane_rounds += 1
        self._probe = None

    def _probe_step(self, xy, in_contact: bool, belief):
        """The probe round's next step, or None when the round is over or, with
        ``check_each_probe``, a probe that touched the target left it known (then the
        policy stops)."""
        made, touched = self._probe.probes_done, self._probe.touches
        step = self._probe.next_step(xy, in_contact, belief)
        self._kind = "probe"
        if step is None or not self.params.check_each_probe or self._probe.probes_done == made:
            return step
        if self._probe.touches == touched and self.params.verified_stop:
            return step
        if self._believe(belief) >= self.params.stop_confidence:
            self._end_round()
            self._stopping = True
            return None
        return step

    def _decide(self, xy, in_contact: bool, belief):
        if self._queue and self._queue[0][0] == "pressed":
            self._queue.pop(0)
            return self._felt(xy, belief, pressed=True)
        if self._probe is not None:
            step = self._probe_step(xy, in_contact, belief)
            if step is not None or self._stopping:
                return step
            self._end_round()
            if self._known(belief):
                return None
            self._leave_lane(xy)
        elif in_contact and self._moving:
            self.contacts += 1
            kind = self._queue[0][0] if self._queue else "move"
            if kind == "shove":  # contacts ignored: the push goes on
                stops = self._shove_stops_from
                if stops is not None and self._peak_force >= stops:  # NaN compares False
                    return self._end_shove(xy)
                return self._follow(xy, belief)
            if kind == "flank_ahead" and self._gave_way():  # pushed along
                return self._follow(xy, belief)
            self._moving = False
            if kind in ("flank", "flank_ahead"):
                return self._flank_touched(kind)
            if kind == "push":
                return self._felt(xy, belief)
            self.bumps += 1
            if self._near_retouch is not None:  # round by the lanes' x instead
                return self._retouch_round(xy)
            self._lane_bumps += 1
            if self._lane_bumps > self.params.lane_bumps:
                self._skip_beyond(xy)
                self._next_lane()
            return self._bounce()
        return self._follow(xy, belief)

    def _assess(self, xy, belief, leave: bool = False) -> np.ndarray | None:
        """After a lane pushed through (or a flank touch): stop if the target is known,
        else probe it if the belief places it (and rounds are left), else go on (``leave``:
        leave the lane, :meth:`_leave_lane`)."""
        if self._known(belief):
            return None
        if self._may_probe():
            self._probe = self._new_probe()
            return self._decide(xy, False, belief)
        if leave:
            self._leave_lane(xy)
        return self._follow(xy, belief)

    def _new_probe(self) -> FaceProbePolicy:
        return FaceProbePolicy(self.shape, self.footprint, self.max_step, self.params.probe,
                               self.in_workspace)

    def _felt(self, xy, belief, pressed: bool = False) -> np.ndarray | None:
        """A push sensed contact: stop if the target is known, else (with
        ``shove_resisted_from`` or ``shove_gave_way_below``) press it once and push the lane
        through if its force says so (:meth:`_shove_cause`), else probe it if the belief
        places it (and rounds are left), else touch it again beside the first touch (see
        ``retouches``), else leave the lane (:meth:`_leave_lane`); first back off."""
        if self._known(belief):
            return None
        p = self.params
        decides = p.shove_resisted_from is not None or p.shove_gave_way_below is not None
        if (decides and p.press_step > 0
                and not (pressed or self._shoved) and self._retouches == 0):  # a first touch
            return self._press()
        back = np.array([-self.params.back_off, 0.0])
        cause = self._shove_cause(pressed)
        if cause == "resisted" and self._flank(xy):
            pass  # touched on its flank first
        elif cause is not None:
            self._leave_lane(xy, from_touch=True, at_once=True)
            if cause == "gave_way":
                self._shove_stops_from = p.shove_stops_from
        elif self._may_probe():
            self._probe = self._new_probe()
        elif self._retouches < self.params.retouches:
            if self._retouches == 0:
                self._touch_y = float(xy[1])
            # Which way is decided after the back-off, once this touch's contacts are known.
            self._queue = [("retouch", np.array([self._queue[0][1][0], self._touch_y]))]
        else:
            self._leave_lane(xy, from_touch=True)
        self._kind = "back_off"
        return back

    def _placed_now(self, belief) -> bool:
        """Whether, asked again once the last touch's contacts are known (they come an action
        late), the belief places the felt object and a probe round may start."""
        self._believe(belief)
        return self._may_probe()

    def _retouch(self, xy, far_touch) -> list[tuple[str, np.ndarray]]:
        """The waypoints of the next touch beside the first (at y ``far_touch[1]``, pushed to
        x ``far_touch[0]``): back to the lanes' x, sideways, the push, and back."""
        p = self.params
        k, self._retouches = self._retouches, self._retouches + 1
        side = 0.0 if self._contact_xy is None else self._contact_xy[1] - far_touch[1]
        if abs(side) > p.side_margin:
            offset = np.sign(side) * (k + 1) * p.retouch_step
        else:  # centred: one side, then the other
            offset = (1.0 if k % 2 == 0 else -1.0) * (k // 2 + 1) * p.retouch_step
        y = far_touch[1] + offset
        # Sideways along the lanes' x, behind the start: beside the felt object, a step
        # back from it, often stands its neighbour (unless ``retouch_back`` says nearer).
        lane_x = self.lanes[self._lane, 0, 0]
        side_x = lane_x if p.retouch_back is None else max(lane_x, xy[0] - p.retouch_back)
        self._near_retouch = None if side_x == lane_x else (y, float(far_touch[0]))
        return self._retouch_legs(xy, side_x, y, far_touch[0])

    def _retouch_legs(self, xy, side_x, y, push_x) -> list[tuple[str, np.ndarray]]:
        lane_x = self.lanes[self._lane, 0, 0]
        return [("move", np.array([side_x, xy[1]])), ("move", np.array([side_x, y])),
                ("push", np.array([push_x, y])), ("move", np.array([lane_x, y]))]

    def _retouch_round(self, xy) -> np.ndarray:
        """The near way to a touch beside bumped: back off, then the lanes' x way."""
        (y, push_x), self._near_retouch = self._near_retouch, None
        self._queue = self._retouch_legs(xy, self.lanes[self._lane, 0, 0], y, push_x)
        return self._bounce()

    def _end_shove(self, xy) -> np.ndarray:
        """A shove met what resists (``shove_stops_from``): back off, then touch its flank
        (``flank_depth``) or assess."""
        far = next(point for kind, point in self._queue if kind == "shove")
        self._shove_stops_from, self._moving = None, False
        if not self._flank(xy):
            self._queue = [("assess", far)]
        return self._bounce()

    def _flank(self, xy) -> bool:
        """With ``flank_depth``, queues the flank touch (:func:`~.flank.plan_flank`) of the
        heavy object the last push met, after the back-off; False when off or not planned."""
        p = self.params
        if p.flank_depth is None or self._contact_xy is None:
            return False
        flank = plan_flank(xy, self._contact_xy, self._last_step, self.footprint, self.reach,
                           depth=p.flank_depth, margin=p.flank_margin, back_off=p.back_off,
                           centred=p.side_margin, in_workspace=self.in_workspace)  # fmt: skip
        if flank is None:
            return False
        self._flank_plan, self._flank_tries = flank, 0
        self._queue = self._flank_legs()
        return True

    def _flank_legs(self) -> list[tuple[str, np.ndarray]]:
        plan = self._flank_plan
        return [("move", plan.side), ("flank_ahead", plan.past), ("flank", plan.push_end),
                ("flanked", plan.push_end)]  # fmt: skip

    def _flank_touched(self, kind: str) -> np.ndarray:
        """The flank touch met something it did not push along: back off, then ask the
        belief; or, met while going forward (the object reaches further out than the plan
        said), go ``flank_step`` further out and try again (``flank_retries`` times)."""
        if kind == "flank_ahead" and self._flank_tries < self.params.flank_retries:
            self._flank_tries += 1
            self._flank_plan = self._flank_plan.further(self.params.flank_step)
            self._queue = self._flank_legs()
        else:
            self._queue = [("flanked", self._flank_plan.push_end)]
        return self._bounce()

    def _bounce(self) -> np.ndarray:
        """The back-off from a travel's contact: back along the last step."""
        back = self._last_step / max(float(np.linalg.norm(self._last_step)), 1e-9)
        self._kind = "back_off"
        return -back * self.params.back_off

    def _withdraw(self, xy) -> None:
        """Back along -x to the lanes' x at ``xy``'s y; then the next lane."""
        self._queue = [("move", np.array([self.lanes[self._lane, 0, 0], xy[1]]))]

    def _leave_lane(self, xy, from_touch: bool = False, at_once: bool = False) -> None:
        """Done with what the lane's push felt: withdraw, or, where the belief places it
        with a confidence below ``push_through_below``, push the lane through (once; with
        ``shove_first`` or ``at_once``, from where the gripper backs off to when ``xy`` is a
        touch's)."""
        if self._shoved or self.confidence >= self.params.push_through_below:
            self._withdraw(xy)
            return
        self._shoved, self.shoves = True, self.shoves + 1
        start, far, back = self.lanes[self._lane]
        if (self.params.shove_first or at_once) and from_touch:  # on from the back-off
            self._queue = [("move", np.array([xy[0] - self.params.back_off, start[1]]))]
        else:
            self._queue = [("move", np.array([start[0], xy[1]])), ("move", start)]
        self._queue += [("shove", far), ("move", back), ("assess", far)]

    def _skip_beyond(self, xy) -> None:
        """The travel to a waypoint keeps bumping: the lanes that lie beyond the gripper on
        that side (reached the same way) are given up."""
        side = np.sign(self._queue[0][1][1] - xy[1]) if self._queue else 0.0
        for j in range(self._lane + 1, len(self.lanes)):
            if side and (self.lanes[j, 0, 1] - xy[1]) * side > 0:
                self._skipped.add(j)

    def _next_lane(self) -> None:
        self._near_retouch = None
        self._lane, self._lane_bumps, self._retouches = self._lane + 1, 0, 0
        self._shoved, self._lane_rounds, self._shove_stops_from = False, 0, None
        while self._lane in self._skipped:
            self._lane += 1
        if self._lane < len(self.lanes):
            start, far, back = self.lanes[self._lane]
            self._queue = [("move", start), ("push", far), ("move", back)]
        else:
            self._queue = []

    def _follow(self, xy, belief) -> np.ndarray | None:
        """The step towards the next waypoint (the next lane's once the queue is done), or
        None once the lanes are done. A waypoint the gripper stopped moving towards without
        sensing contact (held by something it does not feel) is given up: a push's lane is
        withdrawn from."""
        moved = np.inf if self._last_xy is None else np.linalg.norm(xy - self._last_xy)
        if self._moving and self._queue and moved < 0.2 * np.linalg.norm(self._last_step):
            if self._queue[0][0] == "push":
                self._withdraw(xy)
            else:
                self._queue.pop(0)
        for _ in range(3 * len(self.lanes) + 8):
            if not self._queue:
                if self._lane >= len(self.lanes):
                    return None
                self._next_lane()
                continue
            kind, point = self._queue[0]
            if kind == "retouch":
                if self.params.probe_once_placed and self._placed_now(belief):
                    self._queue.pop(0)
                    self._probe = self._new_probe()
                    return self._decide(xy, False, belief)
                self._queue[:1] = self._retouch(xy, point)
                continue
            if kind in ("assess", "flanked"):
                self._queue.pop(0)
                return self._assess(xy, belief, leave=kind == "flanked")
            if np.linalg.norm(point - xy) < self.params.arrive_tolerance:
                self._queue.pop(0)
                continue
            self._moving = True
            self._kind = {"push": "push", "shove": "shove", "flank": "flank",
                          "flank_ahead": "flank"}.get(kind, "travel")  # fmt: skip
            if kind != "move":  # the way to a touch beside is behind
                self._near_retouch = None
            # The rest of the leg in equal steps, as few as the clip allows (the sweep's).
            leg = point - xy
            return leg / np.ceil(float(np.max(np.abs(leg))) / self.max_step - 1e-9)
        return None
