"""The belief rummaging policy (core/rummaging.py), played with a kinematic gripper against a
box whose geometry is known: its steps, contacts and stops are checked against where the box
really is. The coverage sweep's own tests are in test_coverage.py."""

import dataclasses

import numpy as np
import pytest
from test_probing import BOX, FOOTPRINT, footprint_gap, guarded_move

from stucco_drake.core.coverage import (
    CoverageParams,
    coverage_waypoints,
    lane_centres,
    waypoint_steps,
)
from stucco_drake.core.rummage_params import RummageParams
from stucco_drake.core.rummaging import BeliefRummagingPolicy

MAX_STEP = 0.03
START = np.array([0.0, 0.1])
WIDTH = 0.1  # FOOTPRINT's extent along y (m)
# Lanes across the band with both its ends as lanes (not laid out from the start).
BAND = CoverageParams(from_start=False)
BAND_NEAREST = CoverageParams(nearest_first=True, from_start=False)


class Belief:
    """Pose hypotheses stand-in: the box's true pose, confident once the gripper has touched
    the box ``needed`` times (counted by the test)."""

    def __init__(self, pose, needed: int):
        self.true, self.needed, self.touches, self.asked = pose, needed, 0, 0

    def __call__(self):
        self.asked += 1
        confidence = 0.9999 if self.touches >= self.needed else 0.5
        return dataclasses.make_dataclass("H", ["pose", "confidence"])(self.true, confidence)


def play(policy, pose, belief, limit=400, contact_y=None):
    """Plays ``policy`` with the kinematic gripper against BOX at ``pose`` (None: nothing on
    the table): (positions, steps, contacts). With ``contact_y`` (the gripper's y -> the
    contact's y), each touch's contact point is given to the policy."""
    xy, in_contact, positions, steps, contacts = START.copy(), False, [START.copy()], [], []
    for _ in range(limit):
        step = policy.next_step(xy, in_contact, belief)
        if step is None:
            break
        if pose is None:
            xy, in_contact = xy + step, False
        else:
            xy, in_contact = guarded_move(xy, step, pose)
        if in_contact and isinstance(belief, Belief):
            belief.touches += 1
        if in_contact and contact_y is not None:
            policy.sensed([[xy[0] + 0.04, contact_y(xy[1]), 0.1]])
        positions.append(xy.copy())
        steps.append(step)
        contacts.append(in_contact)
    return np.array(positions), np.array(steps), np.array(contacts)


def test_with_nothing_felt_the_policy_plays_the_whole_sweep():
    """Nothing on the table, lanes from the start's x: every lane is pushed to its far end,
    in the sweep's own steps (its lanes nearest the start first), and the belief is never
    asked."""
    policy = BeliefRummagingPolicy(BOX, FOOTPRINT, MAX_STEP, START,
                                   RummageParams(coverage=BAND_NEAREST, max_actions=400,
                                                 transit_back=0.0))
    belief = Belief(None, 1)
    _positions, steps, _ = play(policy, None, belief)
    lanes = coverage_waypoints(START, BAND_NEAREST, WIDTH)
    sweep = waypoint_steps(START, lanes, MAX_STEP)
    assert len(steps) == len(sweep) and steps == pytest.approx(sweep, abs=1e-12)
    assert belief.asked == 0


def test_actions_are_tallied_by_what_they_were_for():
    """Nothing on the table: every step along +x is a lane's push, every other step travel,
    and the tally says so. With the box of the next test: the step after the first touch is
    a back-off, and the probe round's steps are the rest after the lane's travel and push."""
    params = RummageParams(coverage=BAND_NEAREST, max_actions=400, transit_back=0.0)
    policy = BeliefRummagingPolicy(BOX, FOOTPRINT, MAX_STEP, START, params)
    _positions, steps, _ = play(policy, None, Belief(None, 1))
    forward = int(np.sum((steps[:, 0] > 0) & (np.abs(steps[:, 1]) < 1e-12)))
    assert policy.action_kinds == {"push": forward, "travel": len(steps) - forward}

    pose = np.array([0.3, 0.17, np.radians(90)])
    policy = BeliefRummagingPolicy(BOX, FOOTPRINT, MAX_STEP, START,
                                   RummageParams(coverage=BAND_NEAREST))
    _positions, steps, contacts = play(policy, pose, Belief(pose, needed=2))
    first = int(np.argmax(contacts))
    kinds = policy.action_kinds
    assert sum(kinds.values()) == len(steps) and kinds["back_off"] == 1
    assert kinds["push"] + kinds.get("travel", 0) == first + 1
    assert kinds["probe"] == len(steps) - first - 2 > 0
    # The probe round's steps by phase add up to them; a retreat follows each touch.
    phases = policy.probe_phases
    assert sum(phases.values()) == kinds["probe"] and phases["approach"] >= 1
    assert phases.get("retreat", 0) == policy.touches


