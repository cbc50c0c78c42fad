"""GraspExecutor: a timed state machine that grasps and lifts an object from above.

While idle it passes the upstream joint command (the planar controller's) through unchanged.
:meth:`GraspExecutor.start` arms it on a context; from then on it sequences, on the simulator
clock, the phases listed in :data:`PHASES`:

1. ``raise``: lift the gripper straight up, to the safe height or as high as the arm reaches
   there (pointing down near the pedestal, the elbow limit caps the height: about 0.2 m at
   0.3 m from the base), before opening the fingers so that opening them cannot shove an
   object the rummaging left next to the gripper;
2. ``open``: open both fingers fully;
3. ``transit``: move above the grasp point while turning (yaw) to the grasp orientation; the
   height reaches the safe height halfway, so the gripper climbs before it passes over things;
4. ``descend``: go straight down to the grasp height, above the grasp point or, for an
   attempt given an approach offset, that far from it. The descent is guarded: when the
   measured gripper height trails the reference by more than ``block_tolerance`` (a finger has
   landed on something), and :meth:`GraspExecutor.start` was given more attempts, the sequence
   starts again from ``raise`` at the measured pose with the next one (its yaw and offset);
5. ``slide``: at the grasp height, slide from where the descent ended to the grasp point, the
   open fingers either side of the target (a box approached along its long axis from beyond
   an end: the fingers shove aside what stands beside its long faces, where a descent from
   above would land on it). An attempt may also descend shifted sideways from its offset
   (clear of something standing beyond the end); its slide first moves back in line, shoving
   that aside, then slides on. An attempt without an offset skips it (it lasts 0 s). The slide is
   guarded as the descent is: when the measured gripper trails the reference by more than
   ``slide_tolerance`` across the table (something stops the fingers short of the grasp
   point), the next attempt, if any, starts. When the last attempt is blocked, the sequence
   presses on by default; started with ``withdraw=True`` it withdraws instead: the gripper
   rises straight up from where it was stopped, fingers still open, and stays there (the
   ``grasp_phase`` output reads ``raise``, then done; :meth:`GraspExecutor.withdrew`);
6. ``close``: close the fingers (see ``close_position``: a command beyond the closed stop, so the
   joint controller keeps squeezing once the bubbles touch the object);
7. ``lift``: raise the gripper by ``lift``;
8. ``hold``: hold still so the object settles (or slips) before the caller measures.

Each phase follows a minimum-jerk profile between two gripper-frame poses (x, y, z, yaw; m, rad,
world frame; the gripper points down, see ``gripper_rotation``) and differential IK on the full
pose integrates the arm's joint command, so the rummaging controller's planar constraint does
not apply. Fingers are commanded in position through the same joint controller.

Ports:
    input ``desired_state``: upstream [q; v] command of the robot-only plant.
    input ``robot_state``: measured [q; v] of the robot-only plant.
    output ``desired_state``: the command to track (upstream while idle).
    output ``grasp_phase``: index into :data:`PHASES` (-1 idle, ``len(PHASES)`` done).
"""

from __future__ import annotations

import numpy as np
from pydrake.common.eigen_geometry import AngleAxis
from pydrake.math import RigidTransform
from pydrake.systems.framework import BasicVector, LeafSystem

from stucco_drake.systems.planar_controller import (
    ArmKinematics,
    gripper_rotation,
    solve_start_ik,
)

