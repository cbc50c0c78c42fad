"""Time and memory of one SoftTracker update as contacts accumulate (prints; asserts nothing).

Complexity of one update with N particles and n accumulated contacts:
  - in contact: connection sampling O(N n m) for m new contacts; the penetration check of every
    config against every point groups each contact's values across particles (O(N n log N)),
    boxes those groups (O(n^2) comparisons), finds the state pairs particles hold in the
    P column pairs whose boxes come near the robot (O(N P) integer work), and screens and
    interpolates each held state pair once rather than once per particle; ReplaceBad is
    O(B n) for B bad points. Particles that share few states (a diverse belief) take the
    per-particle pass instead: O(N n^2) cheap comparisons, lookups for pairs near the robot.
    Memory is bounded by the pair budget (2^20 pairs per block).
  - out of contact: O(N n) (the current config against every point).

The contacts come from the built-in planar world: a 10 cm disc EE rummaging through 8 boxes
scattered over 0.7 x 0.7 m, pushing them (exact contacts, so the belief stays consistent as in
real data); pxpen is a 1 mm grid SDF of that disc.

With ``--orientations`` every contact is sensed at an end-effector orientation of its own (a
yaw drawn within +-3 deg), as in a closed-loop run, where the check makes one pass per distinct
orientation. The disc is symmetric about z, so the contacts stay consistent.

Run: python benchmarks/bench_soft_tracker.py [--particles 100] [--contacts 25 50 100 200 400]
     [--orientations]
"""

from __future__ import annotations

import argparse
import copy
import platform
import time
import tracemalloc

import numpy as np

from stucco_drake.core import (
    CylinderSdf,
    GridSdf,
    RobotPenetration,
    SoftTracker,
    SoftTrackingParams,
)
from stucco_drake.core.synthetic import random_clutter, rummage


def robot_grid() -> GridSdf:
    """The rummaging EE: a 10 cm disc 10 cm tall, as a 1 mm grid."""
    return GridSdf.build(CylinderSdf(0.05, 0.05), [-0.06, -0.06, -0.06], [0.06, 0.06, 0.06], 0.001)


def contact_stream(rng, count):
    """Contacts of a disc EE rummaging through random box clutter, one list entry per contact."""
    world = random_clutter(rng, ee_radius=0.05)
    positions, points, dx = [], [], []
    for observation in rummage(world, rng):
        for p, d in zip(observation.contact_points, observation.contact_dx, strict=True):
            positions.append(observation.ee_position)
            points.append(p)
            dx.append(d)
        if len(points) >= count:
            return np.array(positions), np.array(points), np.array(dx)


def yaw_rotation(yaw: float) -> np.ndarray:
    c, s = np.cos(yaw), np.sin(yaw)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def measure(particles: int, contacts: int, repeats: int, grid: GridSdf, orientations: bool):
    rng = np.random.default_rng(0)
    params = SoftTrackingParams(n_particles=particles)
    tracker = SoftTracker(RobotPenetration(grid), params)
    positions, points, dx = contact_stream(rng, contacts + repeats)
    yaws = rng.uniform(-0.05, 0.05, len(points)) if orientations else np.zeros(len(points))
    rotations = [yaw_rotation(yaw) for yaw in yaws]
    for t in range(contacts):
        tracker.update(rng, positions[t], points[t : t + 1], dx[t : t + 1], rotations[t])
    timings = {"contact": [], "free": []}
    peak = 0
    for r in range(repeats):
        t = contacts + r
        for kind in ("contact", "free"):
            args = (points[t : t + 1], dx[t : t + 1]) if kind == "contact" else (None, None)
            trial = copy.deepcopy(tracker)
            start = time.perf_counter()
            trial.update(np.random.default_rng(r), positions[t], *args, rotations[t])
            timings[kind].append(time.perf_counter() - start)
            if r < 3:  # memory in a separate pass: tracing allocations slows numpy down
                trial = copy.deepcopy(tracker)
                tracemalloc.start()
                trial.update(np.random.default_rng(r), positions[t], *args, rotations[t])
                peak = max(peak, tracemalloc.get_traced_memory()[1])
                tracemalloc.stop()
    return timings, peak


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--particles", type=int, default=100)
    parser.add_argument("--contacts", type=int, nargs="+", default=[25, 50, 100, 200, 400])
    parser.add_argument("--repeats", type=int, default=30)
    parser.add_argument("--orientations", action="store_true",
                        help="sense each contact at an end-effector orientation of its own")
    args = parser.parse_args()
    grid = robot_grid()
    print(
        f"# SoftTracker.update, {args.particles} particles, 1 mm grid SDF "
        f"{tuple(grid.values.shape)}, "
        f"{'one orientation per contact' if args.orientations else 'one orientation'}; "
        f"numpy {np.__version__}, "
        f"{platform.processor() or platform.machine()}"
    )
    print(
        "| contacts | in contact median (ms) | p90 (ms) | out of contact median (ms) | p90 (ms) "
        "| peak memory (MB) |"
    )
    print("|---:|---:|---:|---:|---:|---:|")
    for contacts in args.contacts:
        timings, peak = measure(args.particles, contacts, args.repeats, grid, args.orientations)
        c, f = (np.array(timings[k]) * 1e3 for k in ("contact", "free"))
        print(
            f"| {contacts} | {np.median(c):.2f} | {np.percentile(c, 90):.2f} | "
            f"{np.median(f):.2f} | {np.percentile(f, 90):.2f} | {peak / 1e6:.1f} |"
        )


if __name__ == "__main__":
    main()
