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

The lanes are walked as :class:`~.lane_walk.LaneWalk` does. A lane whose felt object the
belief still does not place with some confidence, once touched again or probed, is pushed
through to its far end, contacts ignored: a guarded push never gets past clutter standing in
front of the target, a shove moves it aside. With ``shove_first`` that push comes as soon as
the touches beside are spent, before any probe, from where the gripper backed off: what stands
flush beside a heavy target is shoved along, and the target is probed after. The force a press
meets tells a heavy object from a light one (``shove_resisted_from``,
``shove_gave_way_below``), and a heavy one may be touched on its flank
(``flank_depth``, :mod:`~.flank`).

Planar points (x, y) in the world frame W (m); the gripper's yaw is fixed.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import ClassVar

import numpy as np

from stucco_drake.core.flank import plan_flank
from stucco_drake.core.lane_walk import LaneWalk, belief_of
from stucco_drake.core.motion_scale import GRAVITY
from stucco_drake.core.probing import FaceProbePolicy, outline_box
from stucco_drake.core.rummage_params import RummageParams
from stucco_drake.core.shapes import BoxSdf, CylinderSdf


class BeliefRummagingPolicy(LaneWalk):
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

    STEP_KINDS: ClassVar[dict[str, str]] = {"push": "push", "shove": "shove", "flank": "flank",
                                            "flank_ahead": "flank"}

    def __init__(self, shape: BoxSdf | CylinderSdf, footprint, max_step: float, start_xy,
                 params: RummageParams | None = None,
                 in_workspace: Callable[[np.ndarray], bool] | None = None,
                 target_mass: float | None = None):  # fmt: skip
        params = params or RummageParams()
        if params.shove_gave_way_below is not None and target_mass is None:
            raise ValueError("shove_gave_way_below: the policy needs the target's mass")
        super().__init__(footprint, max_step, start_xy, params, in_workspace)
        self.shape = shape
        self.target_weight = None if target_mass is None else float(target_mass) * GRAVITY
        self.reach = float(outline_box(np.zeros(3), shape)[1].max())  # the flank's (m)
        self.rounds = self.touches = self.shoves = 0
        # (action, confidence) each time the belief was asked.
        self.trace: list[tuple[int, float]] = []
        # action_kinds: "push" (a lane's or a touch beside's, guarded), "shove" (pushed
        # through), "flank" (see flank_depth), "travel", "back_off" (from a push's or a
        # travel's contact), "press" (see press_step) and "probe" (a probe round's, its
        # travel included).
        self._phases_done: dict[str, int] = {}  # the finished probe rounds' actions by phase
        self._lane_rounds = 0
        self._shoved = False
        self._shove_stops_from: float | None = None  # (N) where the shove under way ends
        self._shove_left: int | None = None  # its actions in contact before it ends
        self._flank_plan, self._flank_tries = None, 0  # the flank touch under way
        self._flank_again = False  # its second touch further along the face is under way
        self._flank_push = np.zeros(2)  # the direction of the push that met what it flanks
        self._verified = self._stopping = False
        self.confidence, self.pose = 0.0, None
        self._peak_force = float("nan")  # the last action's (N), see felt_force
        self._probe: FaceProbePolicy | None = None
        self._next_lane()

    def copy(self) -> BeliefRummagingPolicy:
        """A copy whose play does not change this one (settings, shape, footprint and lanes
        shared, read only)."""
        other = super().copy()
        other.trace = list(self.trace)
        other._phases_done = dict(self._phases_done)
        other._probe = None if self._probe is None else self._probe.copy()
        return other

    @property
    def probe_phases(self) -> dict[str, int]:
        """The probe rounds' actions by phase (:attr:`FaceProbePolicy.phase_actions`), the
        round under way included."""
        phases = dict(self._phases_done)
        for phase, count in (self._probe.phase_actions if self._probe else {}).items():
            phases[phase] = phases.get(phase, 0) + count
        return phases

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
        self.pose, self.confidence = belief_of(belief)
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
                if self._shove_left is not None:
                    self._shove_left -= 1
                    if self._shove_left <= 0:
                        return self._end_shove(xy)
                return self._follow(xy, belief)
            if kind == "flank_ahead" and self._gave_way():  # pushed along
                return self._follow(xy, belief)
            self._moving = False
            if kind in ("flank", "flank_ahead"):
                return self._flank_touched(kind)
            if kind == "push":
                return self._felt(xy, belief)
            return self._bumped(xy)
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
        through if its force says so (:meth:`_shove_cause`; what resisted is touched on its
        flank instead with ``flank_depth`` and no ``shove_resisted_for``), else probe it if
        the belief places it (and rounds are left), else touch it again beside the first
        touch (see ``retouches``), else leave the lane (:meth:`_leave_lane`); first back
        off."""
        if self._known(belief):
            return None
        p = self.params
        decides = p.shove_resisted_from is not None or p.shove_gave_way_below is not None
        if (decides and p.press_step > 0
                and not (pressed or self._shoved) and self._retouches == 0):  # a first touch
            return self._press()
        back = np.array([-self.params.back_off, 0.0])
        cause = self._shove_cause(pressed)
        if cause is not None:
            flank_now = cause == "resisted" and p.shove_resisted_for is None
            if not (flank_now and self._flank(xy)):
                self._leave_lane(xy, from_touch=True, at_once=True)
                self._shove_stops_from = p.shove_stops_from if cause == "gave_way" else None
                self._shove_left = p.shove_resisted_for if cause == "resisted" else None
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

    def _end_shove(self, xy) -> np.ndarray:
        """A shove met what resists (``shove_stops_from``), or slid along what resisted for
        ``shove_resisted_for`` actions: back off, then touch its flank (``flank_depth``) or
        assess."""
        far = next(point for kind, point in self._queue if kind == "shove")
        self._shove_stops_from, self._shove_left, self._moving = None, None, False
        if not self._flank(xy):
            self._queue = [("assess", far)]
        return self._bounce()

    def _flank(self, xy) -> bool:
        """With ``flank_depth``, queues the flank touch of the heavy object the push from
        ``xy`` met, planned after the back-off (:meth:`_plan_flank`); False when off."""
        if self.params.flank_depth is None:
            return False
        self._flank_push = self._last_step.copy()
        self._queue = [("plan_flank", xy.copy())]
        return True

    def _plan_flank(self, touch_xy) -> bool:
        """Plans the flank touch (:func:`~.flank.plan_flank`) from the push's contact, known
        now that the gripper has backed off (an action's contacts come an action late: at the
        push's own end the last known contact may be another object's); False when none
        is planned."""
        p = self.params
        if self._contact_xy is None:
            return False
        flank = plan_flank(touch_xy, self._contact_xy, self._flank_push, self.footprint,
                           self.reach, depth=p.flank_depth, margin=p.flank_margin,
                           back_off=p.back_off, centred=p.side_margin,
                           in_workspace=self.in_workspace)  # fmt: skip
        if flank is None:
            return False
        self._flank_plan, self._flank_tries, self._flank_again = flank, 0, False
        self._queue[:1] = self._flank_plan.legs()
        return True

    def _flank_touched(self, kind: str) -> np.ndarray:
        """The flank touch met something it did not push along: back off, then ask the
        belief; or, met while going forward (the object reaches further out than the plan
        said), go ``flank_step`` further out and ``flank_step_ahead`` further forward and try
        again (``flank_retries`` times); or, met by the sideways push with
        ``flank_again_ahead``, touch the face once more that much further forward."""
        p = self.params
        if kind == "flank_ahead" and not self._flank_again and self._flank_tries < p.flank_retries:
            self._flank_tries += 1
            self._flank_plan = self._flank_plan.further(p.flank_step, p.flank_step_ahead)
            self._queue = self._flank_plan.legs()
        elif kind == "flank" and self._may_flank_again():
            self._flank_again = True
            self._flank_plan = self._flank_plan.further(0.0, p.flank_again_ahead)
            self._queue = self._flank_plan.legs()[1:]  # from beside the object already
        else:
            self._queue = [("flanked", self._flank_plan.push_end)]
        return self._bounce()

    def _may_flank_again(self) -> bool:
        """Whether the face the flank met is to be touched again further forward (once, with
        ``flank_again_ahead``, where the waypoints are in the workspace)."""
        ahead = self.params.flank_again_ahead
        if ahead is None or self._flank_again:
            return False
        plan = self._flank_plan.further(0.0, ahead)
        return self.in_workspace(plan.past) and self.in_workspace(plan.push_end)

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

    def _next_lane(self) -> None:
        self._shoved, self._lane_rounds = False, 0
        self._shove_stops_from = self._shove_left = None
        super()._next_lane()

    def _marker(self, kind: str, point, xy, belief) -> tuple[bool, np.ndarray | None]:
        """Before a touch beside, with ``probe_once_placed``, probe at once if the belief
        places the felt object; once backed off from a heavy object, plan its flank touch;
        after a shove (or a flank touch), assess."""
        if kind == "retouch" and self.params.probe_once_placed and self._placed_now(belief):
            self._queue.pop(0)
            self._probe = self._new_probe()
            return True, self._decide(xy, False, belief)
        if kind == "plan_flank":
            if self._plan_flank(point):
                return True, self._follow(xy, belief)
            kind = "flanked"  # none planned: on as after one
        if kind in ("assess", "flanked"):
            self._queue.pop(0)
            return True, self._assess(xy, belief, leave=kind == "flanked")
        return False, None
