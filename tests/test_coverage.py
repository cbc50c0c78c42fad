"""The coverage sweep (core/coverage.py): its lanes tile the band by construction, reach as
far as the workspace allows, and its steps pass through every waypoint within the clip."""

import numpy as np
import pytest
from test_rummaging import BAND, BAND_NEAREST, MAX_STEP, START, WIDTH

from stucco_drake.core.coverage import (
    CoverageParams,
    coverage_waypoints,
    lane_centres,
    waypoint_steps,
)


def test_lanes_tile_the_band_one_footprint_apart():
    """The band -0.17..0.28 (0.45 m) in lanes at most 0.1 m apart: ceil(4.5) + 1 = 6 lanes,
    0.09 m apart, both ends included; lane after lane from the end nearer the start."""
    lanes = lane_centres(BAND, WIDTH)
    assert lanes == pytest.approx(np.linspace(-0.17, 0.28, 6), abs=1e-12)
    points = coverage_waypoints(START, BAND, WIDTH)
    assert points[:, 1].reshape(-1, 3)[:, 0] == pytest.approx(lanes[::-1])  # 0.1 nearer 0.28
    assert points[1::3, 0] == pytest.approx(np.full(6, 0.38))
    assert points[0::3, 0] == pytest.approx(np.zeros(6))


def test_nearest_first_sweeps_out_from_the_start():
    """From y 0.1: the lane at 0.10, out to the nearer end (0.19, 0.28), then from the start
    the other way (0.01, -0.08, -0.17)."""
    points = coverage_waypoints(START, BAND_NEAREST, WIDTH)
    assert points[0::3, 1] == pytest.approx([0.10, 0.19, 0.28, 0.01, -0.08, -0.17])


def test_lanes_from_the_start_reach_past_both_ends_of_the_band():
    """From y 0.1, lanes 0.1 apart: one straight ahead, the others out to the first at or
    beyond each end of the band -0.17..0.28: -0.2 .. 0.3, six lanes."""
    lanes = lane_centres(CoverageParams(), WIDTH, START[1])
    assert lanes == pytest.approx([-0.2, -0.1, 0.0, 0.1, 0.2, 0.3], abs=1e-12)
    points = coverage_waypoints(START, CoverageParams(nearest_first=True), WIDTH)
    assert points[0::3, 1] == pytest.approx([0.1, 0.2, 0.3, 0.0, -0.1, -0.2], abs=1e-12)


def test_lanes_stop_short_of_what_the_arm_cannot_reach():
    """A workspace x <= 0.3 where y > 0.2: the lane at y = 0.28 is pushed to 0.30 (5 mm steps
    back from 0.38), the others to 0.38."""
    def inside(xy):
        return xy[0] <= 0.3 + 1e-9 or xy[1] <= 0.2
    points = coverage_waypoints(START, BAND, WIDTH, inside)
    far = points[1::3]
    assert far[0] == pytest.approx([0.30, 0.28]) and far[1:, 0] == pytest.approx(0.38)


def test_lanes_moved_back_stop_at_the_workspace():
    """Lanes 4 cm behind the start (x 0) in a workspace that begins at x = -0.02: each lane
    begins and ends at -0.02 (5 mm steps forward from -0.04), its far end still at 0.38."""
    def inside(xy):
        return xy[0] >= -0.02 - 1e-9
    points = coverage_waypoints(START, BAND, WIDTH, inside, back=0.04)
    assert points[0::3, 0] == pytest.approx(np.full(6, -0.02))
    assert points[2::3, 0] == pytest.approx(np.full(6, -0.02))
    assert points[1::3, 0] == pytest.approx(np.full(6, 0.38))


def test_steps_pass_through_every_waypoint_within_the_clip():
    points = coverage_waypoints(START, BAND, WIDTH)
    steps = waypoint_steps(START, points, MAX_STEP)
    assert np.abs(steps).max() <= MAX_STEP + 1e-12
    ends = START + np.cumsum(steps, axis=0)
    for point in points:  # every waypoint is where some step ends (1e-12 m)
        assert np.min(np.linalg.norm(ends - point, axis=1)) < 1e-12
    # Per leg ceil(longest axis / 0.03) steps: to the first lane 0.18 m (6), each push and
    # withdrawal 0.38 m (13 each), each of 5 lane changes 0.09 m (3).
    assert len(steps) == 6 + 6 * 26 + 5 * 3
