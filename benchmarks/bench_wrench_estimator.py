"""Cost per plant step of the ExternalWrenchEstimator's discrete update (prints; asserts nothing).

Three numbers:
  - the update itself on a context with fixed inputs, with and without sensor noise: the Python
    callback alone, and through Drake's event machinery (EvalUniquePeriodicDiscreteUpdate plus
    storing the result);
  - its parts: the robot-model calls it makes (mass matrix, bias, gravity, Jacobian, pose);
  - the free-space rig (SAP plant, inverse-dynamics control, estimator, contact detector) per
    simulated 1 ms step, to put the update's share in context.

Run: python benchmarks/bench_wrench_estimator.py [--steps 2000]
"""

from __future__ import annotations

import argparse
import platform
import time

import numpy as np
from pydrake.multibody.tree import JacobianWrtVariable
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import ConstantVectorSource

from stucco_drake.robot.models import iiwa_observed_robot_arguments
from stucco_drake.systems.contact_detector import (
    FINGERS_NOMINAL,
    Q_NOMINAL,
    ContactDetector,
    add_joint_controlled_robot,
    random_joint_trajectory,
)
from stucco_drake.systems.observed_robot import ObservedRobot
from stucco_drake.systems.wrench_estimator import ExternalWrenchEstimator

H = 1e-3


def iiwa(fingers=None, X_WB=None) -> ObservedRobot:
    """Our iiwa as the estimator's robot model: arm joints observed, fingers held."""
    return ObservedRobot(**iiwa_observed_robot_arguments(X_WB, fingers))


def per_call_us(fn, n: int, repeats: int = 5) -> float:
    """Best of ``repeats`` batches of n // repeats calls (the best batch is the one least
    disturbed by other processes on a shared machine)."""
    fn()  # warm caches and lazy allocations
    batch = max(1, n // repeats)
    best = np.inf
    for _ in range(repeats):
        t0 = time.perf_counter()
        for _ in range(batch):
            fn()
        best = min(best, (time.perf_counter() - t0) / batch)
    return best * 1e6


def bench_update(n: int, noisy: bool) -> tuple[float, float]:
    kwargs = dict(torque_noise_std=0.1, velocity_noise_std=1e-3, noise_seed=0) if noisy else {}
    est = ExternalWrenchEstimator(H, iiwa(FINGERS_NOMINAL), **kwargs)
    context = est.CreateDefaultContext()
    rng = np.random.default_rng(0)
    est.GetInputPort("state").FixValue(context, np.r_[Q_NOMINAL, 0.1 * rng.normal(size=7)])
    est.GetInputPort("applied_torque").FixValue(context, rng.normal(size=7))
    # Step the state so that every call takes the n > 0 branch with fresh values.
    context.SetDiscreteState(est.EvalUniquePeriodicDiscreteUpdate(context))

    def step():
        context.SetDiscreteState(est.EvalUniquePeriodicDiscreteUpdate(context))

    # The callback alone (what the simulator pays per step beyond its own event bookkeeping),
    # then through the framework: allocate, compute and store new discrete values.
    values = est.AllocateDiscreteVariables()
    return per_call_us(lambda: est._update(context, values), n), per_call_us(step, n)


def bench_parts(n: int) -> dict[str, float]:
    est = ExternalWrenchEstimator(H, iiwa())
    plant = est.robot_plant
    ctx = plant.CreateDefaultContext()
    x = np.r_[Q_NOMINAL, FINGERS_NOMINAL, 0.1 * np.ones(9)]
    frame = plant.GetFrameByName("gripper_frame")
    w = plant.world_frame()
    return {
        "SetPositionsAndVelocities": per_call_us(
            lambda: plant.SetPositionsAndVelocities(ctx, x), n
        ),
        "  + CalcMassMatrix": per_call_us(
            lambda: (plant.SetPositionsAndVelocities(ctx, x), plant.CalcMassMatrix(ctx)), n
        ),
        "  + CalcBiasTerm": per_call_us(
            lambda: (plant.SetPositionsAndVelocities(ctx, x), plant.CalcBiasTerm(ctx)), n
        ),
        "  + CalcGravityGeneralizedForces": per_call_us(
            lambda: (
                plant.SetPositionsAndVelocities(ctx, x),
                plant.CalcGravityGeneralizedForces(ctx),
            ),
            n,
        ),
        "  + CalcJacobianSpatialVelocity": per_call_us(
            lambda: (
                plant.SetPositionsAndVelocities(ctx, x),
                plant.CalcJacobianSpatialVelocity(
                    ctx, JacobianWrtVariable.kV, frame, np.zeros(3), w, w
                ),
            ),
            n,
        ),
    }


def bench_rig(duration: float) -> float:
    builder = DiagramBuilder()
    trajectory = random_joint_trajectory(np.random.default_rng(0), duration)
    robot = add_joint_controlled_robot(builder, trajectory)
    detector = builder.AddSystem(ContactDetector(H))
    action = builder.AddSystem(ConstantVectorSource([0.0]))
    est = robot.estimator
    builder.Connect(est.GetOutputPort("residual_chi2"), detector.GetInputPort("residual_chi2"))
    builder.Connect(est.GetOutputPort("ee_position"), detector.GetInputPort("ee_position"))
    builder.Connect(action.get_output_port(), detector.GetInputPort("action_index"))
    simulator = Simulator(builder.Build())
    robot.set_initial_configuration(simulator.get_mutable_context())
    simulator.AdvanceTo(0.05)
    t0 = time.perf_counter()
    simulator.AdvanceTo(0.05 + duration)
    return (time.perf_counter() - t0) / (duration / H) * 1e6


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=2000, help="calls per measurement")
    parser.add_argument("--rig-seconds", type=float, default=3.0, help="simulated time of the rig")
    args = parser.parse_args()
    print(f"python {platform.python_version()}, numpy {np.__version__}, {platform.machine()}")
    for noisy in (False, True):
        callback, framework = bench_update(args.steps, noisy)
        print(
            f"estimator update, noise {'on ' if noisy else 'off'}: callback {callback:6.1f} us, "
            f"through EvalUniquePeriodicDiscreteUpdate {framework:6.1f} us per step"
        )
    for name, us in bench_parts(args.steps).items():
        print(f"  {name:<36s} {us:7.1f} us")
    rig = bench_rig(args.rig_seconds)
    print(f"rig (plant + IDC + estimator + detector): {rig:7.1f} us per 1 ms step, "
          f"real-time factor {1e3 / rig:.2f}")  # fmt: skip


if __name__ == "__main__":
    main()
