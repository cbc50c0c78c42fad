"""External joint torques and end-effector wrench from proprioception: a momentum observer.

The observer (De Luca & Mattone 2005; Haddadin, De Luca & Albu-Schäffer 2017) sees what a real
robot's controller sees, the arm's joint positions, velocities and applied joint torques, and a
model of the robot alone (arm + gripper, no objects). It never reads contact forces.
"""

from __future__ import annotations

import numpy as np
from pydrake.multibody.tree import JacobianWrtVariable
from pydrake.systems.framework import LeafSystem

from stucco_drake.core.detection import ResidualStatistics
from stucco_drake.core.momentum_observer import memory_size, observer_step, wrench_least_squares
from stucco_drake.systems.observed_robot import ObservedRobot
from stucco_drake.systems.ports import eval_finite

# Noise draws come in blocks of this many steps, one Generator per block (see _noise).
_NOISE_BLOCK = 4096
_ORIGIN = np.zeros(3)


class _StateLayout:
    """Slices of the estimator's state vector for n observed joints: the observer memory, then
    what the outputs show (r, wrench, chi-square, frame position)."""

    def __init__(self, n: int):
        m = memory_size(n)
        self.memory = slice(0, m)
        self.r = slice(m, m + n)
        self.wrench = slice(m + n, m + n + 6)
        self.chi2 = slice(m + n + 6, m + n + 7)
        self.position = slice(m + n + 7, m + n + 10)
        self.size = m + n + 10


