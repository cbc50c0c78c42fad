"""The method in pure numpy/scipy: soft tracking, segmentation, signed distances, metrics.

Nothing in this package imports Drake, so it is testable in milliseconds without a simulator.
The lowest layer but ``runtime``: it also holds the checks of command-line inputs (``inputs``)
that every layer's commands share.
"""

from stucco_drake.core.dynamics import TranslationDynamics
from stucco_drake.core.function_penetration import FunctionPenetration
from stucco_drake.core.metrics import (
    ambiguity,
    contact_error,
    fowlkes_mallows,
    paired_median_gap,
    target_pose_error,
)
from stucco_drake.core.observation import ActionContacts
from stucco_drake.core.params import SoftTrackingParams
from stucco_drake.core.penetration import RobotPenetration
from stucco_drake.core.sdf import GridSdf
from stucco_drake.core.segmentation import connected_components
from stucco_drake.core.shapes import BoxSdf, CylinderSdf, SphereSdf
from stucco_drake.core.soft_tracker import SoftTracker
from stucco_drake.core.target_pose import estimate_target_pose
from stucco_drake.core.tracker import Tracker

__all__ = [
    "ActionContacts",
    "BoxSdf",
    "CylinderSdf",
    "FunctionPenetration",
    "GridSdf",
    "RobotPenetration",
    "SoftTracker",
    "SoftTrackingParams",
    "SphereSdf",
    "Tracker",
    "TranslationDynamics",
    "ambiguity",
    "connected_components",
    "contact_error",
    "estimate_target_pose",
    "fowlkes_mallows",
    "paired_median_gap",
    "target_pose_error",
]
