"""A user's own pxpen: the tracker on a signed-distance function instead of a grid.

Truth: the cylinder's closed-form signed distance, and the synthetic world's own contact
objects and surfaces (the key case of the paper: a disc nudges two boxes apart).
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from stucco_drake.core import (
    CylinderSdf,
    FunctionPenetration,
    GridSdf,
    RobotPenetration,
    SoftTracker,
    SoftTrackingParams,
    contact_error,
    fowlkes_mallows,
)
from stucco_drake.core.synthetic import separation_scenario

DISC = CylinderSdf(0.02, 0.05)


def test_depths_and_excess_sums_match_the_closed_form_and_the_grid():
    rng = np.random.default_rng(0)
    pxpen = FunctionPenetration(DISC)
    points = rng.uniform(-0.04, 0.04, (500, 3))
    np.testing.assert_array_equal(pxpen(np.zeros(3), points), np.maximum(-DISC(points), 0.0))
    # Beyond any grid, exactly: 1 m away is outside, 1 cm from the axis is 1 cm deep.
    np.testing.assert_allclose(pxpen(np.zeros(3), [[1.0, 0, 0], [0.01, 0, 0]]), [0.0, 0.01])
    grid = RobotPenetration(GridSdf.build(DISC, [-0.03, -0.03, -0.06], [0.03, 0.03, 0.06], 0.001))
    points_e = rng.uniform(-0.05, 0.05, (3, 4, 30)).astype(np.float32)
    configs_e = rng.uniform(-0.02, 0.02, (3, 4, 6)).astype(np.float32)
    configs_e[:, 1, 2] = np.nan  # a config held in another orientation: skipped
    exact, exact_points = pxpen.excess_sums(points_e, configs_e, 0.002)
    _, gridded_points = grid.excess_sums(points_e, configs_e, 0.002)
    assert exact.max() > 0.01  # the pairs do penetrate
    # The 1 mm grid's interpolation error, summed over at most 6 configs per point.
    np.testing.assert_allclose(exact_points, gridded_points, atol=6 * 2e-4)


def test_soft_tracker_on_a_function_pxpen_solves_the_key_case():
    """The synthetic separation case with the disc's closed-form distance as pxpen: STUCCO
    revises the contacts as the boxes part (the grid's result: CE 0.00 cm, FMI 1.000)."""
    tracker = SoftTracker(FunctionPenetration(DISC), SoftTrackingParams.sim())
    world, actions = separation_scenario()
    rng, truth = np.random.default_rng(0), []
    for obs in actions:
        tracker.update(rng, obs.ee_position, obs.contact_points, obs.contact_dx)
        truth.extend(obs.contact_objects)
    assert len(truth) >= 10
    assert contact_error(tracker.map_points(), world.object_surfaces()) < 0.005
    assert fowlkes_mallows(truth, tracker.segment()) > 0.95


def test_function_pxpen_refusals():
    with pytest.raises(ValueError, match="callable"):
        FunctionPenetration(0.02)
    with pytest.raises(ValueError, match="finite values"):
        FunctionPenetration(lambda p: np.full(len(p), np.nan))(np.zeros(3), [[0.0, 0, 0]])
    with pytest.raises(ValueError, match="touched-side rule"):
        SoftTracker(FunctionPenetration(DISC),
                    dataclasses.replace(SoftTrackingParams.sim(), touched_side_margin=0.002))
