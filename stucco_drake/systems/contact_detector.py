"""Contact detection from the wrench residual, per action, and its free-space calibration.

- :class:`ContactDetector`: flags each step whose residual statistic exceeds a threshold (paper
  Eq. 1) and sums, per action, the end-effector displacement made while in contact (dx_t).
- :func:`calibrate_residual_statistics`: runs random free-space joint motions of the robot alone
  under joint-level control, records the :class:`ExternalWrenchEstimator`'s wrench and fits its
  mean and covariance (the paper's precision matrix is the inverse), cached per robot model.
- :func:`add_joint_controlled_robot`: that free-space rig (iiwa14 + gripper on a welded base,
  an InverseDynamicsController on a robot-only plant), also usable to push the robot with known
  forces through the plant's ``applied_spatial_force`` input.

Threshold choice: the estimator's ``residual_chi2`` is a true chi-square statistic (Σ is the
measured covariance), so its free-space mean is 6, and the paper's Table I value of 1 cannot be
reused with it (the paper's sim code pairs 1 with a hand-set precision diag(1,1,1,50,50,50) on
[f; τ], not with a measured one). The default threshold is the chi-square(6) level exceeded with
probability 1e-5 per step by a Gaussian free-space residual (33.1). ``paper_sim_statistics()``
with threshold 1 reproduces the paper's sim rule for comparison.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import os
from pathlib import Path

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.math import RigidTransform
from pydrake.multibody.parsing import Parser
from pydrake.multibody.plant import AddMultibodyPlant, MultibodyPlant, MultibodyPlantConfig
from pydrake.systems.analysis import Simulator
from pydrake.systems.controllers import InverseDynamicsController
from pydrake.systems.framework import DiagramBuilder, LeafSystem
from pydrake.systems.primitives import LogVectorOutput, TrajectorySource
from pydrake.trajectories import PiecewisePolynomial

from stucco_drake.core.detection import (
    ActionContact,
    ActionContactAccumulator,
    ResidualStatistics,
    chi2_threshold,
    fit_residual_statistics,
)
from stucco_drake.robot.models import (
    IIWA_ARM_JOINTS,
    MODELS_DIR,
    add_iiwa14_with_bubble_gripper,
    iiwa_observed_robot_arguments,
    iiwa_robot_plant,
)
from stucco_drake.systems.observed_robot import ObservedRobot
from stucco_drake.systems.ports import eval_finite
from stucco_drake.systems.wrench_estimator import ExternalWrenchEstimator

#: The calibration rig's arm joints (our iiwa's seven).
N_ARM = len(IIWA_ARM_JOINTS)

#: Arm configuration (rad) with the gripper pointing straight down, 0.6 m in front of the base.
Q_NOMINAL = np.array([0.0, 0.7, 0.0, -1.5, 0.0, 0.94, 0.0])
#: Finger half-gaps (m) the rig holds; the estimator must be told the same.
FINGERS_NOMINAL = np.array([0.03, 0.03])
#: Per-step false-alarm rate behind the default threshold (Gaussian free-space residual).
DEFAULT_FALSE_ALARM_RATE = 1e-5
#: Smallest std kept in the wrench covariance: 0.05 N·m on torques, 0.3 N on forces.
DEFAULT_FLOOR_STD = (0.05, 0.05, 0.05, 0.3, 0.3, 0.3)


def default_threshold() -> float:
    """chi-square(6) level for :data:`DEFAULT_FALSE_ALARM_RATE` (about 33.1)."""
    return chi2_threshold(6, DEFAULT_FALSE_ALARM_RATE)


def paper_sim_statistics() -> ResidualStatistics:
    """The paper's sim detector as statistics: precision diag(50,50,50,1,1,1) in our [τ; f] order
    (the authors' diag(1,1,1,50,50,50) on [f; τ]); use it with threshold 1."""
    return ResidualStatistics(np.zeros(6), np.diag([1 / 50] * 3 + [1.0] * 3))


class ContactDetector(LeafSystem):
    """Per-step contact flag (r^T Σ^-1 r > threshold) and per-action contact summary.

    Input ports:
        residual_chi2: (1,) the estimator's r^T Σ^-1 r.
        ee_position: (3,) end-effector position in world (m), e.g. the estimator's output.
        action_index: (1,) index of the action under way (an integer; a change starts a new
            action, so the tracker's update clock and this detector agree on action boundaries).
        ee_wrench: (6,) [τ (N·m); f (N)], the estimated external wrench on the end effector,
            e.g. the estimator's (optional: unconnected, the actions' ``peak_force`` is NaN).

    Output ports (updated every ``time_step`` s; each reads the inputs' values at the tick, so it
    trails the estimator by one step):
        in_contact: (1,) 1.0 when the last step's statistic exceeded ``threshold``, else 0.0.
        current_action: :class:`ActionContact` of the action under way, accumulated so far.
        completed_action: :class:`ActionContact` of the last action that has ended; its dx is
            the paper's dx_t (world frame, m), the end-effector motion made while in contact.

    An action counts as in contact when at least ``min_contact_steps`` of its steps were.
    """

    def __init__(
        self, time_step: float, threshold: float | None = None, min_contact_steps: int = 1
    ):
        super().__init__()
        self.threshold = default_threshold() if threshold is None else float(threshold)
        if not (np.isfinite(self.threshold) and self.threshold > 0):
            raise ValueError(f"ContactDetector: threshold must be > 0, got {threshold}")
        if min_contact_steps < 1:
            raise ValueError(
                f"ContactDetector: min_contact_steps must be >= 1, got {min_contact_steps}"
            )
        self.min_contact_steps = int(min_contact_steps)
        self._chi2 = self.DeclareVectorInputPort("residual_chi2", 1)
        self._position = self.DeclareVectorInputPort("ee_position", 3)
        self._action = self.DeclareVectorInputPort("action_index", 1)
        self._wrench = self.DeclareVectorInputPort("ee_wrench", 6)
        self._acc = self.DeclareDiscreteState(ActionContactAccumulator.initial_state())
        self._flag = self.DeclareDiscreteState(1)
        self.DeclareStateOutputPort("in_contact", self._flag)
        for name, calc in (("current_action", self.calc_current_action),
                           ("completed_action", self.calc_completed_action)):  # fmt: skip
            self.DeclareAbstractOutputPort(name, lambda: AbstractValue.Make(ActionContact()), calc)
        self.DeclarePeriodicDiscreteUpdateEvent(time_step, 0.0, self._update)

    def _read(self, context, port) -> np.ndarray:
        return eval_finite("ContactDetector", context, port)

    def _update(self, context, discrete_state):
        chi2 = self._read(context, self._chi2)[0]
        position = self._read(context, self._position)
        action = round(float(self._read(context, self._action)[0]))
        in_contact = bool(chi2 > self.threshold)
        force = (float(np.linalg.norm(self._read(context, self._wrench)[3:]))
                 if self._wrench.HasValue(context) else float("nan"))  # fmt: skip
        acc = context.get_discrete_state(self._acc).get_value()
        new = ActionContactAccumulator.step(acc, action, in_contact, position, force)
        discrete_state.get_mutable_vector(self._acc).SetFromVector(new)
        discrete_state.get_mutable_vector(self._flag).SetFromVector([float(in_contact)])

    def calc_current_action(self, context, output):
        acc = context.get_discrete_state(self._acc).get_value()
        output.set_value(ActionContactAccumulator.current(acc, self.min_contact_steps))

    def calc_completed_action(self, context, output):
        acc = context.get_discrete_state(self._acc).get_value()
        output.set_value(ActionContactAccumulator.completed(acc, self.min_contact_steps))


# ------------------------------------------------------------------------------ free-space rig
@dataclasses.dataclass
class JointControlledRobot:
    """Handles into a rig added by :func:`add_joint_controlled_robot`."""

    plant: MultibodyPlant
    estimator: ExternalWrenchEstimator
    controller: InverseDynamicsController
    trajectory: PiecewisePolynomial

    def set_initial_configuration(self, root_context) -> None:
        """Puts the plant at the trajectory's start configuration, at rest, fingers locked.

        Locking (a SAP constraint) holds the fingers rigidly, as the estimator assumes: held only
        by the controller's PD, a push on the palm swings them by centimetres, and their reaction
        would show up in the arm's residual.
        """
        plant_context = self.plant.GetMyMutableContextFromRoot(root_context)
        self.plant.SetPositions(plant_context, self.trajectory.value(0.0)[:, 0])
        for name in ("right_finger_joint", "left_finger_joint"):
            self.plant.GetJointByName(name).Lock(plant_context)


def random_joint_trajectory(
    rng: np.random.Generator,
    duration: float,
    *,
    segment_duration: float = 1.0,
    amplitude: float = 0.2,
    q_nominal=Q_NOMINAL,
    finger_positions=FINGERS_NOMINAL,
) -> PiecewisePolynomial:
    """Smooth random joint motion (9 rows: arm then fingers), starting at rest at ``q_nominal``.

    Waypoints every ``segment_duration`` s, each joint uniform in q_nominal ± ``amplitude`` rad,
    joined by a cubic spline with zero end velocities; the fingers stay at ``finger_positions``.
    """
    n = max(1, int(np.ceil(duration / segment_duration)))
    times = segment_duration * np.arange(n + 1)
    arm = np.asarray(q_nominal, float)[:, None] + rng.uniform(-amplitude, amplitude, (N_ARM, n + 1))
    arm[:, 0] = q_nominal
    fingers = np.repeat(np.asarray(finger_positions, float)[:, None], n + 1, axis=1)
    knots = np.vstack([arm, fingers])
    zero = np.zeros(knots.shape[0])
    return PiecewisePolynomial.CubicWithContinuousSecondDerivatives(times, knots, zero, zero)


def add_joint_controlled_robot(
    builder: DiagramBuilder,
    trajectory: PiecewisePolynomial,
    *,
    time_step: float = 1e-3,
    X_WB: RigidTransform | None = None,
    kp: float = 400.0,
    estimator_kwargs: dict | None = None,
    use_sampled_output_ports: bool = True,
) -> JointControlledRobot:
    """Adds a discrete (SAP) plant of the iiwa14 + gripper alone, base welded at X_WB, tracking
    ``trajectory`` (9 rows) with an InverseDynamicsController (gains kp, 2 sqrt(kp), ki = 1) on a
    robot-only plant, plus an :class:`ExternalWrenchEstimator` wired to the plant's iiwa state and
    net actuation. The plant's ``applied_spatial_force`` input is left for the caller.
    ``use_sampled_output_ports`` configures the plant and tells the estimator (see its Timing).
    """
    config = MultibodyPlantConfig(
        time_step=time_step,
        discrete_contact_approximation="sap",
        use_sampled_output_ports=use_sampled_output_ports,
    )
    plant, _ = AddMultibodyPlant(config, builder)
    iiwa, _ = add_iiwa14_with_bubble_gripper(Parser(plant))
    plant.WeldFrames(
        plant.world_frame(),
        plant.GetFrameByName("iiwa_link_0", iiwa),
        X_WB if X_WB is not None else RigidTransform(),
    )
    plant.Finalize()
    nv = plant.num_velocities()
    gains = np.full(nv, kp)
    controller = builder.AddSystem(
        InverseDynamicsController(
            iiwa_robot_plant(X_WB), gains, np.ones(nv), 2 * np.sqrt(gains), False
        )
    )
    source = builder.AddSystem(TrajectorySource(trajectory, output_derivative_order=1))
    builder.Connect(source.get_output_port(), controller.get_input_port_desired_state())
    builder.Connect(plant.get_state_output_port(), controller.get_input_port_estimated_state())
    builder.Connect(controller.get_output_port_control(), plant.get_actuation_input_port())
    robot = ObservedRobot(**iiwa_observed_robot_arguments(
        X_WB, finger_positions=trajectory.value(0.0)[N_ARM:, 0]))  # fmt: skip
    kwargs = {"sampled_plant_outputs": use_sampled_output_ports, **(estimator_kwargs or {})}
    estimator = builder.AddSystem(ExternalWrenchEstimator(time_step, robot, **kwargs))
    builder.Connect(plant.get_state_output_port(iiwa), estimator.GetInputPort("state"))
    builder.Connect(
        plant.get_net_actuation_output_port(iiwa), estimator.GetInputPort("applied_torque")
    )
    return JointControlledRobot(plant, estimator, controller, trajectory)


# ------------------------------------------------------------------------------- calibration
def robot_model_hash() -> str:
    """sha256 of the robot's model files (arm and gripper), the key of cached calibrations."""
    digest = hashlib.sha256()
    for rel in ("iiwa14/iiwa14.urdf", "bubble_gripper/bubble_gripper.sdf"):
        digest.update(rel.encode())
        digest.update((MODELS_DIR / rel).read_bytes())
    return digest.hexdigest()


def default_cache_dir() -> Path:
    """Per-user cache folder (XDG convention) for calibrations."""
    root = os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache"
    return Path(root) / "stucco_drake"


def calibrate_residual_statistics(
    *,
    time_step: float = 1e-3,
    duration: float = 10.0,
    seed: int = 0,
    amplitude: float = 0.2,
    segment_duration: float = 1.0,
    warmup: float = 0.2,
    floor_std=DEFAULT_FLOOR_STD,
    estimator_kwargs: dict | None = None,
    cache_dir: str | Path | None = None,
) -> ResidualStatistics:
    """Mean and covariance of the estimated end-effector wrench over random free-space motion.

    Runs :func:`random_joint_trajectory` (seeded with ``seed``) for ``duration`` s on the rig of
    :func:`add_joint_controlled_robot`, drops the first ``warmup`` s (the observer starts from
    rest), and fits :func:`~stucco_drake.core.detection.fit_residual_statistics` with the
    diagonal ``floor_std``. ``estimator_kwargs`` (gain, noise, ...) must match the estimator
    that will use the result, since they shape the residual.

    The result is saved as ``<cache_dir>/residual_statistics_<key>.npz`` (``cache_dir`` defaults
    to :func:`default_cache_dir`) and loaded from there when the key matches: the key hashes the
    robot model files together with every setting above.
    """
    estimator_kwargs = dict(estimator_kwargs or {})
    settings = dict(
        time_step=time_step,
        duration=duration,
        seed=seed,
        amplitude=amplitude,
        segment_duration=segment_duration,
        warmup=warmup,
        floor_std=[float(v) for v in np.broadcast_to(floor_std, (6,))],
        estimator={k: _jsonable(v) for k, v in sorted(estimator_kwargs.items())},
    )
    payload = json.dumps({"model": robot_model_hash(), "settings": settings}, sort_keys=True)
    key = hashlib.sha256(payload.encode()).hexdigest()[:24]
    path = Path(cache_dir or default_cache_dir()) / f"residual_statistics_{key}.npz"
    if path.is_file():
        try:
            cached = ResidualStatistics.load(path)
        except (ValueError, KeyError, OSError):
            cached = None  # a damaged or outdated file is recomputed, never trusted
        if cached is not None and cached.key == key:
            return cached

    builder = DiagramBuilder()
    trajectory = random_joint_trajectory(
        np.random.default_rng(seed),
        duration,
        segment_duration=segment_duration,
        amplitude=amplitude,
    )
    robot = add_joint_controlled_robot(
        builder, trajectory, time_step=time_step, estimator_kwargs=estimator_kwargs
    )
    logger = LogVectorOutput(robot.estimator.GetOutputPort("ee_wrench"), builder, time_step)
    diagram = builder.Build()
    simulator = Simulator(diagram)
    robot.set_initial_configuration(simulator.get_mutable_context())
    simulator.AdvanceTo(duration)
    log = logger.FindLog(simulator.get_context())
    samples = log.data().T[log.sample_times() >= warmup]
    stats = fit_residual_statistics(samples, floor_std, key=key)
    stats.save(path)
    return stats


def _jsonable(value):
    """Settings as JSON for the cache key (arrays as lists, transforms as 4x4 matrices)."""
    if isinstance(value, RigidTransform):
        return np.round(value.GetAsMatrix4(), 12).tolist()
    if isinstance(value, np.ndarray | list | tuple):
        return np.asarray(value, dtype=float).round(12).tolist()
    return value