def touches_are_guarded(positions, contacts, pose) -> bool:
    """Every position where contact was sensed lies within one guarded-move increment (1/30 of
    a step of at most 3 cm) outside the box: the gripper never pressed into it."""
    gaps = [footprint_gap(p, pose) for p in positions[1:][contacts]]
    return all(-1e-9 < gap <= 0.03 / 30 + 1e-9 for gap in gaps)


def test_the_policy_backs_off_probes_and_stops_once_confident():
    """A box 30 cm ahead, long side along x (x 0.221..0.379, y 0.14..0.20), caught by the
    first lane's footprint (y 0.05..0.15): the push that touches it is backed off from by 2 cm
    along -x; the hypotheses place it, a probe round touches it, and with that touch the
    belief is confident and the policy stops, long before the sweep's 177 actions."""
    pose = np.array([0.3, 0.17, np.radians(90)])
    belief = Belief(pose, needed=2)
    policy = BeliefRummagingPolicy(BOX, FOOTPRINT, MAX_STEP, START,
                                   RummageParams(coverage=BAND_NEAREST))
    positions, steps, contacts = play(policy, pose, belief)
    first = int(np.argmax(contacts))
    assert positions[first + 1][1] == pytest.approx(0.10)
    assert steps[first + 1] == pytest.approx([-RummageParams().back_off, 0.0])
    assert policy.rounds == 1 and policy.touches >= 1 and belief.touches >= 2
    # The first push reaches the box in 7 steps; a probe round takes at most 30.
    assert policy.confidence == pytest.approx(0.9999) and len(steps) < 40
    assert touches_are_guarded(positions, contacts, pose)


def test_checked_after_each_probe_the_policy_stops_at_the_touch_that_bears_it_out():
    """The previous test's box and belief, asked after every probe: the policy stops at the
    first probe that touches the box (its last step is that touch, no retreat after it),
    sooner than when it waits for the round's end."""
    pose = np.array([0.3, 0.17, np.radians(90)])
    whole = BeliefRummagingPolicy(BOX, FOOTPRINT, MAX_STEP, START,
                                  RummageParams(coverage=BAND_NEAREST))
    _positions, whole_steps, _ = play(whole, pose, Belief(pose, needed=2))
    each = BeliefRummagingPolicy(BOX, FOOTPRINT, MAX_STEP, START,
                                 RummageParams(coverage=BAND_NEAREST, check_each_probe=True))
    positions, steps, contacts = play(each, pose, Belief(pose, needed=2))
    assert contacts[-1] and each.touches == 1 and each.rounds == 1
    assert each.confidence == pytest.approx(0.9999) and len(steps) < len(whole_steps)
    assert touches_are_guarded(positions, contacts, pose)


def test_a_lane_through_the_believed_target_is_pushed_guarded():
    """Never confident, one probe round: the policy explores on, and the next lane (y 0.19),
    straight through the believed box, is pushed until it touches the box's near end and
    backed off from, without pressing into it."""
    pose = np.array([0.3, 0.17, np.radians(90)])
    params = RummageParams(coverage=BAND_NEAREST, max_rounds=1, max_actions=400)
    policy = BeliefRummagingPolicy(BOX, FOOTPRINT, MAX_STEP, START, params)
    positions, _steps, contacts = play(policy, pose, Belief(pose, needed=99))
    assert policy.rounds == 1
    touched = positions[1:][contacts]
    assert np.any(np.abs(touched[:, 1] - 0.19) < 1e-9)
    assert touches_are_guarded(positions, contacts, pose)
    for y in (0.01, -0.08, -0.17):  # the lanes beyond the box are pushed to their far end
        assert positions[np.abs(positions[:, 1] - y) < 1e-9, 0].max() == pytest.approx(0.38)


