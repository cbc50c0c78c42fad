"""Planar end-effector control: prescribed planar steps turned into joint references.

:class:`PlanarEndEffectorController` holds the gripper frame at a fixed height and orientation
and moves it in the world's x-y plane by one planar step per action, as the STUCCO paper's
simulated robot does: each step (dx, dy) is clipped to ``max_step`` per axis and starts from the
*measured* gripper position, so a blocked gripper never accumulates error. Within an action the
reference follows a minimum-jerk profile for ``move_fraction`` of the action and then holds.
Differential IK integrates a joint command that tracks the reference; a joint-level controller
downstream tracks that command.

:class:`PlanarActionSequence` is the matching source of planar steps for a fixed action list.

Units: metres, radians, seconds. Poses and steps are in the world frame.
"""

from __future__ import annotations

import numpy as np
from pydrake.common.eigen_geometry import AngleAxis
from pydrake.math import RigidTransform, RollPitchYaw, RotationMatrix
from pydrake.multibody.tree import JacobianWrtVariable
from pydrake.systems.framework import BasicVector, LeafSystem

#: Damping of the IK's pseudo-inverse (m, rad); it only matters near singular postures.
_DAMPING = 1e-3
#: Gain (1/s) of the null-space pull towards the nominal posture (one redundant DoF).
_NULL_GAIN = 2.0


def gripper_rotation(yaw: float) -> RotationMatrix:
    """World orientation of a downward-pointing gripper whose closing axis (x) has this yaw.

    The gripper frame's z (the approach direction) points along world -z.
    """
    return RotationMatrix(RollPitchYaw(0.0, 0.0, yaw)) @ RotationMatrix.MakeXRotation(np.pi)


class ArmKinematics:
    """Forward kinematics and the gripper-frame Jacobian of the robot-only plant.

    It owns a scratch context of that plant, so one instance must not serve two simulations
    running in parallel threads. Positions are in the plant's ordering (rad, m); poses and
    Jacobians are of the gripper frame in the world frame, the Jacobian restricted to the arm's
    n single-dof joints (rows: angular then linear velocity; n = 7 for our iiwa, 3 for the
    SCARA probe arm, whose 6 x 3 Jacobian spans exactly the planar motions).
    """

    def __init__(self, plant, arm_instance, gripper_frame):
        self.plant = plant
        self.context = plant.CreateDefaultContext()
        self.frame = gripper_frame
        joints = [plant.get_joint(j) for j in plant.GetJointIndices(arm_instance)]
        joints = [j for j in joints if j.num_positions() == 1]
        self.q_index = np.array([j.position_start() for j in joints])
        self.v_index = np.array([j.velocity_start() for j in joints])
        self.q_lower = np.array([j.position_lower_limits()[0] for j in joints])
        self.q_upper = np.array([j.position_upper_limits()[0] for j in joints])
        self.v_limit = np.array([j.velocity_upper_limits()[0] for j in joints])

    def set_positions(self, q_full: np.ndarray) -> None:
        """Sets every robot position (the plant's full q, rad and m)."""
        self.plant.SetPositions(self.context, q_full)

    def pose(self) -> RigidTransform:
        """X_WG, the gripper frame's pose in the world."""
        return self.frame.CalcPoseInWorld(self.context)

    def jacobian(self) -> np.ndarray:
        """6 x n spatial-velocity Jacobian of the gripper frame's origin, in the world frame."""
        world = self.plant.world_frame()
        J = self.plant.CalcJacobianSpatialVelocity(
            self.context, JacobianWrtVariable.kV, self.frame, np.zeros(3), world, world
        )
        return J[:, self.v_index]


def _pose_error(X_des: RigidTransform, X: RigidTransform) -> np.ndarray:
    """[angular; linear] error (rad, m) taking X to X_des, expressed in the world frame."""
    R_err = X_des.rotation() @ X.rotation().inverse()
    aa = AngleAxis(R_err.matrix())
    return np.concatenate([aa.angle() * aa.axis(), X_des.translation() - X.translation()])


