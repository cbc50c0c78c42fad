"""ActionContactsAssembler: one :class:`ActionContacts` per completed action, for the tracker.

It joins what the detector and the isolator report step by step into what the tracker takes
once per action (paper Algorithm 1): the contact point(s) p_t, the end-effector displacement
while in contact dx_t and the end-effector pose x_t at the end of the action.

Ground truth for scoring (optional) is taken where scoring needs it: the assembler copies a
``truth_state`` vector (e.g. the plant's state) at each step whose points it latches, and asks a
:class:`TruthLabeller` for the true contacts once per completed action, never every step.
"""

from __future__ import annotations

import dataclasses
from typing import Protocol

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.math import RigidTransform
from pydrake.systems.framework import LeafSystem

from stucco_drake.core.detection import ActionContact
from stucco_drake.core.observation import ActionContacts
from stucco_drake.systems.contact_isolator import pose_from_vector


@dataclasses.dataclass(frozen=True)
class TruthContact:
    """A true contact between the robot and an object (ground truth, for evaluation only).

    Attributes:
        name: the touched object's name (its model instance; ``model::body`` for several bodies).
        point: (3,) the contact's location (m, world): a hydroelastic surface's centroid or a
            point contact's point.
    """

    name: str
    point: np.ndarray


class TruthLabeller(Protocol):
    """Names the true contact behind each sensed point, from a snapshot of the world's state.

    ``state_size`` is the length of the ``truth_state`` vector the assembler copies at the step
    a point is sensed; ``label(points, truth_state)`` returns one :class:`TruthContact` per row
    of ``points`` ((n, 3), m, world): the true contact nearest it in the world described by
    ``truth_state`` (name "" and a NaN point when the robot touched nothing there).
    """

    state_size: int

    def label(self, points: np.ndarray, truth_state: np.ndarray) -> tuple: ...


def nearest_truth(points: np.ndarray, truth: list) -> tuple:
    """For each of ``points`` (n, 3) the :class:`TruthContact` of ``truth`` nearest to it (by
    Euclidean distance, m), or ("" , NaN) for every point when ``truth`` is empty."""
    if not truth:
        return (TruthContact("", np.full(3, np.nan)),) * len(points)
    where = np.array([t.point for t in truth]).reshape(-1, 3)
    nearest = np.linalg.norm(points[:, None] - where[None], axis=2).argmin(axis=1)
    return tuple(truth[i] for i in nearest)


@dataclasses.dataclass(frozen=True)
class _AssemblerState:
    """What the assembler keeps (replaced, never mutated, by each update)."""

    action_index: int = -1  # the action under way, as the detector reports it
    latched: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros((0, 3)))
    latched_truth_state: np.ndarray | None = None  # truth_state when the points were latched
    completed: ActionContacts = dataclasses.field(default_factory=ActionContacts)
    completed_truth: tuple = ()
    ee_pose: RigidTransform = dataclasses.field(default_factory=RigidTransform)
    detected_without_point: int = 0  # actions in contact whose contact was never isolated

    def __deepcopy__(self, memo):
        # Immutable (each update builds a new one), so Drake's clone at every step may share it.
        return self


