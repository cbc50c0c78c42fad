"""Shared fixtures: small robot geometries for the tracker tests."""

import os

import pytest

from stucco_drake.core import CylinderSdf, GridSdf, RobotPenetration


@pytest.fixture(scope="session")
def disc_penetration() -> RobotPenetration:
    """pxpen of a 2 cm-radius, 10 cm-tall disc end effector, as a 1 mm grid."""
    grid = GridSdf.build(CylinderSdf(0.02, 0.05), [-0.03, -0.03, -0.06], [0.03, 0.03, 0.06], 0.001)
    return RobotPenetration(grid)


@pytest.fixture
def meshcat(monkeypatch):
    """A Meshcat on an ephemeral port of this machine only (no browser connects to it).

    Drake refuses to start Meshcat when DRAKE_ALLOW_NETWORK is set without ``meshcat``; a
    localhost-only server is within the spirit of such a policy, so the test allows it.
    """
    allowed = os.environ.get("DRAKE_ALLOW_NETWORK")
    if allowed is not None and "meshcat" not in allowed.split(":"):
        monkeypatch.setenv("DRAKE_ALLOW_NETWORK", "meshcat")
    from pydrake.geometry import Meshcat, MeshcatParams

    return Meshcat(MeshcatParams(host="localhost", port=0))
