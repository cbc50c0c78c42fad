"""What a tracker receives after each action: the contacts it made and how far they moved."""

from __future__ import annotations

import dataclasses

import numpy as np

from stucco_drake.core.validation import as_finite_array


@dataclasses.dataclass(frozen=True)
class ActionContacts:
    """The contact points of one completed action (paper Alg. 1 inputs p_t and dx_t).

    Attributes:
        action_index: index of the completed action on the action clock (-1: none yet).
        points: (m, 3) contact points detected during the action (m, world); m = 0 when the
            action made no contact.
        dx: (m, 3) end-effector displacement while in contact, one row per point (m, world).
        peak_force: the largest estimated external force on the end effector while in contact
            during the action (N; NaN: not measured; see
            :class:`~stucco_drake.core.detection.ActionContact`).
    """

    action_index: int = -1
    points: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros((0, 3)))
    dx: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros((0, 3)))
    peak_force: float = float("nan")

    def __post_init__(self):
        points = as_finite_array(self.points, "ActionContacts.points", (None, 3))
        dx = as_finite_array(self.dx, "ActionContacts.dx", (len(points), 3))
        object.__setattr__(self, "points", points)
        object.__setattr__(self, "dx", dx)