def _ik_velocity(J: np.ndarray, V: np.ndarray, q: np.ndarray, q_nominal: np.ndarray):
    """Joint velocity realising spatial velocity V, plus a null-space pull towards q_nominal."""
    JJt = J @ J.T + _DAMPING**2 * np.eye(6)
    J_pinv = J.T @ np.linalg.solve(JJt, np.eye(6))
    null = np.eye(J.shape[1]) - J_pinv @ J
    return J_pinv @ V + null @ (_NULL_GAIN * (q_nominal - q))


class StartUnreachable(RuntimeError):
    """The arm cannot put the gripper at the requested start pose (its IK did not converge)."""


def solve_start_ik(kin: ArmKinematics, q_full: np.ndarray, X_des: RigidTransform,
                   q_nominal: np.ndarray, *, tol: float = 1e-7, max_iter: int = 300):
    """Arm positions (rad) putting the gripper frame at ``X_des``, by Newton steps from
    ``q_nominal``; the other robot positions are taken from ``q_full``. Raises
    :class:`StartUnreachable` if it fails."""
    q_full = np.array(q_full, dtype=float)
    q = np.array(q_nominal, dtype=float)
    for _ in range(max_iter):
        q_full[kin.q_index] = q
        kin.set_positions(q_full)
        error = _pose_error(X_des, kin.pose())
        if np.linalg.norm(error) < tol:
            return q
        # Pull towards the nominal posture only while far away: the damped pseudo-inverse
        # leaks a little of that pull into the task and would stall the last micrometres.
        pull_to = q_nominal if np.linalg.norm(error) > 1e-3 else q
        step = _ik_velocity(kin.jacobian(), error, q, pull_to) * 0.5
        q = np.clip(q + step, kin.q_lower, kin.q_upper)
    raise StartUnreachable(f"start IK did not converge: pose error {np.linalg.norm(error):.2e}")


def _min_jerk(s: float) -> tuple[float, float]:
    """Minimum-jerk profile value and its derivative d/ds at s in [0, 1]."""
    s = min(max(s, 0.0), 1.0)
    return s**3 * (10 - 15 * s + 6 * s * s), 30 * s * s * (1 - s) ** 2


