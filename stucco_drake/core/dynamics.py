"""pxdyn: how tracked contact points and their end-effector configs move when pushed."""

from __future__ import annotations

from typing import Protocol

import numpy as np


class ContactDynamics(Protocol):
    """Moves the connected (point, config) pairs of every particle, in place.

    Args of ``apply``:
        points: (3, n_particles, n) float32 world positions of contact points (m).
        configs: (3, n_particles, n) float32 world positions of the EE origin at each contact (m).
        connected: (n_particles, n) bool, which pairs move with the latest contact.
        displacement: (n_particles, n, 3) the EE displacement while in contact that each pair
            follows (m, world frame; the nearest new contact's dx).
    """

    def apply(self, points, configs, connected, displacement) -> None: ...


class TranslationDynamics:
    """The paper's pxdyn (Sec. V): connected objects translate with the end effector.

    pxdyn(P, dx) = {(p + F(dx), x + dx)}: each connected point and its config shift by the EE's
    translation while in contact; objects do not rotate. Unconnected pairs stay where they are.
    """

    def apply(self, points, configs, connected, displacement) -> None:
        for axis in range(3):
            shift = np.where(connected, displacement[..., axis], 0.0).astype(points.dtype)
            points[axis] += shift
            configs[axis] += shift
