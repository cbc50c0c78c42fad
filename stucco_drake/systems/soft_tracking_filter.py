"""SoftTrackingFilter: STUCCO (or any Tracker) as a Drake system, updated once per action."""

from __future__ import annotations

import copy
import dataclasses

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.math import RigidTransform
from pydrake.systems.framework import LeafSystem

from stucco_drake.core.contact_motion import DX_MODELS, contact_motion
from stucco_drake.core.observation import ActionContacts
from stucco_drake.core.pose_hypotheses import tracker_spread
from stucco_drake.core.tracker import Tracker


@dataclasses.dataclass
class TrackingState:
    """The filter's abstract state: the belief, its random stream and the action it last saw.

    Copy on write: Drake clones abstract state (``copy.deepcopy``) at every unrestricted
    update, i.e. at every check, although the belief changes once per action; the clone
    therefore shares the tracker and generator, and :meth:`fork` (real copies) is taken
    before anything is changed. A state in the context is never modified in place, so a
    cloned context still re-runs to identical results.
    """

    tracker: Tracker
    rng: np.random.Generator
    last_action: ActionContacts = dataclasses.field(default_factory=ActionContacts)
    n_updates: int = 0

    def __deepcopy__(self, memo):
        return copy.copy(self)

    def fork(self) -> TrackingState:
        """A copy owning its own tracker and generator, safe to update."""
        return TrackingState(
            copy.deepcopy(self.tracker),
            copy.deepcopy(self.rng),
            self.last_action,  # immutable
            self.n_updates,
        )


class SoftTrackingFilter(LeafSystem):
    """Feeds each completed action's contacts to a contact tracker (paper Algorithm 1).

    Input ports:
        ee_pose: RigidTransform X_WE of the end effector (m, world) — x_t of the paper, read when
            an action completes.
        action_contacts: :class:`~stucco_drake.core.observation.ActionContacts` of the last
            completed action. When its ``action_index`` differs from the last one seen, the
            tracker takes one update with its points and dx (none: an out-of-contact update).

    Output ports:
        map_points: (n, 3) numpy array, the tracker's MAP contact points (m, world).
        segment_labels: (n,) numpy int array, object labels of those points (Algorithm 3).
        tracked_action: the :class:`ActionContacts` of the last update taken; systems that
            read the outputs after each update (the target-pose estimator) key on it.
        point_spread: (n,) numpy array, each tracked point's weighted RMS distance (m) from
            its mean over the tracker's particles; zeros for a tracker without particles.

    The check is a periodic unrestricted-update event (every ``check_period`` s, typically the
    plant's time step), so the update happens on the action clock without any side effect in
    an output calculation.

    Args:
        tracker: a fresh tracker (``SoftTracker`` or a baseline); the filter's default state
            holds a deep copy of it, so one instance can build several diagrams.
        seed: seed of the numpy Generator every draw of the tracker comes from.
        check_period: how often (s) to look for a newly completed action.
        dx_model: how far each contact point moves (see
            :func:`~stucco_drake.core.contact_motion.contact_motion`): ``"ee"`` the end
            effector's displacement in contact (paper), ``"normal"`` its part along the robot's
            outward surface normal at the contact, ``"cone"`` it clipped to the friction cone
            about that normal; both need ``robot_sdf``.
        robot_sdf: the robot's signed distance in the end-effector frame (for ``"normal"``
            and ``"cone"``).
    """

    def __init__(self, tracker: Tracker, seed: int, check_period: float, *,
                 dx_model: str = "ee", robot_sdf=None):
        super().__init__()
        if not isinstance(tracker, Tracker):
            raise ValueError(f"tracker: {type(tracker).__name__} is not a contact Tracker")
        if not check_period > 0:
            raise ValueError(f"check_period: must be > 0 s, got {check_period!r}")
        if dx_model not in DX_MODELS:
            raise ValueError(f"dx_model: expected one of {DX_MODELS}, got {dx_model!r}")
        if dx_model != "ee" and robot_sdf is None:
            raise ValueError(f"dx_model {dx_model!r} needs robot_sdf")
        self.dx_model, self._robot_sdf = dx_model, robot_sdf
        self._ee_pose = self.DeclareAbstractInputPort(
            "ee_pose", AbstractValue.Make(RigidTransform())
        )
        self._contacts = self.DeclareAbstractInputPort(
            "action_contacts", AbstractValue.Make(ActionContacts())
        )
        initial = TrackingState(copy.deepcopy(tracker), np.random.default_rng(seed))
        self._state = self.DeclareAbstractState(AbstractValue.Make(initial))
        self.DeclareAbstractOutputPort(
            "map_points", lambda: AbstractValue.Make(np.zeros((0, 3))), self.calc_map_points
        )
        self.DeclareAbstractOutputPort(
            "segment_labels",
            lambda: AbstractValue.Make(np.zeros(0, dtype=np.int64)),
            self.calc_segment_labels,
        )
        self.DeclareAbstractOutputPort(
            "tracked_action", lambda: AbstractValue.Make(ActionContacts()), self.calc_tracked_action
        )
        self.DeclareAbstractOutputPort(
            "point_spread", lambda: AbstractValue.Make(np.zeros(0)), self.calc_point_spread
        )
        self.DeclarePeriodicUnrestrictedUpdateEvent(check_period, 0.0, self._on_step)

    def tracking_state(self, context) -> TrackingState:
        """The belief held in ``context`` (read-only use)."""
        return context.get_abstract_state(int(self._state)).get_value()

    def _on_step(self, context, state):
        contacts = self._contacts.Eval(context)
        current = self.tracking_state(context)
        if contacts.action_index == current.last_action.action_index:
            return
        updated = current.fork()
        pose = self._ee_pose.Eval(context)
        dx = contacts.dx
        if len(contacts.points):
            dx = contact_motion(self.dx_model, contacts.dx, contacts.points, self._robot_sdf,
                                pose.translation(), pose.rotation().matrix())
        updated.tracker.update(
            updated.rng,
            pose.translation(),
            contacts.points,
            dx,
            pose.rotation().matrix(),
        )
        updated.last_action = contacts
        updated.n_updates += 1
        state.get_mutable_abstract_state(int(self._state)).set_value(updated)

    def calc_map_points(self, context, output):
        output.set_value(self.tracking_state(context).tracker.map_points())

    def calc_segment_labels(self, context, output):
        output.set_value(np.asarray(self.tracking_state(context).tracker.segment()))

    def calc_tracked_action(self, context, output):
        output.set_value(self.tracking_state(context).last_action)

    def calc_point_spread(self, context, output):
        tracker = self.tracking_state(context).tracker
        spread = tracker_spread(tracker)
        output.set_value(np.zeros(tracker.n_contacts) if spread is None else spread)