class PlanarEndEffectorController(LeafSystem):
    """Differential IK holding the gripper's height and orientation while stepping in x-y.

    Input ports:
        robot_state: measured [q; v] of the robot-only plant (its own ordering).
        planar_step: (dx, dy) of the current action (m, world frame); read once per action,
            at its start, and clipped to ``max_step`` per axis.
    Output ports:
        desired_state: commanded [q; v] of the robot-only plant. Arm joints follow the IK;
            every other robot joint (the fingers) is held at ``hold_positions``.
        planar_goal: (x, y) the current action moves the gripper frame to (m, world frame).

    Discrete state: [q_cmd (n), v_cmd (n), start_xy (2), goal_xy (2), tick (1)] for the arm's
    n joints, updated every ``period`` seconds. An action lasts ``ticks_per_action`` updates.

    ``max_push_force`` (N, None for no limit) caps how hard the gripper pushes in x-y, as the
    paper's floating gripper was moved by a constraint of at most 30 N: whenever the joint
    controller (inverse dynamics, position gain ``joint_kp`` in 1/s^2) pushes harder than that
    along the reference's lead, the reference is pulled back towards the measured gripper
    position, so a gripper blocked by a heavy object stops instead of toppling it.
    """

    def __init__(self, robot_plant, arm_instance, gripper_frame, *, height: float, yaw: float,
                 q_start, q_nominal, hold_positions, start_xy, period: float,
                 action_duration: float, move_fraction: float = 0.7, gain: float = 20.0,
                 max_step: float = 0.03, max_push_force: float | None = None,
                 joint_kp: float | None = None):
        super().__init__()
        self._kin = ArmKinematics(robot_plant, arm_instance, gripper_frame)
        n_arm = len(self._kin.q_index)
        self._nq, self._nv = robot_plant.num_positions(), robot_plant.num_velocities()
        self._n_arm = n_arm
        self._height, self._R = float(height), gripper_rotation(yaw)
        self._q_nominal = np.asarray(q_nominal, dtype=float)
        self._hold = np.asarray(hold_positions, dtype=float)  # full robot q; arm part ignored
        self._period, self._gain, self._max_step = float(period), float(gain), float(max_step)
        self._ticks = round(action_duration / period)
        if abs(self._ticks * period - action_duration) > 1e-9 or self._ticks < 1:
            raise ValueError("action_duration must be a whole number of controller periods")
        self._move_time = move_fraction * action_duration
        if max_push_force is not None and (max_push_force <= 0 or not joint_kp or joint_kp <= 0):
            raise ValueError("max_push_force needs a positive force and a positive joint_kp")
        self._max_push_force = max_push_force
        self._joint_kp = joint_kp
        self.DeclareVectorInputPort("robot_state", self._nq + self._nv)
        self.DeclareVectorInputPort("planar_step", 2)
        x0 = np.concatenate([q_start, np.zeros(n_arm), start_xy, start_xy, [0.0]])
        self._state = self.DeclareDiscreteState(x0)
        self.DeclarePeriodicDiscreteUpdateEvent(period, 0.0, self._update)
        # Both outputs depend on the discrete state only; saying so spares recomputing them
        # at every plant step.
        only_state = {self.discrete_state_ticket(self._state)}
        self.DeclareVectorOutputPort("desired_state", self._nq + self._nv, self.calc_desired_state,
                                     prerequisites_of_calc=only_state)
        self.DeclareVectorOutputPort("planar_goal", 2, self.calc_planar_goal,
                                     prerequisites_of_calc=only_state)

    def _split(self, x):
        n = self._n_arm
        return x[:n], x[n:2 * n], x[2 * n:2 * n + 2], x[2 * n + 2:2 * n + 4], int(x[-1])

    def _update(self, context, discrete_state):
        q, _, start, goal, tick = self._split(context.get_discrete_state(self._state).value())
        start, goal = start.copy(), goal.copy()
        phase = tick % self._ticks
        if phase == 0:
            # A new action: start from where the gripper really is (the paper's semantics).
            x_meas = self.get_input_port(0).Eval(context)
            self._kin.set_positions(x_meas[:self._nq])
            start = self._kin.pose().translation()[:2].copy()
            step = np.clip(self.get_input_port(1).Eval(context), -self._max_step, self._max_step)
            goal = start + step
        # Reference at the end of this update's interval, and its velocity.
        s_dot = 1.0 / self._move_time
        value, slope = _min_jerk((phase + 1) * self._period * s_dot)
        xy_ref, v_ref = start + value * (goal - start), slope * s_dot * (goal - start)
        if self._max_push_force is not None:
            xy_ref, v_ref = self._limit_push(context, q, xy_ref, v_ref)
        X_des = RigidTransform(self._R, [xy_ref[0], xy_ref[1], self._height])
        q_full = self._hold.copy()
        q_full[self._kin.q_index] = q
        self._kin.set_positions(q_full)
        V = self._gain * _pose_error(X_des, self._kin.pose())
        V[3:5] += v_ref
        v = _ik_velocity(self._kin.jacobian(), V, q, self._q_nominal)
        # Respect the joint speed limits by slowing every joint alike (keeps the direction).
        v *= min(1.0, float(np.min(self._kin.v_limit / (np.abs(v) + 1e-12))))
        q_next = np.clip(q + v * self._period, self._kin.q_lower, self._kin.q_upper)
        discrete_state.set_value(
            self._state, np.concatenate([q_next, v, start, goal, [tick + 1]])
        )

    def _limit_push(self, context, q_cmd, xy_ref, v_ref):
        """The reference pulled back so that the joint controller pushes with at most
        ``max_push_force`` along the reference's lead over the measured gripper position.

        The push is the planar force J^+T M kp (q_cmd - q) of the joint controller's position
        term (it balances the contact force once the gripper is blocked). When it exceeds the
        cap, the lead is scaled down by cap / push from the commanded pose's current lead, so
        a blocked gripper presses with about the cap instead of toppling what blocks it.
        """
        x_meas = self.get_input_port(0).Eval(context)
        kin = self._kin
        kin.set_positions(x_meas[:self._nq])
        xy_meas = kin.pose().translation()[:2].copy()
        lead = xy_ref - xy_meas
        norm = float(np.linalg.norm(lead))
        if norm < 1e-9:
            return xy_ref, v_ref
        unit = lead / norm
        J = kin.jacobian()
        M = kin.plant.CalcMassMatrix(kin.context)[np.ix_(kin.v_index, kin.v_index)]
        tau = self._joint_kp * M @ (q_cmd - x_meas[kin.q_index])
        push = float(unit @ (np.linalg.pinv(J).T @ tau)[3:5])
        q_full = x_meas[:self._nq].copy()
        q_full[kin.q_index] = q_cmd
        kin.set_positions(q_full)
        commanded_lead = float(unit @ (kin.pose().translation()[:2] - xy_meas))
        if push <= 0.0 or commanded_lead <= 0.0:
            return xy_ref, v_ref
        allowed = commanded_lead * self._max_push_force / push
        if norm <= allowed:
            return xy_ref, v_ref
        return xy_meas + unit * allowed, np.zeros(2)

    def calc_desired_state(self, context, output: BasicVector):
        q, v, _, _, _ = self._split(context.get_discrete_state(self._state).value())
        x = np.concatenate([self._hold, np.zeros(self._nv)])
        x[self._kin.q_index] = q
        x[self._nq + self._kin.v_index] = v
        output.SetFromVector(x)

    def calc_planar_goal(self, context, output: BasicVector):
        output.SetFromVector(self._split(context.get_discrete_state(self._state).value())[3])


