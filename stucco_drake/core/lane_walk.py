"""The coverage lanes walked one guarded push at a time: the moves under the rummaging chosen
from the belief (:class:`~stucco_drake.core.rummaging.BeliefRummagingPolicy`), which decides
what a felt contact means.

The gripper follows a queue of waypoints, each reached in equal steps as few as the
controller's clip allows: "move" (travel: a contact is a bump, backed off from) and "push" (a
lane's or a touch beside's: a contact there is felt, :meth:`LaneWalk._felt`), and the kinds a
subclass gives a meaning. Two things keep it from wearing itself out on clutter. The gripper
travels between lanes a little behind its start, clear of what stands just in front of it,
and a travel that keeps bumping into something gives up every lane beyond it on that side
(they are reached the same way). A felt object is touched again beside the first touch
(``retouches``), reached sideways along the lanes' x or, with ``retouch_back``, nearer.

Planar points (x, y) in the world frame W (m); the gripper's yaw is fixed.
"""

from __future__ import annotations

import copy
from collections.abc import Callable
from typing import ClassVar

import numpy as np

from stucco_drake.core.coverage import coverage_waypoints
from stucco_drake.core.rummage_params import RummageParams

#: A queue entry: (kind, point W).
Waypoint = tuple[str, np.ndarray]


def belief_of(belief) -> tuple[np.ndarray | None, float]:
    """(likeliest pose or None, confidence) of the pose hypotheses ``belief`` (an object with
    ``pose`` and ``confidence``, None, or a function returning either)."""
    belief = belief() if callable(belief) else belief
    if belief is None:
        return None, 0.0
    return np.asarray(belief.pose, dtype=np.float64), float(belief.confidence)