class ActionContactsAssembler(LeafSystem):
    """Latches the isolator's contact point(s) during each action; emits them when it ends.

    Every ``time_step`` s (use the plant's step): when the isolator reports contact, its
    point(s) replace those latched for the action under way, so an action's points are those of
    its last isolated contact step. When the detector's action changes, the completed action's
    :class:`ActionContacts` is formed: the latched points if the detector judged the action in
    contact (else none) and, for each point, the detector's dx. The gripper pose at that moment
    becomes x_t. All of this happens in an unrestricted-update event; outputs only read state.

    Input ports:
        current_action: the detector's :class:`ActionContact` of the action under way (its
            ``action_index`` is the action clock).
        completed_action: the detector's :class:`ActionContact` of the last completed action.
        has_contact: (1,) the isolator's flag (> 0.5: this step isolated a contact).
        contact_points: the isolator's list of (3,) world points (m) of this step.
        gripper_pose: (7,) [x, y, z, qw, qx, qy, qz] of ``gripper_frame`` (m, world; w-first).
        truth_state (only with ``truth``): (truth.state_size,) the vector the labeller reads,
            copied at each step whose points are latched.

    Output ports:
        action_contacts: :class:`ActionContacts` of the last completed action (action_index -1
            before the first); points (m, 3) and dx (m, 3) in m, world.
        ee_pose: RigidTransform X_WG of ``gripper_frame`` when that action completed.
        action_truth (only with ``truth``): tuple of :class:`TruthContact`, one per point
            of ``action_contacts``: the true contact nearest that point at the step it was
            latched (name "" and a NaN point when the robot touched nothing then), labelled
            by ``truth`` once, when the action completes.
    """

    def __init__(self, time_step: float, *, truth: TruthLabeller | None = None):
        super().__init__()
        if not (np.isfinite(time_step) and time_step > 0):
            raise ValueError(f"ActionContactsAssembler: time_step must be > 0, got {time_step}")
        self._truth_labeller = truth
        self._with_truth = truth is not None
        self._current = self.DeclareAbstractInputPort(
            "current_action", AbstractValue.Make(ActionContact())
        )
        self._completed = self.DeclareAbstractInputPort(
            "completed_action", AbstractValue.Make(ActionContact())
        )
        self._has_contact = self.DeclareVectorInputPort("has_contact", 1)
        self._points = self.DeclareAbstractInputPort(
            "contact_points", AbstractValue.Make([np.zeros(3)])
        )
        self._pose = self.DeclareVectorInputPort("gripper_pose", 7)
        if self._with_truth:
            self._truth = self.DeclareVectorInputPort("truth_state", int(truth.state_size))
        self._state = self.DeclareAbstractState(AbstractValue.Make(_AssemblerState()))
        ticket = {self.abstract_state_ticket(self._state)}
        self.DeclareAbstractOutputPort(
            "action_contacts", lambda: AbstractValue.Make(ActionContacts()),
            self.calc_action_contacts, prerequisites_of_calc=ticket)  # fmt: skip
        self.DeclareAbstractOutputPort(
            "ee_pose", lambda: AbstractValue.Make(RigidTransform()),
            self.calc_ee_pose, prerequisites_of_calc=ticket)  # fmt: skip
        if self._with_truth:
            self.DeclareAbstractOutputPort(
                "action_truth", lambda: AbstractValue.Make(()),
                self.calc_action_truth, prerequisites_of_calc=ticket)  # fmt: skip
        self.DeclarePeriodicUnrestrictedUpdateEvent(time_step, 0.0, self._update)

    def assembler_state(self, context) -> _AssemblerState:
        """The state held in ``context`` (read-only use); ``detected_without_point`` counts
        actions the detector flagged but the isolator never localised."""
        return context.get_abstract_state(self._state).get_value()

    def calc_action_contacts(self, context, output):
        output.set_value(self.assembler_state(context).completed)

    def calc_ee_pose(self, context, output):
        output.set_value(self.assembler_state(context).ee_pose)

    def calc_action_truth(self, context, output):
        output.set_value(self.assembler_state(context).completed_truth)
    def _update(self, context, state):
        old = self.assembler_state(context)
        new = old
        current = self._current.Eval(context)
        if current.action_index != old.action_index:
            if old.action_index >= 0:
                new = self._complete(context, old)
            new = dataclasses.replace(
                new, action_index=current.action_index, latched=np.zeros((0, 3)),
                latched_truth_state=None,
            )
        if self._has_contact.Eval(context)[0] > 0.5:
            points = np.array(self._points.Eval(context), dtype=float).reshape(-1, 3)
            if len(points):
                # A snapshot, not the labels: labelling waits for the action's end.
                truth = self._truth.Eval(context).copy() if self._with_truth else None
                new = dataclasses.replace(new, latched=points, latched_truth_state=truth)
        if new is not old:
            state.get_mutable_abstract_state(self._state).set_value(new)

    def _complete(self, context, old: _AssemblerState) -> _AssemblerState:
        done = self._completed.Eval(context)
        if done.action_index != old.action_index:
            # The detector closes an action in the same update that starts the next one, so
            # this cannot happen with its outputs wired; refuse rather than mislabel.
            raise RuntimeError(
                f"ActionContactsAssembler: completed action {done.action_index} does not match "
                f"the action under way {old.action_index}"
            )
        points, truth = np.zeros((0, 3)), ()
        missed = old.detected_without_point
        if done.in_contact:
            points = old.latched
            missed += not len(points)
            if len(points) and self._with_truth:
                truth = tuple(self._truth_labeller.label(points, old.latched_truth_state))
        dx = np.tile(np.asarray(done.dx, dtype=float).reshape(1, 3), (len(points), 1))
        return dataclasses.replace(
            old,
            completed=ActionContacts(done.action_index, points, dx, done.peak_force),
            completed_truth=truth,
            ee_pose=pose_from_vector(self._pose.Eval(context)),
            detected_without_point=missed,
        )


__all__ = ["ActionContactsAssembler", "TruthContact", "TruthLabeller", "nearest_truth"]
