"""The robot model a proprioceptive system reads: the user's robot-only plant and its joints.

The sensing systems (:class:`~stucco_drake.systems.wrench_estimator.ExternalWrenchEstimator`,
:class:`~stucco_drake.systems.contact_isolator.GripperPoseFromState`) take an
:class:`ObservedRobot` by argument instead of building a robot: any fixed-base arm the user has
as a finalized ``MultibodyPlant`` (the robot alone, no objects, base welded where the real one
stands), the frame contacts are expressed at (the end effector's), which of the plant's joints
their ports carry, and where the other joints (e.g. a gripper's fingers) are held.
"""

from __future__ import annotations

import numpy as np
from pydrake.multibody.plant import MultibodyPlant


class ObservedRobot:
    """A robot-only plant, an end-effector frame and the joints a system observes.

    Args:
        plant: finalized ``MultibodyPlant`` of the robot alone (continuous or discrete: only
            its kinematics and dynamics are evaluated). Every joint must have as many position
            as velocity coordinates (revolute, prismatic, welded; no floating or ball joints).
        frame: a frame of ``plant``; outputs are about its origin (e.g. the gripper's).
        joints: the plant's generalized coordinate indices the systems' ports carry, in port
            order (default: all of them, 0 .. nv-1).
        positions: (nq,) the plant's positions (rad or m); the observed entries are replaced by
            the measured ones at every evaluation, the others (joints not observed, held
            rigidly) keep these values. Default: the plant's default positions.

    Attributes:
        n: number of observed joints (port sizes: state 2 n, torques n).
        plant, frame, joints, positions: the arguments (joints as an index array).
        context: the scratch context the systems evaluate the model in.
    """

    def __init__(self, plant: MultibodyPlant, frame, *, joints=None, positions=None):
        if not plant.is_finalized():
            raise ValueError("ObservedRobot: the plant must be finalized")
        nq, nv = plant.num_positions(), plant.num_velocities()
        if nq != nv:
            raise ValueError(f"ObservedRobot: need as many positions as velocities, got {nq} "
                             f"and {nv} (floating or ball joints are not supported)")  # fmt: skip
        if frame is not plant.get_frame(frame.index()):
            raise ValueError(f"ObservedRobot: frame '{frame.name()}' is not a frame of the plant")
        self.joints = np.arange(nv) if joints is None else np.asarray(joints, dtype=int)
        if (self.joints.ndim != 1 or len(self.joints) == 0 or len(set(self.joints.tolist()))
                != len(self.joints) or self.joints.min() < 0 or self.joints.max() >= nv):
            raise ValueError(f"ObservedRobot: joints must be distinct indices in [0, {nv}), "
                             f"got {joints}")  # fmt: skip
        self.plant, self.frame = plant, frame
        self.n = len(self.joints)
        self.context = plant.CreateDefaultContext()
        q = plant.GetPositions(self.context) if positions is None else positions
        q = np.asarray(q, dtype=float)
        if q.shape != (nq,) or not np.all(np.isfinite(q)):
            raise ValueError(f"ObservedRobot: positions must be {nq} finite values")
        self.positions = q.copy()
        # [q; v] of the whole plant: held joints at their positions and at rest.
        self._qv = np.concatenate([q, np.zeros(nv)])
        self._nq = nq
        # Observed joints first in the plant's order is the common case (an arm, then its
        # gripper): then slices, not index arrays, select them (same values, less work).
        n = self.n
        self.select = slice(0, n) if np.array_equal(self.joints, np.arange(n)) else self.joints

    def rows(self, vector: np.ndarray) -> np.ndarray:
        """The observed joints' entries of a plant-sized vector."""
        return vector[self.select]

    def block(self, matrix: np.ndarray) -> np.ndarray:
        """The observed joints' rows and columns of an (nv, nv) matrix."""
        s = self.select
        return matrix[s, s] if isinstance(s, slice) else matrix[np.ix_(s, s)]

    def columns(self, matrix: np.ndarray) -> np.ndarray:
        """The observed joints' columns of a (k, nv) matrix (e.g. a Jacobian)."""
        return matrix[:, self.select]

    def set_state(self, q, v=None) -> None:
        """Writes the observed joints' positions ``q`` (n,) and velocities ``v`` (n,; zero when
        omitted) into the scratch context; the other joints keep their held positions."""
        qv = self._qv
        qv[self.joints] = q
        qv[self._nq + self.joints] = 0.0 if v is None else v
        self.plant.SetPositionsAndVelocities(self.context, qv)


__all__ = ["ObservedRobot"]
