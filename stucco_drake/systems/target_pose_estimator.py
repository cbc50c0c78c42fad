"""TargetPoseEstimator: segmentation + planar ICP of the tracked contacts (paper Sec. IV-C)."""

from __future__ import annotations

import copy
import dataclasses

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.math import RigidTransform, RotationMatrix
from pydrake.systems.framework import LeafSystem, ValueProducer

from stucco_drake.core.free_space import FreeSpace
from stucco_drake.core.motion_scale import MOTION_SCALES, motion_scaled_hypotheses
from stucco_drake.core.observation import ActionContacts
from stucco_drake.core.penetration import RobotPenetration
from stucco_drake.core.pose_hypotheses import HypothesisParams, pose_hypotheses
from stucco_drake.core.shapes import BoxSdf, CylinderSdf
from stucco_drake.core.target_pose import (
    TOUCH_TOLERANCE,
    NoSegmentToFit,
    TargetPoseEstimate,
    estimate_target_pose,
)


@dataclasses.dataclass
class EstimatorState:
    """Abstract state: the configs visited, the latest estimate and the random stream.

    Copy on write, as :class:`~stucco_drake.systems.soft_tracking_filter.TrackingState`:
    Drake's per-check clones share everything; :meth:`fork` copies before an update.
    """

    rng: np.random.Generator
    config_positions: np.ndarray  # (k, 3) EE origins at the end of each action (m, world)
    # (n,) index into config_positions of the action that sensed each tracked point, in the
    # trackers' contact order.
    point_steps: np.ndarray = dataclasses.field(
        default_factory=lambda: np.zeros(0, dtype=np.int64))
    # (n, 3) each tracked point where it was sensed (m, world), in the same order.
    sensed_points: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros((0, 3)))
    # (n,) the peak force (N; NaN: not measured) of the action that sensed each point.
    point_forces: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros(0))
    # (k,) whether each action of config_positions sensed no contact (its path is free space).
    free_actions: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros(0, dtype=bool))
    last_action_index: int = -1
    estimate: TargetPoseEstimate | None = None

    def __deepcopy__(self, memo):
        return copy.copy(self)

    def fork(self) -> EstimatorState:
        """A copy owning its own generator and arrays, safe to update."""
        return dataclasses.replace(
            self, rng=copy.deepcopy(self.rng), config_positions=self.config_positions.copy(),
            point_steps=self.point_steps.copy(), sensed_points=self.sensed_points.copy(),
            point_forces=self.point_forces.copy(), free_actions=self.free_actions.copy(),
            estimate=copy.deepcopy(self.estimate))


