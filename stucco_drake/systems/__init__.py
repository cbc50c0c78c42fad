"""Drake LeafSystems: thin wrappers that own ports and events and call into ``core``."""

from stucco_drake.systems.action_contacts_assembler import ActionContactsAssembler
from stucco_drake.systems.bubble_contact_sensor import BubbleContactSensor
from stucco_drake.systems.contact_detector import ContactDetector
from stucco_drake.systems.contact_isolator import ContactIsolator, GripperPoseFromState
from stucco_drake.systems.contact_tracking_visualizer import ContactTrackingVisualizer
from stucco_drake.systems.grasp_executor import GraspExecutor
from stucco_drake.systems.planar_controller import (
    PlanarActionSequence,
    PlanarEndEffectorController,
)
from stucco_drake.systems.soft_tracking_filter import SoftTrackingFilter
from stucco_drake.systems.target_pose_estimator import TargetPoseEstimator
from stucco_drake.systems.wrench_estimator import ExternalWrenchEstimator

__all__ = [
    "ActionContactsAssembler",
    "BubbleContactSensor",
    "ContactDetector",
    "ContactIsolator",
    "ContactTrackingVisualizer",
    "ExternalWrenchEstimator",
    "GraspExecutor",
    "GripperPoseFromState",
    "PlanarActionSequence",
    "PlanarEndEffectorController",
    "SoftTrackingFilter",
    "TargetPoseEstimator",
]
