"""ExternalWrenchEstimator and ContactDetector on a simulated iiwa14 + bubble gripper.

The rig: the robot alone on a welded base, tracking random joint motion under an
InverseDynamicsController, pushed by known forces through the plant's applied_spatial_force input.
The estimator sees only joint state and applied torque. Shared simulations are module-scoped to
keep the file near 20 s on 2 cores.
"""

from __future__ import annotations

import numpy as np
import pytest
from pydrake.common.value import AbstractValue
from pydrake.multibody.math import SpatialForce
from pydrake.multibody.plant import ExternallyAppliedSpatialForce
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder, LeafSystem
from pydrake.systems.primitives import LogVectorOutput

from stucco_drake.core.detection import ResidualStatistics
from stucco_drake.robot.models import iiwa_observed_robot_arguments
from stucco_drake.systems.contact_detector import (
    FINGERS_NOMINAL,
    Q_NOMINAL,
    ContactDetector,
    add_joint_controlled_robot,
    calibrate_residual_statistics,
    default_threshold,
    random_joint_trajectory,
)
from stucco_drake.systems.observed_robot import ObservedRobot
from stucco_drake.systems.wrench_estimator import ExternalWrenchEstimator

H = 1e-3  # plant and estimator period (s)
ACTION = 0.6  # action duration (s)
N_ACTIONS = 16  # even actions move freely, odd ones are pushed
NOISE = dict(torque_noise_std=0.1, velocity_noise_std=1e-3)  # N·m, rad/s
P_GRIPPER = np.array([0.0, 0.0, 0.12])  # gripper_frame origin in the palm body frame (m)


class ForceSchedule(LeafSystem):
    """Pushes one body with force f (world, N) at point p_B during each [t0, t1) window."""

    def __init__(self, body_index, p_B, windows):
        super().__init__()
        self._body, self._p_B, self._windows = body_index, p_B, windows
        self.DeclareAbstractOutputPort(
            "forces", lambda: AbstractValue.Make([ExternallyAppliedSpatialForce()]), self._calc
        )

    def _calc(self, context, output):
        t, f = context.get_time(), np.zeros(3)
        for t0, t1, f_window in self._windows:
            if t0 <= t < t1:
                f = f_window
        applied = ExternallyAppliedSpatialForce()
        applied.body_index = self._body
        applied.p_BoBq_B = self._p_B
        applied.F_Bq_W = SpatialForce(np.zeros(3), f)
        output.set_value([applied])


class ActionClock(LeafSystem):
    """action_index = floor(t / period)."""

    def __init__(self, period: float):
        super().__init__()
        self.DeclareVectorOutputPort(
            "action_index", 1, lambda c, o: o.SetFromVector([np.floor(c.get_time() / period)])
        )


def iiwa(fingers=None, X_WB=None) -> ObservedRobot:
    """Our iiwa as the estimator's robot model: arm joints observed, fingers held."""
    return ObservedRobot(**iiwa_observed_robot_arguments(X_WB, fingers))


def push_windows(seed: int):
    """A 5-10 N push in a random, mostly horizontal direction over 20-80 % of each odd action."""
    rng = np.random.default_rng(seed)
    windows = []
    for a in range(1, N_ACTIONS, 2):
        d = rng.normal(size=3) * [1.0, 1.0, 0.3]
        f = d / np.linalg.norm(d) * rng.uniform(5.0, 10.0)
        windows.append(((a + 0.2) * ACTION, (a + 0.8) * ACTION, f))
    return windows


def run_pushes(estimator_kwargs, windows, p_B=P_GRIPPER, n_actions=N_ACTIONS, sampled=True):
    """Simulates the rig with pushes; returns logs and each action's completed summary."""
    builder = DiagramBuilder()
    trajectory = random_joint_trajectory(
        np.random.default_rng(5), n_actions * ACTION, segment_duration=ACTION, amplitude=0.15
    )
    robot = add_joint_controlled_robot(
        builder, trajectory, estimator_kwargs=estimator_kwargs, use_sampled_output_ports=sampled
    )
    est = robot.estimator
    forces = builder.AddSystem(
        ForceSchedule(robot.plant.GetBodyByName("body").index(), p_B, windows)
    )
    builder.Connect(forces.get_output_port(), robot.plant.get_applied_spatial_force_input_port())
    detector = builder.AddSystem(ContactDetector(H))
    clock = builder.AddSystem(ActionClock(ACTION))
    builder.Connect(est.GetOutputPort("residual_chi2"), detector.GetInputPort("residual_chi2"))
    builder.Connect(est.GetOutputPort("ee_position"), detector.GetInputPort("ee_position"))
    builder.Connect(est.GetOutputPort("ee_wrench"), detector.GetInputPort("ee_wrench"))
    builder.Connect(clock.get_output_port(), detector.GetInputPort("action_index"))
    logs = {
        name: LogVectorOutput(est.GetOutputPort(name), builder, H)
        for name in ("ee_wrench", "residual_chi2", "ee_position")
    }
    iiwa = robot.plant.GetModelInstanceByName("iiwa")
    logs["iiwa_state"] = LogVectorOutput(robot.plant.get_state_output_port(iiwa), builder, H)
    diagram = builder.Build()
    simulator = Simulator(diagram)
    robot.set_initial_configuration(simulator.get_mutable_context())
    completed_port = detector.GetOutputPort("completed_action")
    actions = []
    for a in range(n_actions):
        # Half a step past the boundary, the detector has closed action a.
        simulator.AdvanceTo((a + 1) * ACTION + 0.5 * H)
        actions.append(completed_port.Eval(detector.GetMyContextFromRoot(simulator.get_context())))
    out = {"actions": actions, "windows": windows, "p_B": np.asarray(p_B)}
    for name, logger in logs.items():
        log = logger.FindLog(simulator.get_context())
        out["t"], out[name] = log.sample_times(), log.data().T
    return out