class ExternalWrenchEstimator(LeafSystem):
    r"""Momentum observer for a robot arm's external joint torques and end-effector wrench.

    The robot is the caller's (an :class:`ObservedRobot`: a robot-only plant, the end-effector
    frame, the observed joints); below, n is the number of observed joints and E the frame.

    **Continuous form.** With p = M(q) v, M v̇ + C(q, v) v = τ + τ_g(q) + τ_ext and
    Ṁ = C + Cᵀ, the momentum obeys ṗ = τ + τ_g + Cᵀv + τ_ext, and the residual
    r = K_O (p - p(0) - ∫ (τ + τ_g + Cᵀv + r) dt) obeys ṙ = K_O (τ_ext - r): a first-order
    filter of τ_ext that needs no acceleration. Drake gives C(q, v) v (``CalcBiasTerm``) but not
    C, so Cᵀv is written Ṁv - Cv (``CalcGravityGeneralizedForces`` returns τ_g = -g(q), a force
    on the right-hand side).

    **Discrete form used here** (exact for Drake's discrete plant, time step h). The plant takes
    v_{n+1} from M_n (v_{n+1} - v_n) = h (τ_n + τ_g,n - C_n v_n + τ_ext,n), with M_n, C_n v_n and
    τ_g,n evaluated at step n (checked to round-off for the SAP solver). Hence, exactly,
    p_{n+1} - p_n = β_n + h τ_ext,n with the known momentum increment
    β_n = h (τ_n + τ_g,n - C_n v_n) + (M_{n+1} - M_n) v_{n+1}
    (the last term is the discrete Ṁv; together with -h C v it is the discrete h Cᵀv). The
    observer is then
    r_{n+1} = K_O (p_{n+1} - p_0 - Σ_{k=0..n} (β_k + h r_k)),
    so r_{n+1} = (1 - K_O h) r_n + K_O h τ_ext,n: unbiased, stable for 0 < K_O h <= 1 (K_O h = 1
    would be the one-step, unfiltered estimate). The output at time t estimates τ_ext over the
    last plant step this system has seen, filtered with time constant 1/K_O.

    **Timing (which torque goes with which state).** Wire ``state`` from the simulated plant's
    ``get_state_output_port(arm)`` and ``applied_torque`` from its
    ``get_net_actuation_output_port(arm)`` (the torque the plant actually applied, after any
    clamping or built-in PD). With ``MultibodyPlantConfig.use_sampled_output_ports`` true (Drake's
    default) the plant has already stepped when this update runs at the same tick: the state is
    x_{n+1} and the torque is τ_n, the one that produced it. With sampled ports off, the state is
    x_n and the torque τ_n is the one about to be applied. Set ``sampled_plant_outputs`` to match;
    a mismatch pairs each state with the torque of the neighbouring step and shows up as a
    residual proportional to the torque's rate of change.

    **Joints not observed** (e.g. a gripper's fingers) are treated as rigid parts of the robot,
    held at the robot's ``positions``. That is exact when they are held fixed: their joint
    forces act only in the fingers' rows of the equations, never in the arm's rows used here.
    (A finger that moves adds its reaction to the arm's residual: held only by a PD loop, a
    5-10 N push on the palm swung them by centimetres and gave force errors up to 18 %; lock
    them, e.g. with SAP's ``Joint.Lock``, or hold them stiffly.)

    **End-effector wrench.** τ_ext = Jᵀ F for a spatial force F = [τ; f] (Drake's SpatialForce
    order: torque (N·m) then force (N)) applied at the origin of E, expressed in the world frame,
    with J the 6 x n Jacobian of E's spatial velocity (in world) over the observed joints. F is
    the damped least-squares solution of Jᵀ F = r, i.e. (J Jᵀ + λ² I) F = J r: the least-squares
    fit (n equations, 6 unknowns) kept finite near singular arm configurations. The part of r
    that no wrench at E explains (contact on the arm's links, model error) is dropped.

    **Detection statistic.** ``residual_chi2`` = (F - μ)ᵀ Σ⁻¹ (F - μ) with μ, Σ the wrench's
    free-space mean and covariance (``residual_statistics``; see
    :func:`stucco_drake.systems.contact_detector.calibrate_residual_statistics`).

    **Noise (optional).** Zero-mean Gaussian noise of std ``torque_noise_std`` (N·m) on each
    measured torque and ``velocity_noise_std`` (rad/s) on each measured velocity, drawn inside
    the discrete update from numpy Generators seeded with ``noise_seed``. Draw n depends only on
    (seed, n), so the same seed gives bit-identical outputs however the simulation is restarted.

    Args:
        time_step: update period h (s); use the plant's time step.
        robot: the robot model (:class:`ObservedRobot`), e.g.
            ``ObservedRobot(robot_plant, robot_plant.GetFrameByName("gripper_frame"),
            joints=range(7), positions=q_held)``. The system keeps it (its scratch context
            holds only what the current update writes).
        gain: K_O (1/s), the observer's bandwidth; 0 < K_O h <= 1. Higher tracks faster and
            passes more velocity noise (which enters p = M v directly).
        residual_statistics: free-space wrench statistics for ``residual_chi2``; default
            :func:`default_wrench_statistics` (uncalibrated).
        damping: λ of the damped least squares (units of J, i.e. m or 1; 1e-3 is far below
            J's singular values away from singularities, so it biases nothing there).
        torque_noise_std, velocity_noise_std, noise_seed: see Noise.
        sampled_plant_outputs: see Timing.

    Input ports:
        state: (2 n,) the observed joints' [q (rad or m); v (rad/s or m/s)].
        applied_torque: (n,) joint torques (N·m or N) their actuators applied (see Timing).

    Output ports (from discrete state, updated every ``time_step`` s, no direct feedthrough;
    the residual, wrench and statistic are zero until the second update):
        external_joint_torques: (n,) r, the estimated external joint torques (N·m).
        ee_wrench: (6,) [τ (N·m); f (N)] on the robot at the origin of E, expressed in world.
        residual_chi2: (1,) the detection statistic above (dimensionless).
        ee_position: (3,) origin of E in world (m), from the measured q.
    """

    def __init__(
        self,
        time_step: float,
        robot: ObservedRobot,
        *,
        gain: float = 50.0,
        residual_statistics: ResidualStatistics | None = None,
        damping: float = 1e-3,
        torque_noise_std: float = 0.0,
        velocity_noise_std: float = 0.0,
        noise_seed: int | None = None,
        sampled_plant_outputs: bool = True,
    ):
        super().__init__()
        if not (np.isfinite(time_step) and time_step > 0):
            raise ValueError(f"ExternalWrenchEstimator: time_step must be > 0, got {time_step}")
        if not 0.0 < gain * time_step <= 1.0:
            raise ValueError(
                f"ExternalWrenchEstimator: gain * time_step must lie in (0, 1], "
                f"got {gain} * {time_step}"
            )
        if min(torque_noise_std, velocity_noise_std) < 0:
            raise ValueError("ExternalWrenchEstimator: noise standard deviations must be >= 0")
        self._noisy = torque_noise_std > 0 or velocity_noise_std > 0
        if self._noisy and noise_seed is None:
            raise ValueError("ExternalWrenchEstimator: noise is on, so noise_seed is required")
        self.time_step = float(time_step)
        self._torque_lags_state = bool(sampled_plant_outputs)
        self.gain = float(gain)
        n = robot.n
        self._noise_std = np.r_[np.full(n, torque_noise_std), np.full(n, velocity_noise_std)]
        self._noise_seed = noise_seed
        self._noise_cache: tuple[int, np.ndarray] | None = None
        stats = residual_statistics or default_wrench_statistics()
        if stats.dim != 6:
            raise ValueError(
                f"ExternalWrenchEstimator: residual statistics must be 6-D, got {stats.dim}"
            )
        self._stats_mean = stats.mean
        self._precision = stats.precision()

        # The robot model (its scratch context holds only what the current update writes).
        self.robot = robot
        self.robot_plant = robot.plant
        self._world = robot.plant.world_frame()
        self._damping = float(damping)

        self._state_port = self.DeclareVectorInputPort("state", 2 * n)
        self._torque_port = self.DeclareVectorInputPort("applied_torque", n)
        # One state vector (one write per update), laid out as in _StateLayout.
        self._layout = layout = _StateLayout(n)
        self._xd = self.DeclareDiscreteState(layout.size)
        # Outputs read state only: no direct feedthrough, so closing a loop through them
        # (e.g. into a controller) is fine.
        ticket = {self.xd_ticket()}
        for name, part, calc in (
            ("external_joint_torques", layout.r, self.calc_external_joint_torques),
            ("ee_wrench", layout.wrench, self.calc_ee_wrench),
            ("residual_chi2", layout.chi2, self.calc_residual_chi2),
            ("ee_position", layout.position, self.calc_ee_position),
        ):
            self.DeclareVectorOutputPort(name, part.stop - part.start, calc,
                                         prerequisites_of_calc=ticket)  # fmt: skip
        self.DeclarePeriodicDiscreteUpdateEvent(self.time_step, 0.0, self._update)

    # ---------------------------------------------------------------------------------- outputs
    def _state_part(self, context, part: slice) -> np.ndarray:
        return context.get_discrete_state(self._xd).get_value()[part]

    def calc_external_joint_torques(self, context, output):
        output.SetFromVector(self._state_part(context, self._layout.r))

    def calc_ee_wrench(self, context, output):
        output.SetFromVector(self._state_part(context, self._layout.wrench))

    def calc_residual_chi2(self, context, output):
        output.SetFromVector(self._state_part(context, self._layout.chi2))

    def calc_ee_position(self, context, output):
        output.SetFromVector(self._state_part(context, self._layout.position))

    # ----------------------------------------------------------------------------------- update
    def _noise(self, n: int) -> np.ndarray:
        """Noise for update n: (2 n_joints,) [torque; velocity], a function of (seed, n)."""
        block, row = divmod(n, _NOISE_BLOCK)
        if self._noise_cache is None or self._noise_cache[0] != block:
            # One Generator per block, keyed by (seed, block): draws never depend on how many
            # updates ran before in this process or context.
            rng = np.random.default_rng([self._noise_seed, block])
            shape = (_NOISE_BLOCK, 2 * self.robot.n)
            self._noise_cache = (block, rng.standard_normal(shape))
        return self._noise_cache[1][row] * self._noise_std

    def _update(self, context, discrete_state):
        x = eval_finite("ExternalWrenchEstimator", context, self._state_port)
        tau = eval_finite("ExternalWrenchEstimator", context, self._torque_port)
        old = context.get_discrete_state(self._xd).get_value()
        robot, S = self.robot, self._layout
        n = robot.n
        v = x[n:]
        if self._noisy:
            noise = self._noise(int(old[0]))
            tau = tau + noise[:n]
            v = v + noise[n:]

        robot.set_state(x[:n], v)
        plant, ctx = robot.plant, robot.context
        M = robot.block(plant.CalcMassMatrix(ctx))
        known = robot.rows(plant.CalcGravityGeneralizedForces(ctx)) - robot.rows(
            plant.CalcBiasTerm(ctx))  # fmt: skip
        new = old.copy()
        new[S.memory], r = observer_step(
            old[S.memory], old[S.r], M, known, tau, v,
            self.time_step, self.gain, self._torque_lags_state,
        )  # fmt: skip
        J = robot.columns(plant.CalcJacobianSpatialVelocity(
            ctx, JacobianWrtVariable.kV, robot.frame, _ORIGIN, self._world, self._world
        ))  # fmt: skip
        wrench = wrench_least_squares(J, r, self._damping)
        e = wrench - self._stats_mean
        new[S.r] = r
        new[S.wrench] = wrench
        new[S.chi2] = e @ self._precision @ e
        new[S.position] = robot.frame.CalcPoseInWorld(ctx).translation()
        discrete_state.set_value(self._xd, new)


def default_wrench_statistics() -> ResidualStatistics:
    """Uncalibrated fallback: zero mean, std 0.05 N·m on torques and 0.5 N on forces.

    Only for wiring and tests that do not detect contact; a detector should use the statistics
    measured by the calibration routine.
    """
    return ResidualStatistics.isotropic([0.05] * 3 + [0.5] * 3)


__all__ = ["ExternalWrenchEstimator", "default_wrench_statistics"]