class PlanarActionSequence(LeafSystem):
    """Source of planar steps (m, world frame) for a fixed list, one per ``duration`` seconds.

    Output ports:
        planar_step: steps[k] for t in [k*duration, (k+1)*duration), zeros after the last.
        action_index: k as a 1-vector (the number of actions once all have been played).
    """

    def __init__(self, steps, duration: float):
        super().__init__()
        self._steps = np.asarray(steps, dtype=float).reshape(-1, 2)
        self._duration = float(duration)
        self.DeclareVectorOutputPort("planar_step", 2, self.calc_planar_step)
        self.DeclareVectorOutputPort("action_index", 1, self.calc_action_index)

    def _index(self, context) -> int:
        # A small tolerance so that t = k * duration, computed in floating point, counts as k.
        k = int(np.floor(context.get_time() / self._duration + 1e-6))
        return min(k, len(self._steps))

    def calc_planar_step(self, context, output: BasicVector):
        k = self._index(context)
        output.SetFromVector(self._steps[k] if k < len(self._steps) else np.zeros(2))

    def calc_action_index(self, context, output: BasicVector):
        output.SetFromVector([float(self._index(context))])
class ActionClock(LeafSystem):
    """Output ``action_index``: floor(t / duration) as a 1-vector, the action under way.

    The scene's built-in action sequence is the action clock of a BOR Diagram playing a fixed
    list; with external actions (one ``planar_step`` per action, fed by a policy) the detector
    still needs it, and the planar controller starts a new action on the same grid.
    """

    def __init__(self, duration: float):
        super().__init__()
        self._duration = float(duration)
        self.DeclareVectorOutputPort("action_index", 1, self.calc_action_index)

    def calc_action_index(self, context, output):
        # The same tolerance as the scene's action sequence: t = k * duration counts as k.
        output.SetFromVector([float(np.floor(context.get_time() / self._duration + 1e-6))])


