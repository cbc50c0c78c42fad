"""Real-time factor of a scene's full action sequence on one core (prints; asserts nothing).

The real-time factor is simulated time divided by wall time (higher is faster; 1.0 is real
time). The process pins itself to one CPU core first. Build time is reported separately.
It also prints how well the gripper tracked each action's planar goal, split into actions that
ended within 2 mm (free or lightly loaded) and the rest (blocked by an object).

Run: python benchmarks/bench_scene.py [--scene FB] [--actions N] [--time-step 0.002]
"""

from __future__ import annotations

import argparse
import os
import platform
import time

import numpy as np

from stucco_drake.scenes import build_scene, load_scene
from stucco_drake.scenes.playback import play


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scene", default="FB", help="scene name or path (default FB)")
    parser.add_argument("--actions", type=int, default=None, help="first N actions (default all)")
    parser.add_argument("--time-step", type=float, default=None,
                        help="override the scene's plant time step (s), to compare")
    args = parser.parse_args()
    if hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})
    print(f"python {platform.python_version()}, {platform.machine()}, pinned to one core")

    start = time.perf_counter()
    scene = load_scene(args.scene)
    if args.time_step:
        scene.plant.time_step = args.time_step
    built = build_scene(scene)
    print(f"scene {scene.name}: load + build {time.perf_counter() - start:.2f} s, "
          f"time step {scene.plant.time_step * 1000:g} ms, {scene.plant.contact_model}, "
          f"{scene.plant.discrete_contact_approximation}")

    records, wall = play(built, args.actions)
    simulated = records[-1].time
    print(f"{len(records) - 1} actions, {simulated:.1f} s simulated in {wall:.1f} s wall: "
          f"real-time factor {simulated / wall:.2f}")

    errors = np.array([np.linalg.norm(r.gripper_xyz[:2] - r.goal_xy) for r in records[1:]])
    heights = np.array([abs(r.gripper_xyz[2] - scene.gripper_start.height) for r in records])
    reached = errors < 0.002
    print(f"planar goal reached within 2 mm: {reached.sum()} of {len(errors)} actions "
          f"(median error of those {np.median(errors[reached]) * 1000 if reached.any() else 0:.2f}"
          f" mm); blocked actions' median shortfall "
          f"{np.median(errors[~reached]) * 1000 if (~reached).any() else 0:.1f} mm")
    print(f"height error at action ends: max {heights.max() * 1000:.2f} mm")
    for name, pose in records[0].objects.items():
        moved = np.linalg.norm(records[-1].objects[name][:2] - pose[:2])
        print(f"  {name}: moved {moved * 1000:.1f} mm")


if __name__ == "__main__":
    main()