def test_a_felt_object_the_belief_does_not_place_is_touched_beside_then_left():
    """No hypotheses (the belief says None): each push that touches the box is backed off
    from and made again 3 cm to one side, then 3 cm to the other (each from the lanes' x, 4
    cm behind the start), then the lane is left. The
    box spans y 0.14..0.20, the footprint 5 cm either side of its origin: lane 0.10 (the
    first, nearest the start) touches at y 0.10 and 0.13, and its push at 0.07 passes the
    box to the far end; lane 0.19 touches at 0.19, 0.22 and 0.16; lanes 0.28 and 0.01 pass
    it."""
    pose = np.array([0.3, 0.17, np.radians(90)])
    policy = retouching_policy(None)
    positions, _steps, contacts = play(policy, pose, lambda: None)
    assert policy.rounds == 0 and policy.contacts == int(contacts.sum())
    touched_y = positions[1:][contacts][:, 1]
    assert touched_y == pytest.approx([0.10, 0.13, 0.19, 0.22, 0.16], abs=1e-9)
    beside = np.abs(positions[:, 1] - 0.07) < 1e-9
    assert positions[beside, 0].max() == pytest.approx(0.38)
    assert np.max(positions[:, 1]) == pytest.approx(0.28)
    assert positions[-1, 0] == pytest.approx(-0.04, abs=1e-12)  # lanes end 4 cm behind
    # Every sideways move, to a lane or to a touch beside, is made 4 cm behind the start.
    sideways = np.abs(np.diff(positions[:, 1])) > 1e-9
    assert positions[:-1][sideways, 0] == pytest.approx(-0.04, abs=1e-12)
    assert touches_are_guarded(positions, contacts, pose)


def retouching_policy(retouch_back):
    """The policy of the touches-beside tests: nearest lane first, never pushing through."""
    return BeliefRummagingPolicy(BOX, FOOTPRINT, MAX_STEP, START,
                                 RummageParams(coverage=BAND_NEAREST, max_actions=400,
                                               push_through_below=0.0,
                                               retouch_back=retouch_back))


def test_touches_beside_from_where_the_gripper_backed_off_save_the_way_back():
    """The previous test's layout with ``retouch_back`` 0: each touch beside moves sideways
    where the gripper backed off to (2 cm behind its touch at x 0.18, so x 0.16) instead of
    at the lanes' x (-0.04): the same five touches, and each of the four touches beside saves
    the 0.20 m back (7 steps at 3 cm) and forth (the push's steps to the face: 0.22 m in
    equal steps of the whole 0.42 m push, 8, against 0.02 m, 1), 13–14 actions each (the
    legs' equal steps round differently)."""
    pose = np.array([0.3, 0.17, np.radians(90)])
    played = {}
    for back in (None, 0.0):
        policy = retouching_policy(back)
        played[back] = play(policy, pose, lambda: None)
    positions, steps, contacts = played[0.0]
    touched = positions[1:][contacts]
    assert touched[:, 1] == pytest.approx([0.10, 0.13, 0.19, 0.22, 0.16], abs=1e-9)
    assert touched[:, 0] == pytest.approx(0.18, abs=1e-3)  # guarded: stopped at the face
    sideways = np.abs(np.diff(positions[:, 1])) > 1e-9
    assert set(np.round(positions[:-1][sideways, 0], 3)) == {-0.04, 0.16}
    assert 4 * 13 <= len(played[None][1]) - len(steps) <= 4 * 14
    assert touches_are_guarded(positions, contacts, pose)


