"""Shared fixtures: small robot geometries for the tracker tests."""

import pytest

from stucco_drake.core import CylinderSdf, GridSdf, RobotPenetration


@pytest.fixture(scope="session")
def disc_penetration() -> RobotPenetration:
    """pxpen of a 2 cm-radius, 10 cm-tall disc end effector, as a 1 mm grid."""
    grid = GridSdf.build(CylinderSdf(0.02, 0.05), [-0.03, -0.03, -0.06], [0.03, 0.03, 0.06], 0.001)
    return RobotPenetration(grid)
