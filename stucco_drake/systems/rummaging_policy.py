"""RummagingPolicy: the planar step of every action, chosen from what the robot has felt.

A thin wrapper around a policy of :mod:`stucco_drake.core`: it plays a list of prescribed
steps (possibly none), then the policy's, each decided at its action's start from the
detector's verdict on the action before, where the gripper is and the target-pose hypotheses:
:class:`~stucco_drake.core.probing.FaceProbePolicy` (guarded probes of the likeliest target
pose, after a prescribed script) or :class:`~stucco_drake.core.rummaging.BeliefRummagingPolicy`
(lanes explored until the target is felt, probed, and known).
"""

from __future__ import annotations

import dataclasses

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.math import RigidTransform
from pydrake.systems.framework import BasicVector, LeafSystem

from stucco_drake.core.detection import ActionContact
from stucco_drake.core.observation import ActionContacts
from stucco_drake.core.probing import FaceProbePolicy
from stucco_drake.core.rummaging import BeliefRummagingPolicy

PlanarPolicy = FaceProbePolicy | BeliefRummagingPolicy


@dataclasses.dataclass
class PolicyState:
    """Abstract state: the policy as of the last decided action, that action's index (-1:
    none yet) and its step (m, world), None once the policy has stopped."""

    policy: PlanarPolicy
    decided: int = -1
    step: np.ndarray | None = None

    def __deepcopy__(self, memo):
        # Drake copies abstract state on every update and clone: copy the policy's play, not
        # the scene its workspace test belongs to.
        return PolicyState(self.policy.copy(), self.decided,
                           None if self.step is None else self.step.copy())


class RummagingPolicy(LeafSystem):
    """Source of the planar step of every action (m, world frame): ``prescribed`` steps, then
    ``policy``'s (any object with ``next_step(gripper_xy, in_contact, hypotheses)``,
    ``copy()`` and ``params.action_budget``, as the policies of the module docstring).

    The step of action k is decided at t = k ``duration`` (its start), from the inputs then:
    the output computes it from the state of action k-1 without changing anything, and the
    update event due at that instant stores the same decision, so the controller, which reads
    the step at the same instant, and the state agree.

    Input ports:
        body_poses: the plant's body poses (list of RigidTransform by BodyIndex).
        current_action: the detector's :class:`ActionContact` of the action under way (at an
            action's start: of the action that just ended); its ``in_contact`` is given to the
            policy, and its ``peak_force`` too to a policy that has ``felt_force(newtons)``.
        pose_hypotheses: the target-pose estimator's hypotheses (None: none yet); evaluated
            only when the policy asks (they are costly).
        action_contacts: the latest formed :class:`ActionContacts` (the assembler's; an
            action's are formed after the next is decided), given to a policy that has
            ``sensed(points)`` before each decision; optional.

    Output ports:
        planar_step: (dx, dy) of the action under way (m, world); zeros once stopped.
        policy_done: 1-vector, 1.0 once the policy has stopped (no action is under way).

    Args:
        prescribed: (N, 2) the steps played first (m, world).
        duration: the actions' duration (s).
        gripper_frame: the plant's frame whose origin the steps move (its pose from
            ``body_poses`` and its fixed offset in its body).
        policy: the policy played after the prescribed steps (its state is copied).
    """

    def __init__(self, prescribed, duration: float, gripper_frame, policy: PlanarPolicy):
        super().__init__()
        self._prescribed = np.asarray(prescribed, dtype=np.float64).reshape(-1, 2)
        self._duration = float(duration)
        self._body = int(gripper_frame.body().index())
        self._X_BG = gripper_frame.GetFixedPoseInBodyFrame()
        self._max_actions = int(policy.params.action_budget)
        self._poses = self.DeclareAbstractInputPort(
            "body_poses", AbstractValue.Make([RigidTransform()]))
        self._verdict = self.DeclareAbstractInputPort(
            "current_action", AbstractValue.Make(ActionContact()))
        self._hypotheses = self.DeclareAbstractInputPort(
            "pose_hypotheses", AbstractValue.Make(None))
        self._contacts = self.DeclareAbstractInputPort(
            "action_contacts", AbstractValue.Make(ActionContacts()))
        self._state = self.DeclareAbstractState(
            AbstractValue.Make(PolicyState(policy.copy())))
        self.DeclareVectorOutputPort("planar_step", 2, self.calc_planar_step)
        self.DeclareVectorOutputPort("policy_done", 1, self.calc_policy_done)
        self.DeclarePeriodicUnrestrictedUpdateEvent(self._duration, 0.0, self._on_action_start)

    @property
    def max_actions(self) -> int:
        """The most actions played in all: the prescribed ones and the policy's budget."""
        return len(self._prescribed) + self._max_actions

    def _action(self, context) -> int:
        # The action sequence's tolerance: t = k * duration, in floating point, counts as k.
        return int(np.floor(context.get_time() / self._duration + 1e-6))

    def _decide(self, context) -> PolicyState:
        """The state once the action under way is decided (a copy when it is new)."""
        state = context.get_abstract_state(int(self._state)).get_value()
        k = self._action(context)
        if state.decided == k:
            return state
        if k < len(self._prescribed):
            return PolicyState(state.policy, k, self._prescribed[k].copy())
        if state.step is None and state.decided >= len(self._prescribed):
            return PolicyState(state.policy, k, None)
        # The output computes the step without changing the state: play on a copy.
        policy = state.policy.copy()
        X_WG = self._poses.Eval(context)[self._body] @ self._X_BG
        verdict = self._verdict.Eval(context)
        if hasattr(policy, "sensed") and self._contacts.HasValue(context):
            policy.sensed(self._contacts.Eval(context).points)
        if hasattr(policy, "felt_force"):
            policy.felt_force(verdict.peak_force)
        step = policy.next_step(X_WG.translation()[:2], bool(verdict.in_contact),
                                lambda: self._hypotheses.Eval(context))
        return PolicyState(policy, k, None if step is None else np.asarray(step, dtype=float))

    def _on_action_start(self, context, state):
        state.get_mutable_abstract_state(int(self._state)).set_value(self._decide(context))

    def calc_planar_step(self, context, output: BasicVector):
        step = self._decide(context).step
        output.SetFromVector(np.zeros(2) if step is None else step)

    def calc_policy_done(self, context, output: BasicVector):
        output.SetFromVector([1.0 if self._decide(context).step is None else 0.0])

    def policy_state(self, context) -> PolicyState:
        """The policy's state (its counters: ``policy.actions``, ``touches``, ...)."""
        return context.get_abstract_state(int(self._state)).get_value()