PHASES = ("raise", "open", "transit", "descend", "slide", "close", "lift", "hold")
#: Default phase durations (s), same order as PHASES (``slide`` only when there is one).
DURATIONS = (1.5, 0.6, 2.5, 2.0, 2.0, 1.2, 2.0, 0.7)
#: Damping of the IK pseudo-inverse (m, rad); only matters near singular postures.
_DAMPING = 1e-3
#: Gain (1/s) of the null-space pull towards the posture at start (one redundant DoF).
_NULL_GAIN = 2.0
#: Most attempts one grasp makes (the first and its retries).
MAX_ATTEMPTS = 4
# State layout: mode, t0 (of the current attempt), q_cmd (7), then the plan: start (x, y, z,
# yaw), grasp (x, y, yaw), z_safe, z_grasp, finger position at start, q_nominal (7), the height
# the raise phase reaches, the attempt's index, the number of attempts, their yaws, their
# approach offsets (x, y each), their sideways shifts of the descent (x, y each), whether a
# blocked last attempt withdraws. Mode: 0 idle, 1 grasping, 2 withdrawing.
_MODE, _T0, _Q = 0, 1, slice(2, 9)
_START, _GRASP, _ZS, _ZG, _F0, _QN = slice(9, 13), slice(13, 16), 16, 17, 18, slice(19, 26)
_GRASP_YAW = _GRASP.stop - 1
_ZR, _ATTEMPT, _N_YAWS, _YAWS = 26, 27, 28, slice(29, 29 + MAX_ATTEMPTS)
_OFFSETS = slice(_YAWS.stop, _YAWS.stop + 2 * MAX_ATTEMPTS)
_SHIFTS = slice(_OFFSETS.stop, _OFFSETS.stop + 2 * MAX_ATTEMPTS)
_WITHDRAW = _SHIFTS.stop
_N_STATE = _WITHDRAW + 1
_GRASPING, _WITHDRAWING = 1.0, 2.0
#: Share of a shifted attempt's slide spent moving back in line from the shifted descent.
_SHIFT_SHARE = 0.4
_DESCEND, _SLIDE = PHASES.index("descend"), PHASES.index("slide")


def _min_jerk(s: float) -> tuple[float, float]:
    """Minimum-jerk value and its derivative d/ds at s (clamped to [0, 1])."""
    s = min(max(s, 0.0), 1.0)
    return s**3 * (10 - 15 * s + 6 * s * s), 30 * s * s * (1 - s) ** 2