def test_a_near_way_to_a_touch_beside_that_bumps_goes_round_by_the_lanes():
    """A second box stands beside the felt one, a step back from it (x 0.021..0.179, y
    0.17..0.23): with ``retouch_back`` 0 the sideways move from where the gripper backed off
    (x 0.16) bumps it; the gripper backs off and goes round by the lanes' x (-0.04), and from
    there on touches what it touches without the near way, at the same points (the touch
    beside at y 0.13 now meets the second box's near face, footprint front at x 0.021)."""
    felt, neighbour = np.array([0.3, 0.17, np.radians(90)]), np.array([0.1, 0.20, np.radians(90)])

    touched = {}
    for back in (None, 0.0):
        policy = retouching_policy(back)
        xy, in_contact, points = START.copy(), False, []
        while (step := policy.next_step(xy, in_contact, lambda: None)) is not None:
            xy, in_contact = guarded_move(xy, step, [felt, neighbour])
            if in_contact:
                points.append(xy.copy())
        touched[back] = np.array(points)
    assert policy.bumps == 1
    bump = touched[0.0][1]  # the near way's bump: at x 0.16, short of y 0.13
    assert bump[0] == pytest.approx(0.16, abs=1e-9) and 0.10 < bump[1] < 0.13
    assert np.delete(touched[0.0], 1, axis=0) == pytest.approx(touched[None], abs=1e-9)
    # Stopped within one guarded increment (1/30 of a step of at most 3 cm) of the face.
    assert -0.019 - 0.001 - 1e-9 <= touched[None][1][0] <= -0.019
    assert touched[None][1][1] == pytest.approx(0.13, abs=1e-9)


def test_a_touch_on_one_side_of_the_gripper_is_followed_that_way():
    """The lane at y 0.10 meets the box (y 0.14..0.20) with the footprint's +y edge: the
    contact, at the middle of the overlap (y 0.145), lies 4.5 cm to +y of the gripper's centre
    line, so both touches beside go that way, 3 and 6 cm (y 0.13 and 0.16), and both touch the
    box; told nothing of the side, the second would go to y 0.07 and miss it."""
    pose = np.array([0.3, 0.17, np.radians(90)])

    def overlap_middle(y):
        return (max(0.14, y - 0.05) + min(0.20, y + 0.05)) / 2

    policy = retouching_policy(None)
    positions, _steps, contacts = play(policy, pose, lambda: None, contact_y=overlap_middle)
    touched_y = positions[1:][contacts][:, 1]
    assert touched_y[:3] == pytest.approx([0.10, 0.13, 0.16], abs=1e-9)


def test_lanes_begin_and_end_behind_the_start():
    """Nothing on the table: every lane begins and ends ``transit_back`` (4 cm) behind the
    start's x and is pushed to the same far end (0.38 m ahead of the start) as the sweep's."""
    policy = BeliefRummagingPolicy(BOX, FOOTPRINT, MAX_STEP, START,
                                   RummageParams(coverage=BAND_NEAREST, max_actions=400))
    positions, _steps, _ = play(policy, None, Belief(None, 1))
    for y in lane_centres(BAND, WIDTH):
        on_lane = positions[np.abs(positions[:, 1] - y) < 1e-9, 0]
        assert on_lane.min() == pytest.approx(-0.04) and on_lane.max() == pytest.approx(0.38)


# A box just in front of the start's x and to -y of it: x 0.03..0.09, y -0.114..0.044 (the
# footprint reaches 4 cm ahead of the gripper's origin, 5 cm to either side).
NEAR_BOX = np.array([0.06, -0.035, 0.0])


def test_a_travel_that_keeps_bumping_gives_up_the_lanes_beyond():
    """Lanes travelled between at the start's x: going from lane 0.28 down to lane 0.01 the
    footprint meets the box at y 0.094; after the third bump (``lane_bumps`` 2) the lanes
    beyond on that side (0.01, -0.08, -0.17) are given up and, none being left, the policy
    stops: it never gets below y 0.09. Travelled 4 cm further back, it passes the box
    without a bump and pushes those lanes."""
    params = RummageParams(coverage=BAND_NEAREST, max_actions=400, transit_back=0.0)
    policy = BeliefRummagingPolicy(BOX, FOOTPRINT, MAX_STEP, START, params)
    positions, steps, contacts = play(policy, NEAR_BOX, lambda: None)
    assert policy.bumps == 3 and int(contacts.sum()) == 3
    assert positions[:, 1].min() > 0.09 and len(steps) < 400
    behind = BeliefRummagingPolicy(BOX, FOOTPRINT, MAX_STEP, START,
                                   dataclasses.replace(params, transit_back=0.04))
    positions, _steps, _ = play(behind, NEAR_BOX, lambda: None)
    assert behind.bumps == 0 and positions[:, 1].min() == pytest.approx(-0.17)


