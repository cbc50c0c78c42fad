"""The settings of the rummaging chosen from the belief
(:class:`~stucco_drake.core.rummaging.BeliefRummagingPolicy`)."""

from __future__ import annotations

import dataclasses

from stucco_drake.core.coverage import CoverageParams
from stucco_drake.core.probe_params import ProbeParams


@dataclasses.dataclass(frozen=True)
class RummageParams:
    """Settings of :class:`BeliefRummagingPolicy` (m unless noted).

    Attributes:
        coverage: the lanes explored (the coverage sweep's, the nearest to the start first).
        probe: the probe rounds' settings (``max_actions``: of one round).
        stop_confidence: the target confidence at which the policy stops (the confidence from
            which a run counts as confident, ``stucco_drake.eval.sets.CONFIDENT_FROM``, chosen
            on the development layouts).
        verified_stop: stop only once the last probe round touched the target where the
            hypotheses put it (a confidence from a few points, none of them predicted, is
            no evidence that the target is among what was felt).
        back_off: step back along -x after a push that sensed contact.
        arrive_tolerance: distance at which a lane's waypoint counts as reached.
        max_actions: actions in all (with ``extend_below``, while the belief is sure enough).
        extend_below: None (off) or a confidence. Once ``max_actions`` are spent, the policy
            goes on while the belief's confidence is below this, up to
            ``extended_max_actions`` in all: a run whose target is not yet placed gets more
            actions, a placed one stops at the budget.
        extended_max_actions: see ``extend_below``.
        max_rounds: probe rounds in all.
        lane_rounds: probe rounds per lane (a round spent on clutter the belief took for the
            target leaves the rounds of the lanes after it).
        lane_bumps: contacts while moving to or from a lane's push before the lane is left.
        retouches: how many times a felt object the belief does not place yet is pushed
            again before the lane is left (a single touch leaves too few points for any
            pose), each ``retouch_step`` further along y from the first touch, towards the
            side of the gripper the contact was sensed on (more than ``side_margin`` from its
            centre line), else to one side, then the other.
        retouch_step: see ``retouches``.
        retouch_back: how far behind where the gripper backed off to a touch beside moves
            sideways (never behind the lanes' x); a bump on the way there sends it round by
            the lanes' x instead. None: always by the lanes' x, behind the start (clear of a
            neighbour standing a step back from the felt object, at the cost of the way back
            and forth).
        side_margin: see ``retouches``.
        transit_back: how far behind the start (along -x, as far as the workspace allows)
            the lanes begin and end: travel between lanes then passes clear of objects just
            in front of the start, which the gripper's front (4 cm ahead of its origin)
            would graze.
        push_through_below: a lane whose felt object, once touched again or probed, the
            belief places with a confidence below this is pushed through to its far end,
            contacts ignored (once per lane; 0: never).
        shove_first: once its touches are spent, a lane whose felt object the belief places
            with a confidence below ``push_through_below`` is pushed through at once, from
            where the gripper backed off the last touch, and probed after. False: probed
            first, pushed through from the lane's start if still not placed, as every folder
            before the development layouts' thirty-first look, where this was tried: three
            points place a can at 0.99 or more, so it is probed; a box is placed lower and
            shoved at, and the 10 kg box there stays put while what stands beside it is
            shoved along (a light box would be shoved away).
        shove_resisted_from: None (off) or a force (N). Where a lane's first touch met an
            object that resisted, the touch's peak force (the detector's estimate of the
            external force on the end effector) reaching this, the lane is pushed through at
            once from where the gripper backs off, whatever ``retouches`` says, as
            ``shove_first`` with no touch beside, while the belief places that object below
            ``push_through_below``. One that gave way is touched beside and probed as without
            ``shove_first``. A heavy or blocked object resists up to the controller's push
            limit; a light one slides at a few newtons, so it is not shoved away.
        press_step: 0, or a distance (m): with ``shove_resisted_from`` or
            ``shove_gave_way_below``, the touch goes on along the push by this much for one
            more action, a press, whose force decides instead: a touch may come at the end of
            its action, before the force builds up.
        shove_gave_way_below: None (off) or a fraction of the known target's weight (its
            mass times g; the policy is given the mass). A press (``press_step``) whose peak
            force stays below this fraction of it met something that slid more easily than
            the target can (the target needs its friction force, about half its weight on the
            table, to slide), so it is not the target: the lane is pushed through at once, as
            for an object that resisted. Needs ``press_step`` (a touch alone may end before
            its force builds up).
        shove_stops_from: None (off) or a force (N). A lane pushed through because its press
            gave way (``shove_gave_way_below``) ends at the first action of the shove that
            meets at least this force: the light object is shoved aside and something behind
            it resists, a candidate for a heavy target. The gripper backs off and the belief
            is asked at once (probed if it places the target) instead of pushing on into it
            and going back to the lanes' x. A shove begun on an object that resisted goes on
            as before: shoving along a heavy target moves its neighbours aside.
        shove_resisted_for: None (off) or a number of actions. A shove begun because the
            press resisted ends after this many of its actions have sensed contact (the
            gripper sliding along the heavy object's face, a contact each), where the gripper
            backs off and touches the object's flank (``flank_depth``) or asks the belief.
            Without it, ``flank_depth`` flanks such an object at once, unshoved.
        flank_depth: None (off) or a distance (m). A heavy object met, its press resisting
            (``shove_resisted_from``) or a shove stopping on it (``shove_stops_from``), is
            touched on its flank before anything else (:mod:`~stucco_drake.core.flank`):
            the gripper backs off, moves sideways clear of it, forward until its front is this
            far past the touched face, and pushes sideways back towards the touch, guarded. A
            box touched on one face only can be read a quarter turn wrong; the face beside
            it tells. What the forward move meets is pushed along if it gives way
            (``shove_gave_way_below``: it is not the target), else the gripper backs off and
            goes ``flank_step`` further out and ``flank_step_ahead`` further forward,
            ``flank_retries`` times (the object reached further than its contact said; a face
            met again further out slants away from the push, and the face beside it begins
            further ahead). Then the belief is asked (probed if it places the
            target), else the lane is left as after a touch.
        flank_margin: how far clear of the object's estimated edge the flank's forward move
            passes (m).
        flank_step: see ``flank_depth`` (m).
        flank_step_ahead: see ``flank_depth`` (m).
        flank_retries: see ``flank_depth``.
        flank_again_ahead: None (off) or a distance (m). Once the flank's sideways push has
            met the face beside, touch that face once more this far further forward: forward
            beside it, then sideways towards it again, guarded. A face touched only near its
            corner fits a box a quarter turn away as well; further along, only the right one.
        probe_once_placed: before each touch beside, once the touch before has been backed
            off from and its contacts are known, ask the belief again and probe at once if it
            places the felt object, instead of touching beside first (the decision at the
            touch itself is made before its contacts reach the tracker). With hypotheses from
            one point on (``HypothesisParams.min_explained`` 1) the first touch is followed by
            the probes chosen where the hypotheses disagree.
        check_each_probe: ask the belief after each probe of a round that touched the
            target (any probe without ``verified_stop``), not only once the round is over,
            and stop there once it passes ``stop_confidence``.
    """

    coverage: CoverageParams = dataclasses.field(
        default_factory=lambda: CoverageParams(nearest_first=True))
    probe: ProbeParams = dataclasses.field(default_factory=lambda: ProbeParams(max_actions=30))
    stop_confidence: float = 0.999
    verified_stop: bool = True
    back_off: float = 0.02
    arrive_tolerance: float = 0.005
    max_actions: int = 120
    extend_below: float | None = None
    extended_max_actions: int = 0
    max_rounds: int = 6
    lane_rounds: int = 2
    lane_bumps: int = 2
    retouches: int = 2
    retouch_step: float = 0.03
    retouch_back: float | None = None
    side_margin: float = 0.01
    transit_back: float = 0.04
    push_through_below: float = 0.5
    shove_first: bool = False
    shove_resisted_from: float | None = None
    press_step: float = 0.0
    shove_gave_way_below: float | None = None
    shove_stops_from: float | None = None
    shove_resisted_for: int | None = None
    flank_depth: float | None = None
    flank_margin: float = 0.01
    flank_step: float = 0.03
    flank_step_ahead: float = 0.0
    flank_retries: int = 2
    flank_again_ahead: float | None = None
    probe_once_placed: bool = False
    check_each_probe: bool = False

    @property
    def action_budget(self) -> int:
        """The most actions a run may take (``extended_max_actions`` when extended)."""
        return self.max_actions if self.extend_below is None else self.extended_max_actions

    def __post_init__(self):
        if self.extend_below is not None and self.extended_max_actions <= self.max_actions:
            raise ValueError(f"extended_max_actions: with extend_below, needs more than "
                             f"max_actions ({self.max_actions}), got "
                             f"{self.extended_max_actions}")
        if self.shove_gave_way_below is not None and not self.press_step > 0:
            raise ValueError("shove_gave_way_below: needs press_step > 0 (a touch alone may "
                             "end before its force builds up)")
        if self.shove_stops_from is not None and self.shove_gave_way_below is None:
            raise ValueError("shove_stops_from: ends only the shoves of "
                             "shove_gave_way_below, which is not set")
        if self.shove_resisted_for is not None and self.shove_resisted_from is None:
            raise ValueError("shove_resisted_for: ends only the shoves of "
                             "shove_resisted_from, which is not set")
        if (self.flank_depth is not None and self.shove_resisted_from is None
                and self.shove_stops_from is None):
            raise ValueError("flank_depth: flanks only what shove_resisted_from or "
                             "shove_stops_from finds heavy, and neither is set")