class GraspExecutor(LeafSystem):
    """Top-down grasp-and-lift sequencer (see the module docstring).

    Args:
        robot_plant: the robot-only plant (arm and gripper) the joint controller uses.
        arm_instance, gripper_frame: the arm's model instance and the grasp-centre frame.
        period: update period (s) of the IK and the state machine.
        gain: pose-error feedback gain (1/s) of the differential IK.
        open_position: finger command when open (m, per finger).
        close_position: finger command when closing (m, per finger; below the 0 stop, so the
            position error, hence the squeeze force, persists once the bubbles touch).
        lift: how far the ``lift`` phase raises the gripper (m).
        durations: phase durations (s), in the order of :data:`PHASES`.
        block_tolerance: how far (m) the measured gripper height may trail the reference
            during ``descend`` before the descent counts as blocked. A free descent trails by
            at most 3 mm (TC's can); a finger landing on a box top, by 9 cm.
        slide_tolerance: how far (m) the measured gripper may trail the reference across the
            table during ``slide`` before the slide counts as blocked.
    """

    def __init__(self, robot_plant, arm_instance, gripper_frame, *, period: float = 0.01,
                 gain: float = 10.0, open_position: float = 0.055,
                 close_position: float = -0.35, lift: float = 0.1, durations=DURATIONS,
                 block_tolerance: float = 0.015, slide_tolerance: float = 0.03):
        super().__init__()
        self._kin = ArmKinematics(robot_plant, arm_instance, gripper_frame)
        self._nq, self._nv = robot_plant.num_positions(), robot_plant.num_velocities()
        self._period, self._gain = float(period), float(gain)
        self._block_tolerance = float(block_tolerance)
        self._slide_tolerance = float(slide_tolerance)
        self._open, self._close, self._lift = float(open_position), float(close_position), lift
        self._durations = np.asarray(durations, dtype=float)
        if len(self._durations) != len(PHASES):
            raise ValueError(f"need {len(PHASES)} durations")
        # The phase timings, (ends, durations) (s), of an attempt with an approach offset and
        # of one without (its slide lasts 0 s): looked up at every control step.
        straight = self._durations.copy()
        straight[_SLIDE] = 0.0
        self._timings = {True: (np.cumsum(self._durations), self._durations),
                         False: (np.cumsum(straight), straight)}
        arm_joints = set(self._kin.q_index)
        fingers = [robot_plant.get_joint(j) for j in robot_plant.GetJointIndices()]
        fingers = [j for j in fingers if j.num_positions() == 1
                   and j.position_start() not in arm_joints]
        self._finger_q = np.array([j.position_start() for j in fingers])
        self._finger_v = np.array([j.velocity_start() for j in fingers])
        self._arm_v = self._kin.v_index
        self.DeclareVectorInputPort("desired_state", self._nq + self._nv)
        self.DeclareVectorInputPort("robot_state", self._nq + self._nv)
        self._state = self.DeclareDiscreteState(np.zeros(_N_STATE))
        self._v_state = self.DeclareDiscreteState(np.zeros(7 + len(fingers) + 1))
        self.DeclarePeriodicDiscreteUpdateEvent(period, 0.0, self._update)
        # Outputs of the discrete state (and the passed-through command) only: saying so
        # spares recomputing them at each integrator stage of every plant step.
        state = {self.discrete_state_ticket(self._state), self.discrete_state_ticket(self._v_state)}
        command = self.input_port_ticket(self.get_input_port(0).get_index())
        self.DeclareVectorOutputPort("desired_state", self._nq + self._nv, self.calc_desired_state,
                                     prerequisites_of_calc=state | {command})
        self.DeclareVectorOutputPort("grasp_phase", 1, self.calc_grasp_phase,
                                     prerequisites_of_calc=state | {self.time_ticket()})

    def total_duration(self, context) -> float:
        """Time (s) from the start of the current attempt (see :meth:`attempt`) on this
        system's ``context`` to the end of the last phase."""
        return float(self._ends_of(context.get_discrete_state(self._state).value())[0][-1])

    def phase_end(self, context, name: str) -> float:
        """Time (s) from the start of the current attempt (see :meth:`attempt`) on this
        system's ``context`` to the end of phase ``name``."""
        ends = self._ends_of(context.get_discrete_state(self._state).value())[0]
        return float(ends[PHASES.index(name)])

    def start(self, context, grasp_xy, grasp_yaw: float, z_safe: float, z_grasp: float,
              retry_yaws=(), approach_offsets=None, side_shifts=None, withdraw: bool = False):
        """Arms the sequence on this system's ``context``, from the measured robot state.

        Args:
            grasp_xy: where the grasp centre goes (m, world).
            grasp_yaw: yaw of the fingers' closing axis (rad, world); the equivalent yaw
                (mod pi, the fingers are symmetric) nearest the current one is used.
            z_safe: height of the gripper frame for the transit (m, world).
            z_grasp: height of the gripper frame when closing (m, world).
            retry_yaws: closing yaws (rad, world) of the attempts after a blocked descent or
                slide, at most ``MAX_ATTEMPTS - 1``; without them a blocked descent keeps
                pressing on.
            approach_offsets: per attempt (the first, then one per retry yaw), the offset
                (dx, dy) (m, world) from ``grasp_xy`` where it descends before sliding to
                ``grasp_xy`` (``slide``); None: every attempt descends onto ``grasp_xy``.
            side_shifts: per attempt, a shift (dx, dy) (m, world) of its descent point from
                the offset: the slide first moves back to the offset, then on to ``grasp_xy``
                (an attempt without an offset is not shifted); None: no shifts.
            withdraw: when the last attempt's descent or slide is blocked, rise straight up
                and stay, fingers open, rather than press on (see :meth:`withdrew`).
        """
        yaws = [float(grasp_yaw), *(float(y) for y in retry_yaws)]
        if len(yaws) > MAX_ATTEMPTS or not np.all(np.isfinite(yaws)):
            raise ValueError(f"need 1 to {MAX_ATTEMPTS} finite grasp yaws, got {yaws}")
        offsets = np.zeros((len(yaws), 2)) if approach_offsets is None \
            else np.asarray(approach_offsets, dtype=np.float64)
        if offsets.shape != (len(yaws), 2) or not np.all(np.isfinite(offsets)):
            raise ValueError(f"need one finite (dx, dy) approach offset per attempt "
                             f"({len(yaws)}), got shape {offsets.shape}")
        shifts = np.zeros((len(yaws), 2)) if side_shifts is None \
            else np.array(side_shifts, dtype=np.float64)  # a copy: zeroed where straight
        if shifts.shape != (len(yaws), 2) or not np.all(np.isfinite(shifts)):
            raise ValueError(f"need one finite (dx, dy) side shift per attempt ({len(yaws)}), "
                             f"got shape {shifts.shape}")
        shifts[~np.any(offsets, axis=1)] = 0.0  # a straight descent has no slide to shift
        q = self.get_input_port(1).Eval(context)[:self._nq]
        state = np.zeros(_N_STATE)
        state[_GRASP][:2] = grasp_xy
        state[_ZS], state[_ZG] = z_safe, z_grasp
        state[_QN] = q[self._kin.q_index]
        state[_N_YAWS], state[_YAWS][:len(yaws)] = len(yaws), yaws
        state[_OFFSETS][:offsets.size] = offsets.ravel()
        state[_SHIFTS][:shifts.size] = shifts.ravel()
        state[_WITHDRAW] = float(bool(withdraw))
        state, v_state = self._attempt(state, 0, q, context.get_time())
        context.SetDiscreteState(int(self._state), state)
        context.SetDiscreteState(int(self._v_state), v_state)

    def attempt(self, context) -> tuple[int, float]:
        """(index of the current attempt, its start time in s) on this system's context; once
        withdrawn (:meth:`withdrew`), (the number of attempts, when the withdrawal began)."""
        s = context.get_discrete_state(self._state).value()
        return int(s[_ATTEMPT]), float(s[_T0])

    def withdrew(self, context) -> bool:
        """Whether the last attempt was blocked and the gripper withdrew (``withdraw=True``)."""
        return bool(context.get_discrete_state(self._state).value()[_MODE] == _WITHDRAWING)

    def _attempt(self, plan, index: int, q, t: float):
        """The state and velocity state that start attempt ``index`` of ``plan`` at time t
        from the measured robot positions q: raise, open, transit, descend with its yaw. Index
        the number of attempts starts the withdrawal: raise, then stay."""
        self._kin.set_positions(q)
        X = self._kin.pose()
        yaw0 = float(np.arctan2(X.rotation().matrix()[1, 0], X.rotation().matrix()[0, 0]))
        withdrawing = index >= plan[_N_YAWS]
        grasp_yaw = yaw0 if withdrawing else plan[_YAWS][index]
        state = plan.copy()
        state[_MODE] = _WITHDRAWING if withdrawing else _GRASPING
        state[_T0], state[_ATTEMPT] = t, index
        state[_Q] = q[self._kin.q_index]
        state[_START] = [*X.translation(), yaw0]
        # The equivalent closing yaw (mod pi) nearest the current one: the least turn.
        state[_GRASP_YAW] = yaw0 + np.remainder(grasp_yaw - yaw0 + np.pi / 2, np.pi) - np.pi / 2
        z0 = X.translation()[2]
        state[_ZS] = max(plan[_ZS], z0)
        state[_ZR] = self._reachable_height(q, X.translation()[:2], yaw0, z0, state[_ZS])
        state[_F0] = float(np.mean(q[self._finger_q]))
        n_f = len(self._finger_q)
        return state, np.concatenate([np.zeros(7), np.full(n_f, state[_F0]), [0.0]])

    def _reachable_height(self, q_full, xy, yaw: float, z_from: float, z_to: float) -> float:
        """Highest z <= z_to (m) reachable straight above ``xy`` with the gripper down, found by
        IK continuation in 2 cm steps from the current posture."""
        q_arm, z_ok = q_full[self._kin.q_index], z_from
        for z in np.arange(z_from + 0.02, z_to + 0.02, 0.02):
            z = min(z, z_to)
            X = RigidTransform(gripper_rotation(yaw), [xy[0], xy[1], z])
            try:
                q_arm = solve_start_ik(self._kin, q_full, X, q_arm, tol=1e-5, max_iter=100)
            except RuntimeError:
                break
            z_ok = z
        return z_ok

    @staticmethod
    def _offset(s) -> np.ndarray:
        """(dx, dy) approach offset of the plan's current attempt (m, world)."""
        if s[_MODE] == _WITHDRAWING:
            return np.zeros(2)
        return s[_OFFSETS].reshape(MAX_ATTEMPTS, 2)[int(s[_ATTEMPT])]

    @staticmethod
    def _shift(s) -> np.ndarray:
        """(dx, dy) sideways shift of the current attempt's descent (m, world)."""
        if s[_MODE] == _WITHDRAWING:
            return np.zeros(2)
        return s[_SHIFTS].reshape(MAX_ATTEMPTS, 2)[int(s[_ATTEMPT])]

    def _ends_of(self, s) -> tuple[np.ndarray, np.ndarray]:
        """(phase ends, phase durations) (s) of the plan's current attempt: without an
        approach offset the ``slide`` lasts 0 s."""
        return self._timings[bool(np.any(self._offset(s)))]

    def _reference(self, s, t: float):
        """Gripper pose (x, y, z, yaw), its rate, and the finger command at plan time t."""
        x0, y0, z0, yaw0 = s[_START]
        xg, yg, yaw_g = s[_GRASP]
        xd, yd = np.array([xg, yg]) + self._offset(s) + self._shift(s)
        zs, zg, zr = s[_ZS], s[_ZG], s[_ZR]
        poses = [(x0, y0, z0, yaw0), (x0, y0, zr, yaw0), (x0, y0, zr, yaw0),
                 (xd, yd, zs, yaw_g), (xd, yd, zg, yaw_g), (xg, yg, zg, yaw_g),
                 (xg, yg, zg, yaw_g), (xg, yg, zg + self._lift, yaw_g),
                 (xg, yg, zg + self._lift, yaw_g)]
        fingers = [s[_F0], s[_F0], self._open, self._open, self._open, self._open,
                   self._close, self._close, self._close]
        if s[_MODE] == _WITHDRAWING:  # raised, then still: fingers as they were
            poses[2:] = [poses[1]] * (len(poses) - 2)
            fingers = [s[_F0]] * len(fingers)
        ends, durations = self._ends_of(s)
        # A phase lasting 0 s ends where it begins: side="right" passes over it.
        k = int(np.searchsorted(ends, t, side="right"))
        if k >= len(PHASES):
            return np.array(poses[-1]), np.zeros(4), fingers[-1], 0.0, len(PHASES)
        t_begin, duration = ends[k] - durations[k], durations[k]
        a, b = np.array(poses[k]), np.array(poses[k + 1])
        if k == _SLIDE and np.any(self._shift(s)):
            # Back in line first (shoving aside what the shift kept the descent off), then on.
            in_line, back = a - np.array([*self._shift(s), 0.0, 0.0]), _SHIFT_SHARE * duration
            if t - t_begin < back:
                b, duration = in_line, back
            else:
                a, t_begin, duration = in_line, t_begin + back, duration - back
        value, slope = _min_jerk((t - t_begin) / duration)
        rate = slope / duration
        f = fingers[k] + value * (fingers[k + 1] - fingers[k])
        pose, pose_rate = a + value * (b - a), rate * (b - a)
        if PHASES[k] == "transit":
            # Climb in the first half of the transit, before passing over the clutter.
            z_value, z_slope = _min_jerk(2 * (t - t_begin) / durations[k])
            pose[2] = a[2] + z_value * (b[2] - a[2])
            pose_rate[2] = 2 * z_slope / durations[k] * (b[2] - a[2])
        return pose, pose_rate, f, rate * (fingers[k + 1] - fingers[k]), k

    def _blocked(self, context, s, t: float, phase: int):
        """The measured robot positions when the descent (height) or the slide (across the
        table) trails its reference by more than its tolerance and an attempt, or the
        withdrawal, is left, else None."""
        if phase not in (_DESCEND, _SLIDE) or s[_MODE] != _GRASPING:
            return None
        if s[_ATTEMPT] + 1 >= s[_N_YAWS] and not s[_WITHDRAW]:
            return None
        q_measured = self.get_input_port(1).Eval(context)[:self._nq]
        self._kin.set_positions(q_measured)
        lag = self._kin.pose().translation() - self._reference(s, t - self._period)[0][:3]
        if phase == _DESCEND:
            return q_measured if lag[2] > self._block_tolerance else None
        return q_measured if np.hypot(*lag[:2]) > self._slide_tolerance else None

    def _update(self, context, discrete_state):
        s = context.get_discrete_state(self._state).value()
        if s[_MODE] == 0.0:
            return
        # Reference at the end of this update's interval (the command holds until then).
        t = context.get_time() - s[_T0] + self._period
        pose, rate, f, f_rate, phase = self._reference(s, t)
        q_measured = self._blocked(context, s, t, phase)
        if q_measured is not None:
            new, v_state = self._attempt(s, int(s[_ATTEMPT]) + 1, q_measured,
                                         context.get_time())  # fmt: skip
            discrete_state.set_value(self._state, new)
            discrete_state.set_value(self._v_state, v_state)
            return
        X_des = RigidTransform(gripper_rotation(pose[3]), pose[:3])
        q = s[_Q]
        q_full = self.get_input_port(0).Eval(context)[:self._nq].copy()
        q_full[self._kin.q_index] = q
        self._kin.set_positions(q_full)
        X = self._kin.pose()
        aa = AngleAxis((X_des.rotation() @ X.rotation().inverse()).matrix())
        error = np.concatenate([aa.angle() * aa.axis(), X_des.translation() - X.translation()])
        V = self._gain * error + np.array([0.0, 0.0, rate[3], *rate[:3]])
        J = self._kin.jacobian()
        J_pinv = J.T @ np.linalg.inv(J @ J.T + _DAMPING**2 * np.eye(6))
        v = J_pinv @ V + (np.eye(7) - J_pinv @ J) @ (_NULL_GAIN * (s[_QN] - q))
        # Respect the joint speed limits by slowing every joint alike (keeps the direction).
        v *= min(1.0, float(np.min(self._kin.v_limit / (np.abs(v) + 1e-12))))
        new = s.copy()
        new[_Q] = np.clip(q + v * self._period, self._kin.q_lower, self._kin.q_upper)
        discrete_state.set_value(self._state, new)
        discrete_state.set_value(self._v_state, np.concatenate(
            [v, np.full(len(self._finger_q), f), [f_rate]]))

    def calc_desired_state(self, context, output: BasicVector):
        upstream = self.get_input_port(0).Eval(context)
        s = context.get_discrete_state(self._state).value()
        if s[_MODE] == 0.0:
            output.SetFromVector(upstream)
            return
        vs = context.get_discrete_state(self._v_state).value()
        x = upstream.copy()
        x[self._kin.q_index] = s[_Q]
        x[self._nq + self._arm_v] = vs[:7]
        x[self._finger_q] = vs[7:-1]
        x[self._nq + self._finger_v] = vs[-1]
        output.SetFromVector(x)

    def calc_grasp_phase(self, context, output: BasicVector):
        s = context.get_discrete_state(self._state).value()
        if s[_MODE] == 0.0:
            output.SetFromVector([-1.0])
            return
        phase = self._reference(s, context.get_time() - s[_T0])[4]
        if s[_MODE] == _WITHDRAWING and phase > 0:
            phase = len(PHASES)  # raised: nothing more to do
        output.SetFromVector([float(phase)])