@pytest.fixture(scope="module")
def calibration_dir(tmp_path_factory):
    return tmp_path_factory.mktemp("calibration")


@pytest.fixture(scope="module")
def statistics(calibration_dir):
    """Free-space wrench statistics with sensor noise on (6 s of random motion)."""
    kwargs = dict(NOISE, noise_seed=1)
    return calibrate_residual_statistics(
        duration=6.0, estimator_kwargs=kwargs, cache_dir=calibration_dir
    )


@pytest.fixture(scope="module")
def noisy_run(statistics):
    kwargs = dict(NOISE, noise_seed=7, residual_statistics=statistics)
    return run_pushes(kwargs, push_windows(3))


@pytest.fixture(scope="module")
def exact_run():
    """No sensor noise, pushed off-centre (2 cm beside and 3 cm below gripper_frame)."""
    return run_pushes({}, push_windows(11), p_B=P_GRIPPER + np.array([0.02, 0.0, 0.03]))


def steady_force_errors(run):
    """Relative error of the estimated force, and torque error (N·m), over each push's steady part
    (from 0.1 s after onset: five observer time constants)."""
    plant = ExternalWrenchEstimator(H, iiwa()).robot_plant  # only for the palm's orientation
    context = plant.CreateDefaultContext()
    palm = plant.GetBodyByName("body")
    t, wrench, x = run["t"], run["ee_wrench"], run["iiwa_state"]
    rel, torque_err = [], []
    for t0, t1, f in run["windows"]:
        m = (t >= t0 + 0.1) & (t < t1)
        rel.append(np.linalg.norm(wrench[m, 3:] - f, axis=1) / np.linalg.norm(f))
        for i in np.flatnonzero(m)[::20]:
            # A force f at a point offset from the gripper_frame origin is, at that origin, f plus
            # the torque (R_WB offset_B) x f.
            plant.SetPositions(context, np.r_[x[i, :7], FINGERS_NOMINAL])
            R_WB = plant.EvalBodyPoseInWorld(context, palm).rotation().matrix()
            expected = np.cross(R_WB @ (run["p_B"] - P_GRIPPER), f)
            torque_err.append(np.linalg.norm(wrench[i, :3] - expected))
    return np.concatenate(rel), np.array(torque_err)


def test_force_estimate_exact_model(exact_run):
    rel, torque_err = steady_force_errors(exact_run)
    print(f"noise-free: median force error {np.median(rel):.4f}, max {rel.max():.4f}")
    assert np.median(rel) < 0.02
    assert np.median(torque_err) < 0.02


def test_unsampled_plant_ports_are_paired_correctly():
    """With the plant's sampled output ports off, the torque read leads the state by a step; the
    estimator told so is exact again (free motion residual at round-off, push within 2 %)."""
    run = run_pushes({}, push_windows(11)[:1], n_actions=2, sampled=False)
    rel, _ = steady_force_errors(run)
    assert np.median(rel) < 0.02
    free = run["t"] < 0.6
    assert np.abs(run["ee_wrench"][free]).max() < 1e-9


def test_force_estimate_with_noise(noisy_run):
    rel, _ = steady_force_errors(noisy_run)
    print(f"noisy: median force error {np.median(rel):.4f}, 90th pct {np.quantile(rel, 0.9):.4f}")
    assert np.median(rel) < 0.10


def test_no_false_contact_in_free_motion(noisy_run):
    t, chi2 = noisy_run["t"], noisy_run["residual_chi2"][:, 0]
    free = np.zeros_like(t, dtype=bool)
    for a in range(0, N_ACTIONS, 2):
        free |= (t >= a * ACTION) & (t < (a + 1) * ACTION)
    print(f"free-motion chi2 max {chi2[free].max():.1f}, threshold {default_threshold():.1f}")
    assert chi2[free].max() < default_threshold()


def test_detection_precision_recall_per_action(noisy_run, exact_run):
    for run in (noisy_run, exact_run):
        truth = np.arange(N_ACTIONS) % 2 == 1
        predicted = np.array([a.in_contact for a in run["actions"]])
        assert [a.action_index for a in run["actions"]] == list(range(N_ACTIONS))
        tp = np.sum(truth & predicted)
        precision, recall = tp / max(predicted.sum(), 1), tp / truth.sum()
        print(f"precision {precision:.3f} recall {recall:.3f}")
        assert precision >= 0.95 and recall >= 0.95


