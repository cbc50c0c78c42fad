"""One-off build time and memory of the gripper's signed-distance grid at 2 mm and 1 mm.

Builds into a fresh temporary cache (so nothing cached is reused), then loads each grid back.
Prints only. Run: python benchmarks/bench_gripper_sdf.py
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

import numpy as np

from stucco_drake.robot.gripper_sdf import GripperDistance, gripper_grid_sdf


def _drake_cost_per_point(distance: GripperDistance, n: int = 20_000) -> float:
    """Seconds per single-point Drake query, over random points of the gripper's box."""
    points = np.random.default_rng(0).uniform(distance.lower, distance.upper, size=(n, 3))
    start = time.perf_counter()
    distance.drake_distance(points)
    return (time.perf_counter() - start) / n


def main() -> None:
    distance = GripperDistance()
    print(f"Drake point query (boxes only): {1e6 * _drake_cost_per_point(distance):.1f} us/point")
    queried: list[int] = []
    original = GripperDistance.drake_distance

    def counting(self, points, threshold=np.inf):  # counts queried points, changes nothing
        queried.append(len(np.reshape(points, (-1, 3))))
        return original(self, points, threshold)

    GripperDistance.drake_distance = counting
    try:
        for resolution in (0.002, 0.001):
            with tempfile.TemporaryDirectory() as cache:
                queried.clear()
                start = time.perf_counter()
                grid = gripper_grid_sdf(resolution, cache_dir=cache)
                built = time.perf_counter() - start
                start = time.perf_counter()
                gripper_grid_sdf(resolution, cache_dir=cache)
                loaded = time.perf_counter() - start
                size = sum(f.stat().st_size for f in Path(cache).iterdir())
            nodes = grid.values.size
            print(
                f"{resolution * 1e3:.0f} mm: {grid.values.shape} = {nodes:,} nodes, "
                f"build {built:.2f} s ({sum(queried):,} Drake queries = "
                f"{sum(queried) / nodes:.0%} of nodes), cache load {loaded:.2f} s, "
                f"memory {grid.values.nbytes / 2**20:.1f} MiB, file {size / 2**20:.1f} MiB"
            )
    finally:
        GripperDistance.drake_distance = original


if __name__ == "__main__":
    main()