class TargetPoseEstimator(LeafSystem):
    """Estimates the target's planar pose (x, y, yaw) after every action that made contact.

    Each time a new action completes, the EE position is appended to the configs visited; if
    the action made contact and some segment has enough points, ICP re-runs on the tracker's
    MAP points (30 seeded restarts, warm-started from the previous estimate as the authors do)
    and the paper's selection rule picks the pose (see
    :func:`~stucco_drake.core.target_pose.estimate_target_pose`; by default segments the target's
    outline fits much worse than a circle or line are set aside first).

    Input ports:
        ee_pose: RigidTransform X_WE (m, world).
        tracked_action: :class:`ActionContacts` of the tracker's last update (connect the
            SoftTrackingFilter's ``tracked_action``, so the estimate sees the updated points).
        map_points: (n, 3) numpy array of tracked points (m, world).
        segment_labels: (n,) numpy int array.
        point_spread: (n,) numpy array, each point's spread over the tracker's particles (m;
            the SoftTrackingFilter's ``point_spread``); optional, none when unconnected; used
            only with ``motion_scales=None``.

    Output ports:
        target_pose: RigidTransform X_WO of the estimated target frame (yaw about world z, at
            the mean contact height); identity until a first estimate exists.
        estimate: the full :class:`TargetPoseEstimate` (None until a first estimate exists),
            with the per-segment report.
        pose_hypotheses: weighted hypotheses of the target's pose from the points (where sensed
            and where tracked, see ``motion_scales``), the free space of the configs visited
            and the target's outline (a generator seeded by ``[seed, action index]``), and
            with ``hypothesis_params.light_force`` the peak force of the action that sensed
            each point (``tracked_action``'s ``peak_force``); None while no segment has
            enough points. Computed only when evaluated.
        target_confidence: 1-vector, the hypotheses' confidence (0 to 1): the posterior
            probability that a grasp at their chosen pose closes on the target; 0 without
            hypotheses.

    Args:
        target_shape: the target's known geometry in its own frame (``BoxSdf``/``CylinderSdf``).
        penetration: the robot's pxpen for the selection rule.
        seed: seed of the generator for the ICP restarts.
        check_period: how often (s) to look for a newly completed action.
        n_restarts: ICP restarts per segment.
        penetration_configs: which visited configs a restart may not penetrate (see
            :func:`~stucco_drake.core.segment_selection.restart_scores`): ``"since_touch"``
            (default; those since the chosen segment was last touched, because the target
            may have been pushed since the older ones), ``"all"`` (the authors' code) or
            ``"latest"`` (the paper's text).
        touch_tolerance: per-pair penetration (m) forgiven at the configs before that window
            at which the chosen segment was touched (default 1 cm: how far the target may
            have moved since); None leaves them out.
        hypothesis_params: settings of the pose hypotheses (default: HypothesisParams()).
        motion_scales: the motion scales the hypotheses search over, each point between
            where it was sensed and where it is tracked
            (:func:`~stucco_drake.core.motion_scale.motion_scaled_hypotheses`); None: the
            tracked points alone, each weighed by its ``point_spread``.
    """

    def __init__(
        self,
        target_shape: BoxSdf | CylinderSdf,
        penetration: RobotPenetration,
        seed: int,
        check_period: float,
        n_restarts: int = 30,
        penetration_configs: str | int = "since_touch",
        touch_tolerance: float | None = TOUCH_TOLERANCE,
        hypothesis_params: HypothesisParams | None = None,
        motion_scales=MOTION_SCALES,
    ):
        super().__init__()
        if not check_period > 0:
            raise ValueError(f"check_period: must be > 0 s, got {check_period!r}")
        if touch_tolerance is not None and not touch_tolerance >= 0:
            raise ValueError(f"touch_tolerance: must be >= 0 m or None, got {touch_tolerance!r}")
        self.target_shape = target_shape
        self.penetration = penetration
        self.n_restarts = int(n_restarts)
        self.penetration_configs = penetration_configs
        self.touch_tolerance = touch_tolerance
        self.hypothesis_params = hypothesis_params or HypothesisParams()
        self.motion_scales = None if motion_scales is None else tuple(motion_scales)
        self._seed = int(seed)
        self._ee_pose = self.DeclareAbstractInputPort(
            "ee_pose", AbstractValue.Make(RigidTransform())
        )
        self._contacts = self.DeclareAbstractInputPort(
            "tracked_action", AbstractValue.Make(ActionContacts())
        )
        self._points = self.DeclareAbstractInputPort(
            "map_points", AbstractValue.Make(np.zeros((0, 3)))
        )
        self._labels = self.DeclareAbstractInputPort(
            "segment_labels", AbstractValue.Make(np.zeros(0, dtype=np.int64))
        )
        self._spread = self.DeclareAbstractInputPort(
            "point_spread", AbstractValue.Make(np.zeros(0))
        )
        initial = EstimatorState(np.random.default_rng(seed), np.zeros((0, 3)))
        self._state = self.DeclareAbstractState(AbstractValue.Make(initial))
        self.DeclareAbstractOutputPort(
            "target_pose", lambda: AbstractValue.Make(RigidTransform()), self.calc_target_pose
        )
        self.DeclareAbstractOutputPort(
            "estimate", lambda: AbstractValue.Make(None), self.calc_estimate
        )
        # Costly and needed only by who asks (a stopping rule, a viewer): computed once per
        # context, when first evaluated, and shared by both ports.
        self._hypotheses = self.DeclareCacheEntry(
            "pose hypotheses", ValueProducer(
                allocate=lambda: AbstractValue.Make(None), calc=self._compute_pose_hypotheses))
        self.DeclareAbstractOutputPort(
            "pose_hypotheses", lambda: AbstractValue.Make(None), self.calc_pose_hypotheses,
            prerequisites_of_calc={self._hypotheses.ticket()})  # fmt: skip
        self.DeclareVectorOutputPort(
            "target_confidence", 1, self.calc_target_confidence,
            prerequisites_of_calc={self._hypotheses.ticket()})  # fmt: skip
        self.DeclarePeriodicUnrestrictedUpdateEvent(check_period, 0.0, self._on_step)

    def estimator_state(self, context) -> EstimatorState:
        return context.get_abstract_state(int(self._state)).get_value()

    def _on_step(self, context, state):
        contacts = self._contacts.Eval(context)
        current = self.estimator_state(context)
        if contacts.action_index == current.last_action_index:
            return
        updated = current.fork()
        updated.last_action_index = contacts.action_index
        position = self._ee_pose.Eval(context).translation()
        updated.config_positions = np.vstack([current.config_positions, position])
        step = len(updated.config_positions) - 1
        updated.free_actions = np.append(current.free_actions, len(contacts.points) == 0)
        updated.sensed_points = np.vstack([current.sensed_points,
                                           np.asarray(contacts.points, float).reshape(-1, 3)])
        updated.point_steps = np.concatenate(
            [current.point_steps, np.full(len(contacts.points), step, dtype=np.int64)])
        updated.point_forces = np.concatenate(
            [current.point_forces, np.full(len(contacts.points), contacts.peak_force)])
        points = self._points.Eval(context)
        labels = np.asarray(self._labels.Eval(context))
        enough = len(labels) and np.bincount(labels[labels >= 0]).max(initial=0) >= 3
        if len(contacts.points) and enough:
            previous = current.estimate
            try:
                updated.estimate = estimate_target_pose(
                    updated.rng,
                    points,
                    labels,
                    self.target_shape,
                    self.penetration,
                    updated.config_positions,
                    self._ee_pose.Eval(context).rotation().matrix(),
                    n_restarts=self.n_restarts,
                    initial_pose=None if previous is None else previous.pose,
                    penetration_configs=self.penetration_configs,
                    point_steps=updated.point_steps,
                    touch_tolerance=self.touch_tolerance,
                )
            except NoSegmentToFit:
                pass  # every segment is wider than the target, in pieces too small: keep the last
        state.get_mutable_abstract_state(int(self._state)).set_value(updated)

    def calc_target_pose(self, context, output):
        estimate = self.estimator_state(context).estimate
        if estimate is None:
            output.set_value(RigidTransform())
            return
        points = self._points.Eval(context)
        height = float(np.mean(points[:, 2])) if len(points) else 0.0
        rotation = RotationMatrix.MakeZRotation(estimate.yaw)
        output.set_value(RigidTransform(rotation, [estimate.x, estimate.y, height]))

    def calc_estimate(self, context, output):
        output.set_value(self.estimator_state(context).estimate)

    def _compute_pose_hypotheses(self, context, output):
        state = self.estimator_state(context)
        points = self._points.Eval(context)
        labels = np.asarray(self._labels.Eval(context))
        # Points sensed after the last completed action's bookkeeping have no config yet.
        n = min(len(points), len(state.point_steps))
        counts = np.bincount(labels[:n][labels[:n] >= 0], minlength=1)
        if n == 0 or counts.max() < self.hypothesis_params.min_explained:
            output.set_value(None)
            return
        spread = self._spread.Eval(context) if self._spread.HasValue(context) else None
        free = FreeSpace(self.penetration, state.config_positions,
                         self._ee_pose.Eval(context).rotation().matrix(), state.point_steps[:n],
                         free_actions=state.free_actions)
        rng = np.random.default_rng([self._seed, max(state.last_action_index, 0)])
        if self.motion_scales is None:
            output.set_value(pose_hypotheses(
                rng, points[:n], labels[:n], self.target_shape,
                spread=None if spread is None else spread[:n], free_space=free,
                params=self.hypothesis_params, point_forces=state.point_forces[:n]))  # fmt: skip
            return
        output.set_value(motion_scaled_hypotheses(
            rng, state.sensed_points[:n], points[:n], labels[:n], self.target_shape,
            free_space=free, params=self.hypothesis_params,
            scales=self.motion_scales, point_forces=state.point_forces[:n]))  # fmt: skip

    def calc_pose_hypotheses(self, context, output):
        output.set_value(self._hypotheses.Eval(context))

    def calc_target_confidence(self, context, output):
        hypotheses = self._hypotheses.Eval(context)
        output.SetFromVector([0.0 if hypotheses is None else hypotheses.confidence])
