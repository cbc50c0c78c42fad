"""The interface every contact tracker offers: STUCCO and the paper's baselines alike."""

from __future__ import annotations

from typing import Protocol, runtime_checkable

import numpy as np


@runtime_checkable
class Tracker(Protocol):
    """A contact tracker fed once per action; its estimate is read at any time.

    Points are in metres in the world frame. Implementations:
    :class:`~stucco_drake.core.soft_tracker.SoftTracker` and the trackers of
    :func:`~stucco_drake.core.baselines.make_tracker`.
    """

    @property
    def n_contacts(self) -> int:
        """Number of contact points tracked so far."""
        ...

    def update(
        self,
        rng: np.random.Generator,
        ee_position,
        contact_points=None,
        contact_dx=None,
        ee_rotation=None,
    ) -> None:
        """Take one action's result: the EE origin x_t (3,), new contact points (m, 3) and the
        EE displacement while in contact with each (m, 3), all m/world; ``rng`` is the caller's
        seeded generator for every random draw of the step."""
        ...

    def map_points(self) -> np.ndarray:
        """(n_contacts, 3) the best single estimate of every contact point (m, world)."""
        ...

    def segment(self) -> np.ndarray:
        """(n_contacts,) object labels of those points."""
        ...
