"""One Blind Object Retrieval episode on one pinned core: real-time factor, where the time goes.

Every system of the BOR Diagram is on (momentum observer, chi-square detector, contact
isolator with the bubble sensor, action assembler with ground truth for scoring, STUCCO's
tracking filter, target-pose estimator); recording and the grasp are off. Printed:

- the episode's real-time factor (simulated time / wall time; 1.0 is real time) and wall time;
- each Python system's share of the wall time (exclusive: time spent in its own callbacks,
  not in the systems it evaluates), and the rest, which is the plant's step (contact geometry
  and the SAP solve), SceneGraph and Drake's framework;
- peak memory (resident set) of the process;
- as the reference in the same run, the scene alone (plant, joint and planar control, the same
  actions, the same fixed-step integrator) on the same core: the floor the physics sets.

The machine's load average is printed at the start and the end: a loaded machine slows both
runs alike, so read the ratio of the two more than either alone.

Run: python benchmarks/bench_bor.py [--scene FB] [--actions N] [--method stucco]
     [--dx-model cone] [--stucco-params results/table_ii/stucco.yaml] [--no-reference]
"""

from __future__ import annotations

import argparse
import functools
import inspect
import os
import platform
import resource
import time
from collections import defaultdict
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


class SystemTimer:
    """Exclusive wall time of each system class's Python callbacks.

    Wraps, before any Diagram is built, every private method and every output calc
    (``calc_<port>``) of the given classes; a call's time is charged
    to its class minus the time of wrapped calls nested inside it.
    """

    def __init__(self, classes):
        self.seconds = defaultdict(float)
        self._stack = []
        for cls in classes:
            for name, attr in list(vars(cls).items()):
                timed = name.startswith(("_", "calc_")) and not name.startswith("__")
                if timed and inspect.isfunction(attr):
                    setattr(cls, name, self._wrap(cls.__name__, attr))

    def _wrap(self, owner: str, fn):
        @functools.wraps(fn)
        def timed(*args, **kwargs):
            self._stack.append(0.0)
            start = time.perf_counter()
            try:
                result = fn(*args, **kwargs)
            finally:
                elapsed = time.perf_counter() - start
                nested = self._stack.pop()
                self.seconds[owner] += elapsed - nested
                if self._stack:
                    self._stack[-1] += elapsed
            return result

        return timed

    def reset(self):
        self.seconds.clear()


def _systems():
    from stucco_drake.systems.action_contacts_assembler import ActionContactsAssembler
    from stucco_drake.systems.bubble_contact_sensor import BubbleContactSensor
    from stucco_drake.systems.contact_detector import ContactDetector
    from stucco_drake.systems.contact_isolator import ContactIsolator, GripperPoseFromState
    from stucco_drake.systems.grasp_executor import GraspExecutor
    from stucco_drake.systems.planar_controller import (
        ActionClock,
        PlanarActionSequence,
        PlanarEndEffectorController,
    )
    from stucco_drake.systems.soft_tracking_filter import SoftTrackingFilter
    from stucco_drake.systems.target_pose_estimator import TargetPoseEstimator
    from stucco_drake.systems.wrench_estimator import ExternalWrenchEstimator

    return [ExternalWrenchEstimator, ContactDetector, ContactIsolator, GripperPoseFromState,
            BubbleContactSensor, ActionContactsAssembler, SoftTrackingFilter,
            TargetPoseEstimator, PlanarEndEffectorController, PlanarActionSequence,
            ActionClock, GraspExecutor]  # fmt: skip


def _print_shares(timer: SystemTimer, wall: float, rest: str) -> None:
    for name, seconds in sorted(timer.seconds.items(), key=lambda kv: -kv[1]):
        if seconds >= 0.0005 * wall:
            print(f"    {name:28s} {seconds:7.2f} s  {100 * seconds / wall:5.1f} %")
    python = sum(timer.seconds.values())
    print(f"    {rest:28s} {wall - python:7.2f} s  {100 * (wall - python) / wall:5.1f} %")


def run_reference(scene, n_actions: int, timer: SystemTimer) -> tuple[float, float]:
    """The scene alone for ``n_actions``: (simulated s, wall s)."""
    from pydrake.systems.analysis import Simulator

    from stucco_drake.bor.grasp import build_grasp_scene

    built = build_grasp_scene(scene, external_actions=False)
    simulator = Simulator(built.diagram)
    integrator = simulator.get_mutable_integrator()
    integrator.set_fixed_step_mode(True)
    integrator.set_maximum_step_size(float(scene.plant.time_step))
    simulator.Initialize()
    timer.reset()
    start = time.perf_counter()
    simulator.AdvanceTo(n_actions * scene.action_duration)
    return simulator.get_context().get_time(), time.perf_counter() - start


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scene", default="FB", help="scene name or file (default FB)")
    parser.add_argument("--actions", type=int, default=None, help="first N actions (all)")
    parser.add_argument("--method", default="stucco")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--dx-model", default="cone", choices=("ee", "normal", "cone"))
    parser.add_argument("--stucco-params", default=str(REPO / "results/table_ii/stucco.yaml"),
                        help="STUCCO's parameters (YAML; default Table II's); '' for the scene's")
    parser.add_argument("--no-reference", action="store_true",
                        help="skip the scene-alone reference run")
    args = parser.parse_args()
    if hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})
    print(f"python {platform.python_version()}, {platform.machine()}, pinned to one core; "
          f"load average {os.getloadavg()[0]:.2f}")

    timer = SystemTimer(_systems())  # before anything is built
    from stucco_drake.bor.diagram import build_bor_diagram
    from stucco_drake.bor.episode import run_episode
    from stucco_drake.core.params import SoftTrackingParams
    from stucco_drake.scenes import load_scene

    scene = load_scene(args.scene)
    n_actions = len(scene.actions) if args.actions is None else min(args.actions,
                                                                     len(scene.actions))
    params = None
    if args.method == "stucco" and args.stucco_params:
        import yaml

        with open(args.stucco_params) as f:
            params = SoftTrackingParams.from_mapping(yaml.safe_load(f))
    start = time.perf_counter()
    bor = build_bor_diagram(scene, args.method, args.seed, tracker_params=params,
                            dx_model=args.dx_model)  # fmt: skip
    print(f"scene {scene.name}, {args.method}, {args.dx_model}: "
          f"build {time.perf_counter() - start:.1f} s, "
          f"time step {scene.plant.time_step * 1e3:g} ms, {n_actions} actions")
    timer.reset()
    result = run_episode(scene, n_actions=n_actions, bor=bor)
    wall, simulated = result.wall_time_s, result.sim_time_s
    print(f"episode: {simulated:.1f} s simulated in {wall:.1f} s wall: "
          f"real-time factor {simulated / wall:.2f}")
    print(f"  {result.summary()}")
    print("  share of the wall time:")
    _print_shares(timer, wall, "plant step, SceneGraph, Drake framework")
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(f"  peak memory (resident) {peak:.0f} MiB")

    if not args.no_reference:
        ref_sim, ref_wall = run_reference(scene, n_actions, timer)
        print(f"reference, the scene alone: {ref_sim:.1f} s simulated in {ref_wall:.1f} s wall: "
              f"real-time factor {ref_sim / ref_wall:.2f}")
        _print_shares(timer, ref_wall, "plant step, SceneGraph, Drake framework")
        print(f"episode / scene alone wall time: {wall / ref_wall:.2f}")
    print(f"load average {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