def test_a_lane_the_belief_does_not_place_is_pushed_through_once():
    """No hypotheses: once lane 0.19's touch and its two touches beside are spent (as in the
    test above), the lane is pushed again from its start, and the push goes on after it
    touches the box (at 30 N the box does not move: the next step stalls against it and the
    push is given up). Every other lane's touches are as without the shove."""
    pose = np.array([0.3, 0.17, np.radians(90)])
    policy = BeliefRummagingPolicy(BOX, FOOTPRINT, MAX_STEP, START,
                                   RummageParams(coverage=BAND_NEAREST, max_actions=400))
    positions, steps, contacts = play(policy, pose, lambda: None)
    assert policy.shoves == 1
    touched = np.flatnonzero(contacts)
    assert positions[1:][touched][:, 1] == pytest.approx(
        [0.10, 0.13, 0.19, 0.22, 0.16, 0.19, 0.19], abs=1e-9)
    # The shove's first touch is followed by another step ahead, not a back-off.
    assert steps[touched[5] + 1][0] > 0 and touches_are_guarded(
        positions, contacts, pose)


class Misplaced:
    """Pose hypotheses stand-in, certain (0.9999) from the start that the box lies at
    ``pose``, where nothing is."""

    def __init__(self, pose):
        self.pose, self.confidence = pose, 0.9999

    def __call__(self):
        return self


def test_a_confidence_no_probe_has_borne_out_does_not_stop_the_policy():
    """The box at y 0.14..0.20, believed (at 0.9999) at y -0.23..-0.17 where nothing is: the
    first push touches the real box; the probe round goes where the belief says and touches
    nothing, so the policy does not stop there but explores on; without ``verified_stop`` it
    stops at that first touch."""
    pose = np.array([0.3, 0.17, np.radians(90)])
    belief = Misplaced(np.array([0.3, -0.2, np.radians(90)]))
    params = RummageParams(coverage=BAND_NEAREST, max_actions=400)
    policy = BeliefRummagingPolicy(BOX, FOOTPRINT, MAX_STEP, START, params)
    _positions, steps, contacts = play(policy, pose, belief)
    first = int(np.argmax(contacts))
    assert policy.rounds >= 1 and policy.touches == 0 and len(steps) > first + 40
    hasty = BeliefRummagingPolicy(BOX, FOOTPRINT, MAX_STEP, START,
                                  dataclasses.replace(params, verified_stop=False))
    _positions, steps, _ = play(hasty, pose, belief)
    assert len(steps) == first + 1 and hasty.rounds == 0


def test_an_unsure_belief_extends_the_budget_a_sure_one_stops_at_it():
    """Nothing on the table, 10 actions, extended to 16 below a confidence of 0.6: a belief
    at 0.9 stops the run at 10, one at 0.5 at 16, and one that reaches 0.9 once 13 actions
    are played at 13. Without ``extend_below`` the budget is 10 whatever the belief."""
    def run(confidence, **extension):
        params = RummageParams(coverage=BAND_NEAREST, max_actions=10, transit_back=0.0,
                               **extension)
        policy = BeliefRummagingPolicy(BOX, FOOTPRINT, MAX_STEP, START, params)
        H = dataclasses.make_dataclass("H", ["pose", "confidence"])
        _positions, steps, _ = play(policy, None,
                                    lambda: H(np.zeros(3), confidence(policy.actions)))
        return len(steps)

    extension = {"extend_below": 0.6, "extended_max_actions": 16}
    assert run(lambda k: 0.9, **extension) == 10
    assert run(lambda k: 0.5, **extension) == 16
    assert run(lambda k: 0.9 if k >= 13 else 0.5, **extension) == 13
    assert run(lambda k: 0.5) == 10
    with pytest.raises(ValueError, match="extended_max_actions"):
        RummageParams(max_actions=10, extend_below=0.6, extended_max_actions=10)
