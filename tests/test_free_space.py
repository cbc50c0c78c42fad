"""Free space swept by the robot, rasterised on a slice: against a disc gripper's closed-form
depth (radius 2 cm: a point at distance d from the disc's axis lies 0.02 - d inside it)."""

from __future__ import annotations

import numpy as np
import pytest

from stucco_drake.core.free_space import SweptSlice, swept_configs

RADIUS = 0.02
RESOLUTION = 0.0025


def test_a_free_push_is_swept_every_spacing_and_a_touching_one_counts_its_end_only():
    ends = np.array([[0.0, 0.0, 0.05], [0.1, 0.0, 0.05], [0.1, 0.1, 0.05]])
    configs, actions = swept_configs(ends, [True, True, False], spacing=0.005)
    # Action 0 has no logged start (its end only); action 1 is 10 cm free: 20 steps of 5 mm
    # ending at its end; action 2 sensed a contact: its end only.
    assert actions.tolist() == [0] + [1] * 20 + [2]
    np.testing.assert_allclose(configs[1:21, 0], np.linspace(0.005, 0.1, 20), atol=1e-15)
    np.testing.assert_array_equal(configs[[0, 20, 21]], ends)
    assert np.all(np.diff(configs[:21, 0]) <= 0.005 + 1e-15)


def test_bad_flags_or_spacing_are_one_line_errors():
    with pytest.raises(ValueError, match="free_actions: expected 2"):
        swept_configs(np.zeros((2, 3)), [True], 0.005)
    with pytest.raises(ValueError, match="spacing"):
        swept_configs(np.zeros((2, 3)), [True, True], 0.0)


def test_the_slice_holds_the_disc_depth_since_each_action(disc_penetration):
    """A disc swept 10 cm along x in action 1, then standing at (0.1, 0.1) at the end of
    action 2: depth along the swept line is the disc's radius minus the distance to the
    nearest config, and layer 2 keeps only what the robot covered from action 2 on."""
    ends = np.array([[0.0, 0.0, 0.05], [0.1, 0.0, 0.05], [0.1, 0.1, 0.05]])
    configs, actions = swept_configs(ends, [True, True, False], spacing=0.002)
    swept = SweptSlice.build(disc_penetration, configs, actions, 3, None, 0.05, RESOLUTION)
    assert swept.depth_since.shape[0] == 4
    probes = np.array([[0.05, 0.0], [0.05, 0.012], [0.05, -0.03], [0.1, 0.1], [0.1, 0.115]])
    truth = np.array([RADIUS, RADIUS - 0.012, 0.0, RADIUS, RADIUS - 0.015])
    # Nearest cell: up to half a cell's diagonal (1.8 mm) off; configs 2 mm apart: the depth
    # between two of them is up to 0.05 mm short; the 1 mm grid interpolates to 0.2 mm.
    tolerance = RESOLUTION / np.sqrt(2) + 3e-4
    np.testing.assert_allclose(swept.depth(probes, 0), truth, atol=tolerance)
    # Since action 2 only the disc at (0.1, 0.1) counts: the line swept in action 1 is free.
    np.testing.assert_allclose(swept.depth(probes, 2), [0, 0, 0, RADIUS, RADIUS - 0.015],
                               atol=tolerance)  # fmt: skip
    # Nothing after the last action; nothing beyond the raster; one layer per probe works.
    assert np.all(swept.depth(probes, 3) == 0.0)
    assert swept.depth(np.array([[5.0, 5.0]]), 0)[0] == 0.0
    per_probe = swept.depth(probes, np.array([0, 0, 0, 2, 3]))
    np.testing.assert_allclose(per_probe, [RADIUS, RADIUS - 0.012, 0, RADIUS, 0], atol=tolerance)


def test_a_slice_above_the_robot_is_empty(disc_penetration):
    configs, actions = swept_configs(np.array([[0.0, 0.0, 0.05]]), [True], 0.005)
    # The disc is 10 cm tall about its origin: 6 cm above it nothing is inside.
    swept = SweptSlice.build(disc_penetration, configs, actions, 1, None, 0.11, RESOLUTION)
    assert np.all(swept.depth_since == 0.0)
