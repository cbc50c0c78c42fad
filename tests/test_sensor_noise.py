"""Noisy sensing as a scene option: it reaches the wrench estimator and the bubbles.

The independent truth is the detector's calibration: a separate simulation (random joint
motion on a robot-only rig, seed 0) with the same torque noise gives the free-space wrench
statistics. The BOR Diagram's estimator, at rest before the first contact of TC, must show
noise of that size (within a factor of two: other motion, other draws, 0.4 s of samples),
and far above the noise-free estimator's.
"""

import numpy as np
import pytest

import stucco_drake  # noqa: F401  (pins the numeric kernels before numpy loads)
from stucco_drake.bor.diagram import build_bor_diagram
from stucco_drake.bor.episode import make_bor_simulator
from stucco_drake.scenes import load_scene
from stucco_drake.scenes.sensor_noise import REAL_IIWA, with_sensor_noise
from stucco_drake.systems.contact_detector import calibrate_residual_statistics

STEPS = 200  # 0.4 s at 2 ms: TC's gripper meets nothing before 0.5 s


def _free_space_wrenches(scene) -> np.ndarray:
    """(STEPS, 6) the estimator's ee_wrench [tau; f] over the first steps of ``scene``."""
    bor = build_bor_diagram(scene, "stucco", seed=0)
    simulator = make_bor_simulator(bor)
    context = simulator.get_context()
    estimator = bor.estimator.GetMyContextFromRoot(context)
    port = bor.estimator.GetOutputPort("ee_wrench")
    h = float(scene.plant.time_step)
    samples = []
    for k in range(1, STEPS + 1):
        simulator.AdvanceTo(k * h)
        samples.append(port.Eval(estimator).copy())
    return np.array(samples), bor


@pytest.fixture(scope="module")
def scenes():
    clean = load_scene("TC")
    return clean, with_sensor_noise(clean)


def test_noisy_scene_is_a_renamed_copy(scenes):
    clean, noisy = scenes
    assert noisy.name == "TC-noise" and noisy.actions == clean.actions
    assert noisy.sensor_noise == REAL_IIWA and clean.sensor_noise.torque_std == 0.0


def test_torque_noise_reaches_the_estimator_at_the_calibrated_size(scenes):
    clean, noisy = scenes
    quiet, _ = _free_space_wrenches(clean)
    loud, bor = _free_space_wrenches(noisy)
    # Skip the observer's start-up (it starts from rest at 0 momentum).
    quiet, loud = quiet[50:], loud[50:]
    calibrated = calibrate_residual_statistics(
        time_step=float(noisy.plant.time_step),
        estimator_kwargs={"gain": bor.estimator.gain, "torque_noise_std": REAL_IIWA.torque_std,
                          "velocity_noise_std": 0.0, "noise_seed": 0})
    expected = np.sqrt(np.diag(calibrated.covariance))[3:]  # force components, N
    measured = loud[:, 3:].std(axis=0)
    print("force std N: noisy", measured.round(3), "calibrated", expected.round(3),
          "noise-free", quiet[:, 3:].std(axis=0).round(4))
    assert np.all(measured > 0.5 * expected) and np.all(measured < 2.0 * expected)
    assert np.all(quiet[:, 3:].std(axis=0) < 0.1 * measured)
    # The bubbles get their noise too (their sensor's own test checks the draws).
    assert bor.bubble_sensor._noise_std == REAL_IIWA.bubble_point_std
