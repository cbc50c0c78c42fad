"""Touching a heavy object's flank: a second face beside the one a push met.

A push that meets a heavy object (it resisted the press, or stopped a shove) touches one face,
and a box read from one face can be turned a quarter turn: its points fit the end face and the
long face alike. The flank touch backs off, moves sideways clear of the object, forward past
the touched face, and pushes sideways back towards the touch, guarded: what it meets is the
face beside the one touched (or the object's corner), at a right angle to it.

Which side: a contact sensed off the gripper's centre line means the object covers only that
side of the gripper's front, its edge about as far inside the front as the contact is from
the front's edge on that side (the contact is the middle of the overlap), so the flank is the
other side, just clear of that edge. A centred contact says nothing of the object's width;
the flank then clears the target's largest half extent on the first side the workspace allows.
The contact the tracker gives may lie well off the overlap's middle (3 cm towards the gripper's
edge on a box face of the development layouts), so the forward move may still meet the object;
the policy then goes further out and tries again.

Planar points (x, y) in the world frame W (m). The footprint is given as points in W axes
about the gripper's origin (its yaw is fixed).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable

import numpy as np


@dataclasses.dataclass(frozen=True)
class FlankTouch:
    """The flank touch's waypoints (W, m): ``side`` the sideways move at the backed-off
    distance, ``past`` the forward move beside the object, ``push_end`` where the sideways
    push towards the touch ends (the gripper's near edge ``depth`` past the contact);
    ``away`` the unit vector across the push pointing away from the object (the way to go
    further out when the forward move meets the object still), ``ahead`` the push's unit
    direction."""

    side: np.ndarray
    past: np.ndarray
    push_end: np.ndarray
    away: np.ndarray
    ahead: np.ndarray

    def further(self, distance: float, ahead: float = 0.0) -> FlankTouch:
        """The same touch with its sideways and forward moves ``distance`` further out, and
        its forward move and sideways push ``ahead`` further forward (m)."""
        out, forward = distance * self.away, ahead * self.ahead
        return FlankTouch(self.side + out, self.past + out + forward, self.push_end + forward,
                          self.away, self.ahead)  # fmt: skip

    def legs(self) -> list[tuple[str, np.ndarray]]:
        """The touch as a policy's queue of (kind, waypoint): the sideways move, the forward
        move (``"flank_ahead"``), the sideways push (``"flank"``), and ``"flanked"`` where it
        ends (the marker after which the policy assesses)."""
        return [("move", self.side), ("flank_ahead", self.past), ("flank", self.push_end),
                ("flanked", self.push_end)]  # fmt: skip


def plan_flank(gripper_xy, contact_xy, push, footprint, reach: float, *, depth: float,
               margin: float, back_off: float, centred: float = 0.01,
               in_workspace: Callable[[np.ndarray], bool] | None = None,
               ) -> FlankTouch | None:  # fmt: skip
    """The flank touch of the object a push met (see the module's docstring), or None when
    no side has its waypoints in the workspace.

    Args:
        gripper_xy: where the gripper's origin was at the touch.
        contact_xy: the touch's contact point (the mean of its points).
        push: the push's direction (any length).
        footprint: (m, 2) the gripper's planar footprint about its origin (W axes).
        reach: how far the object may reach sideways from a centred contact (the target's
            largest half extent).
        depth: how far past the touched face the gripper's front goes before pushing
            sideways.
        margin: how far clear of the object's estimated edge the gripper moves forward.
        back_off: how far the gripper backed off from the touch along -push.
        centred: how far off the gripper's centre line a contact is still centred.
        in_workspace: whether a waypoint is one the gripper may be sent to.
    """
    in_workspace = in_workspace or (lambda xy: True)
    u = np.asarray(push, dtype=np.float64)
    u = u / np.linalg.norm(u)
    n = np.array([-u[1], u[0]])  # across the push, to its left
    g, c = np.asarray(gripper_xy, dtype=np.float64), np.asarray(contact_xy, dtype=np.float64)
    fp = np.asarray(footprint, dtype=np.float64).reshape(-1, 2)
    along, across = fp @ u, fp @ n
    edges = {1.0: float(across.max()), -1.0: float(across.min())}  # the footprint's sides
    offset = float((c - g) @ n)
    contact_across = float(g @ n) + offset
    if abs(offset) > centred:  # off-centre: the object's edge inside the gripper's front
        side = -float(np.sign(offset))
        covered = float(g @ n) + edges[-side]  # the front's edge on the contact's side
        # Between the gripper's other edge and the contact (the middle of the overlap).
        low, high = sorted((float(g @ n) + edges[side], contact_across))
        candidates = [(side, float(np.clip(2.0 * contact_across - covered, low, high)))]
    else:
        candidates = [(side, contact_across + side * reach) for side in (1.0, -1.0)]
    back = float(g @ u) - back_off
    forward = float(c @ u) + depth - float(along.max())
    for side, edge in candidates:
        # The gripper's near side (facing the object) clear of the edge by the margin.
        across_side = edge + side * margin - edges[-side]
        push_end = contact_across - side * depth - edges[-side]
        points = FlankTouch(back * u + across_side * n, forward * u + across_side * n,
                            forward * u + push_end * n, side * n, u)  # fmt: skip
        if all(in_workspace(p) for p in (points.side, points.past)):
            return points
    return None


__all__ = ["FlankTouch", "plan_flank"]
