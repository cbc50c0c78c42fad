"""The contact-tracking chain for any robot's Diagram (``builder``): sensing to target pose.

Above ``systems/`` (it wires their LeafSystems together) and below the Diagrams that use it:
the BOR Diagram (``bor/``) and the second robot (``second_robot/``). It names no robot.
"""

from stucco_drake.tracking.builder import (
    OUTPUTS,
    ContactTracking,
    Tactile,
    add_contact_tracking,
    observed_joint_selectors,
)

__all__ = ["OUTPUTS", "ContactTracking", "Tactile", "add_contact_tracking",
           "observed_joint_selectors"]