def test_dx_is_the_motion_made_while_pushed(noisy_run):
    t, pos = noisy_run["t"], noisy_run["ee_position"]
    for a, action in enumerate(noisy_run["actions"]):
        if a % 2 == 0:
            assert np.array_equal(action.dx, np.zeros(3))
            continue
        t0, t1, _ = noisy_run["windows"][a // 2]
        # The residual rises and falls with ~20 ms lag: compare with the window shifted by it.
        i0, i1 = np.searchsorted(t, [t0 + 0.02, t1 + 0.02])
        expected = pos[i1] - pos[i0]
        assert np.linalg.norm(action.dx - expected) < 2e-3 + 0.05 * np.linalg.norm(expected)


def test_calibration_is_cached_and_keyed(statistics, calibration_dir):
    assert statistics.n_samples > 5000 and len(statistics.key) == 24
    assert (calibration_dir / f"residual_statistics_{statistics.key}.npz").is_file()
    again = calibrate_residual_statistics(
        duration=6.0, estimator_kwargs=dict(NOISE, noise_seed=1), cache_dir=calibration_dir
    )
    assert again.key == statistics.key
    np.testing.assert_array_equal(again.covariance, statistics.covariance)
    # Sensor noise makes the measured covariance exceed the floor.
    assert np.sqrt(statistics.covariance[3, 3]) > 0.3


# ---------------------------------------------------------------- standalone estimator checks
def standalone(estimator: ExternalWrenchEstimator, x, tau, steps: int = 300):
    """Runs the estimator alone with fixed inputs; returns its residual after each step."""
    builder = DiagramBuilder()
    builder.AddSystem(estimator)
    logger = LogVectorOutput(estimator.GetOutputPort("external_joint_torques"), builder, H)
    diagram = builder.Build()
    simulator = Simulator(diagram)
    context = estimator.GetMyMutableContextFromRoot(simulator.get_mutable_context())
    estimator.GetInputPort("state").FixValue(context, x)
    estimator.GetInputPort("applied_torque").FixValue(context, tau)
    simulator.AdvanceTo(steps * H)
    return logger.FindLog(simulator.get_context()).data().T


def holding_torque(estimator: ExternalWrenchEstimator) -> np.ndarray:
    """Gravity compensation at Q_NOMINAL: the torque that holds the arm at rest."""
    plant = estimator.robot_plant
    context = plant.CreateDefaultContext()
    plant.SetPositions(context, np.r_[Q_NOMINAL, FINGERS_NOMINAL])
    return -plant.CalcGravityGeneralizedForces(context)[:7]


def test_same_seed_same_output_with_noise():
    def run(seed):
        est = ExternalWrenchEstimator(H, iiwa(FINGERS_NOMINAL), noise_seed=seed, **NOISE)
        return standalone(est, np.r_[Q_NOMINAL, np.zeros(7)], holding_torque(est))

    a, b, c = run(3), run(3), run(4)
    assert np.array_equal(a, b)
    assert not np.allclose(a, c)
    assert np.abs(a).max() > 1e-3  # the noise does reach the residual


def test_at_rest_without_noise_residual_is_zero():
    est = ExternalWrenchEstimator(H, iiwa(FINGERS_NOMINAL))
    r = standalone(est, np.r_[Q_NOMINAL, np.zeros(7)], holding_torque(est), steps=50)
    assert np.abs(r).max() < 1e-9


@pytest.mark.parametrize("port", ["state", "applied_torque"])
def test_non_finite_input_raises_naming_the_port(port):
    est = ExternalWrenchEstimator(H, iiwa())
    x, tau = np.r_[Q_NOMINAL, np.zeros(7)], holding_torque(est)
    if port == "state":
        x[9] = np.nan
    else:
        tau[2] = np.inf
    with pytest.raises(ValueError, match=f"input port '{port}'") as info:
        standalone(est, x, tau, steps=3)
    assert "\n" not in str(info.value)


def test_constructor_rejects_bad_settings():
    with pytest.raises(ValueError, match="gain"):
        ExternalWrenchEstimator(H, iiwa(), gain=5000.0)
    with pytest.raises(ValueError, match="noise_seed"):
        ExternalWrenchEstimator(H, iiwa(), torque_noise_std=0.1)
    with pytest.raises(ValueError, match="6-D"):
        ExternalWrenchEstimator(H, iiwa(),
                                residual_statistics=ResidualStatistics.isotropic([1.0] * 7))


def test_peak_force_is_the_applied_push(exact_run):
    """Each pushed action's peak force is the applied force's magnitude: the noise-free
    estimate settles within 2 % of it (above) and a first-order observer does not overshoot,
    so within 5 %; a free action has no contact step, so 0."""
    for a, action in enumerate(exact_run["actions"]):
        if a % 2 == 0:
            assert action.peak_force == 0.0
            continue
        applied = np.linalg.norm(exact_run["windows"][a // 2][2])
        assert action.peak_force == pytest.approx(applied, rel=0.05)