class LaneWalk:
    """The lanes and the queue of waypoints (see the module's docstring). A subclass
    implements :meth:`_decide` (the step of each action), :meth:`_felt` (a push sensed
    contact) and :meth:`_marker` (a queue entry that is a decision, not a waypoint), and calls
    :meth:`_next_lane` at the end of its ``__init__``.

    Args:
        footprint: (m, 2) points of the gripper's planar footprint about its origin (W axes).
        max_step: per-axis clip of a step (m), the controller's.
        start_xy: where the gripper starts (the lanes start and end at its x).
        params: the settings.
        in_workspace: whether a planar point (W) is one the gripper may be sent to.
    """

    #: The action kind of a step towards a waypoint of each kind (others: "travel").
    STEP_KINDS: ClassVar[dict[str, str]] = {"push": "push"}

    def __init__(self, footprint, max_step: float, start_xy, params: RummageParams,
                 in_workspace: Callable[[np.ndarray], bool] | None = None):  # fmt: skip
        self.params = params
        self.footprint = np.asarray(footprint, dtype=np.float64).reshape(-1, 2)
        self.max_step = float(max_step)
        self.in_workspace = in_workspace or (lambda xy: True)
        width = float(np.ptp(self.footprint[:, 1]))
        self.lanes = coverage_waypoints(start_xy, params.coverage, width, self.in_workspace,
                                        params.transit_back).reshape(-1, 3, 2)  # fmt: skip
        self.actions = self.contacts = self.bumps = 0
        # Actions by what they were for (the subclass's kinds; see STEP_KINDS).
        self.action_kinds: dict[str, int] = {}
        self._kind = "travel"
        self._skipped: set[int] = set()
        self._lane, self._lane_bumps, self._retouches = -1, 0, 0
        self._touch_y, self._contact_xy = 0.0, None
        # The touch beside under way while it is reached by the near way (its y and push
        # end), to be reached by the lanes' x instead if that way bumps.
        self._near_retouch: tuple[float, float] | None = None
        self._queue: list[Waypoint] = []
        self._stopped = False
        self._last_step, self._moving, self._last_xy = np.zeros(2), False, None

    def copy(self):
        """A copy whose play does not change this one (settings, footprint and lanes shared,
        read only)."""
        other = copy.copy(self)
        other._queue = list(self._queue)
        other._skipped = set(self._skipped)
        other.action_kinds = dict(self.action_kinds)
        return other

    def next_step(self, gripper_xy, in_contact: bool, belief) -> np.ndarray | None:
        """The next action's step (m, W), or None once stopped."""
        if self._stopped or self._spent(belief):
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

    def _spent(self, belief) -> bool:
        """Whether the action budget is spent: ``max_actions``, or with ``extend_below``
        ``extended_max_actions``, or ``max_actions`` once the belief is that sure."""
        p = self.params
        if self.actions < p.max_actions:
            return False
        if p.extend_below is None or self.actions >= p.extended_max_actions:
            return True
        return belief_of(belief)[1] >= p.extend_below

    def sensed(self, points) -> None:
        """The contact points (m, W) of the latest action whose contacts are known (they come
        an action late: an action's contacts are formed after the next one is decided); an
        empty set keeps the last non-empty one's."""
        points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        if len(points):
            self._contact_xy = points[:, :2].mean(axis=0)

    def _decide(self, xy, in_contact: bool, belief) -> np.ndarray | None:
        raise NotImplementedError

    def _felt(self, xy, belief) -> np.ndarray | None:
        raise NotImplementedError

    def _marker(self, kind: str, point, xy, belief) -> tuple[bool, np.ndarray | None]:
        """(handled, step) for the queue entry ``kind`` at its head: not handled, it is a
        waypoint to move to."""
        return False, None

    def _bumped(self, xy) -> np.ndarray:
        """A travel sensed contact: back off (by the lanes' x where the near way to a touch
        beside bumped); a lane whose travel bumps more than ``lane_bumps`` times is left,
        with the lanes beyond it on that side."""
        self.bumps += 1
        if self._near_retouch is not None:  # round by the lanes' x instead
            (y, push_x), self._near_retouch = self._near_retouch, None
            self._queue = self._retouch_legs(xy, self.lanes[self._lane, 0, 0], y, push_x)
            return self._bounce()
        self._lane_bumps += 1
        if self._lane_bumps > self.params.lane_bumps:
            self._skip_beyond(xy)
            self._next_lane()
        return self._bounce()

    def _retouch(self, xy, far_touch) -> list[Waypoint]:
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

    def _retouch_legs(self, xy, side_x, y, push_x) -> list[Waypoint]:
        lane_x = self.lanes[self._lane, 0, 0]
        return [("move", np.array([side_x, xy[1]])), ("move", np.array([side_x, y])),
                ("push", np.array([push_x, y])), ("move", np.array([lane_x, y]))]

    def _bounce(self) -> np.ndarray:
        """The back-off from a travel's contact: back along the last step."""
        back = self._last_step / max(float(np.linalg.norm(self._last_step)), 1e-9)
        self._kind = "back_off"
        return -back * self.params.back_off

    def _withdraw(self, xy) -> None:
        """Back along -x to the lanes' x at ``xy``'s y; then the next lane."""
        self._queue = [("move", np.array([self.lanes[self._lane, 0, 0], xy[1]]))]

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
            handled, step = self._marker(kind, point, xy, belief)
            if handled:
                return step
            if kind == "retouch":
                self._queue[:1] = self._retouch(xy, point)
                continue
            if np.linalg.norm(point - xy) < self.params.arrive_tolerance:
                self._queue.pop(0)
                continue
            self._moving = True
            self._kind = self.STEP_KINDS.get(kind, "travel")
            if kind != "move":  # the way to a touch beside is behind
                self._near_retouch = None
            # The rest of the leg in equal steps, as few as the clip allows (the sweep's).
            leg = point - xy
            return leg / np.ceil(float(np.max(np.abs(leg))) / self.max_step - 1e-9)
        return None


__all__ = ["LaneWalk", "Waypoint"]
