"""The belief rummaging policy's first touch: pushing a lane through (``shove_first``, or
where the felt object resisted, ``shove_resisted_from``) and probing as soon as the belief
places what was felt (``probe_once_placed``). Played as in test_rummaging.py, against a box
the belief places at a confidence of 0.3."""

import numpy as np
import pytest
from test_probing import BOX, FOOTPRINT, guarded_move
from test_rummaging import BAND_NEAREST, MAX_STEP, START

from stucco_drake.core.rummage_params import RummageParams
from stucco_drake.core.rummaging import BeliefRummagingPolicy


class Unsure:
    """Pose hypotheses stand-in: the box's true pose, always at a confidence of 0.3."""

    def __init__(self, pose):
        self.pose, self.confidence = pose, 0.3

    def __call__(self):
        return self


def overlap_middle(y):
    """The contact's y for the gripper at lane y against the box turned 90 degrees at y 0.17
    (its long face spans y 0.14..0.20; the footprint 10 cm wide): the overlap's middle."""
    return (max(0.14, y - 0.05) + min(0.20, y + 0.05)) / 2


def play_kinds(policy, pose, belief=None, force=None, contact_y=None, limit=80, late=False):
    """Plays ``policy`` against BOX at ``pose``, placed by ``belief`` (default
    :class:`Unsure`): (each action's kind, the gripper's position before it, whether it was a
    push that touched). ``force`` (N, None: not given) is each touch's peak force (0 out of
    contact), or a function of the kind of action that touched giving it; with
    ``contact_y`` (the gripper's y -> the contact's y), each contact's point is given to the
    policy, after the action (``late``: after the next one, as in the loop)."""
    belief = belief or Unsure(pose)
    xy, in_contact, kinds, positions, touches = START.copy(), False, [], [], []
    pending = []
    for _ in range(limit):
        if force is not None:
            felt = force(kinds[-1]) if callable(force) and in_contact else force
            policy.felt_force(felt if in_contact else 0.0)
        step = policy.next_step(xy, in_contact, belief)
        if step is None:
            break
        kinds.append(policy._kind)
        positions.append(xy.copy())
        xy, in_contact = guarded_move(xy, step, pose)
        touches.append(in_contact and kinds[-1] == "push")
        contact = [[xy[0] + 0.04, contact_y(xy[1]), 0.1]] if in_contact and contact_y else []
        if late:
            policy.sensed(pending)
            pending = contact
        elif contact:
            policy.sensed(contact)
    return kinds, positions, touches


def test_shove_first_pushes_an_unsure_lane_through_from_the_touch_then_probes():
    """The box (x 0.221..0.379, y 0.14..0.20) is placed at a confidence of 0.3 from the
    first touch on. By default the policy probes it at once. With ``shove_first`` it touches
    beside twice (towards the contact, at y 0.13 and 0.16, as the test above), then pushes
    lane 0.10 through from where it backed off (the last touch at x = 0.221 - 0.04 = 0.181,
    backed off 2 cm: 0.161), never going back to the lanes' start (x -0.04) on the way, and
    probes after the shove."""
    pose = np.array([0.3, 0.17, np.radians(90)])

    for shove_first in (False, True):
        policy = BeliefRummagingPolicy(BOX, FOOTPRINT, MAX_STEP, START,
                                       RummageParams(coverage=BAND_NEAREST, max_actions=80,
                                                     retouch_back=0.0,
                                                     shove_first=shove_first))  # fmt: skip
        kinds, positions, touches = play_kinds(policy, pose, contact_y=overlap_middle)
        shove = kinds.index("shove") if "shove" in kinds else len(kinds)
        probe = kinds.index("probe")
        if not shove_first:
            assert probe < shove and sum(touches[:probe]) == 1
            continue
        assert shove < probe and sum(touches[:shove]) == 3
        assert positions[shove] == pytest.approx([0.161, 0.10], abs=2e-3)
        first_touch = touches.index(True)
        assert min(p[0] for p in positions[first_touch:shove]) > 0.0


def test_a_push_the_felt_object_resisted_is_shoved_through_at_once():
    """The scene above, with ``shove_resisted_from`` 20 N: a first touch felt at 30 N (the
    object did not give way) has the lane pushed through at once from where the gripper backed
    off (x 0.161), no touch beside first; at 3 N (it gave way) or unmeasured (NaN) the policy
    probes first, as by default. With ``press_step`` the touch is followed by a press, one more
    action along the push, and the press's force decides."""
    pose = np.array([0.3, 0.17, np.radians(90)])
    for press_step in (0.0, 0.02):
        for force, shoves in ((30.0, True), (3.0, False), (float("nan"), False)):
            params = RummageParams(coverage=BAND_NEAREST, max_actions=80,
                                   shove_resisted_from=20.0, press_step=press_step)
            policy = BeliefRummagingPolicy(BOX, FOOTPRINT, MAX_STEP, START, params)
            kinds, positions, touches = play_kinds(policy, pose, force=force)
            shove = kinds.index("shove") if "shove" in kinds else len(kinds)
            assert (shove < kinds.index("probe")) == shoves, (press_step, force)
            pressed = kinds[touches.index(True) + 1] == "press"
            assert pressed == (press_step > 0) and ("press" in kinds) == pressed
            if shoves:
                assert sum(touches[:shove]) == 1
                assert positions[shove] == pytest.approx([0.161, 0.10], abs=2e-3)


def test_a_press_that_gave_way_more_easily_than_the_target_could_is_shoved_through():
    """``shove_gave_way_below`` 0.25 of the target's weight (a 10 kg target: 24.5 N; a
    0.5 kg one: 1.23 N): a press felt at 3 N slid something lighter than a 10 kg target, so
    the lane is pushed through at once from where the gripper backed off; at 30 N (no
    ``shove_resisted_from``), or against a 0.5 kg target, the policy probes first. The rule
    needs a press and the target's mass, and says so before any play."""
    pose = np.array([0.3, 0.17, np.radians(90)])
    params = RummageParams(coverage=BAND_NEAREST, max_actions=80, press_step=0.02,
                           shove_gave_way_below=0.25)
    for mass, force, shoves in ((10.0, 3.0, True), (10.0, 30.0, False), (0.5, 3.0, False)):
        policy = BeliefRummagingPolicy(BOX, FOOTPRINT, MAX_STEP, START, params,
                                       target_mass=mass)
        kinds, positions, touches = play_kinds(policy, pose, force=force)
        shove = kinds.index("shove") if "shove" in kinds else len(kinds)
        assert (shove < kinds.index("probe")) == shoves, (mass, force)
        assert kinds[touches.index(True) + 1] == "press"
        if shoves:
            assert positions[shove] == pytest.approx([0.161, 0.10], abs=2e-3)
    with pytest.raises(ValueError, match="target's mass"):
        BeliefRummagingPolicy(BOX, FOOTPRINT, MAX_STEP, START, params)
    with pytest.raises(ValueError, match="needs press_step"):
        RummageParams(shove_gave_way_below=0.25)
    with pytest.raises(ValueError, match="which is not set"):
        RummageParams(shove_stops_from=30.0)


def test_a_shove_past_what_gave_way_ends_where_something_resists():
    """The press above gave way (3 N, a 10 kg target), and the shove then meets the box at
    45 N (its first step does). With ``shove_stops_from`` 30 N the shove ends there: the
    gripper backs off and probes from where it is, where without it the stalled shove first
    goes back to the lanes' x (a travel) before the probe. A shove begun because the press
    resisted (45 N) is not ended by it."""
    pose = np.array([0.3, 0.17, np.radians(90)])
    for stops_from in (None, 30.0):
        for press_force in (3.0, 45.0):
            params = RummageParams(coverage=BAND_NEAREST, max_actions=80, press_step=0.02,
                                   shove_gave_way_below=0.25, shove_resisted_from=20.0,
                                   shove_stops_from=stops_from)  # fmt: skip
            policy = BeliefRummagingPolicy(BOX, FOOTPRINT, MAX_STEP, START, params,
                                           target_mass=10.0)
            kinds, _, _ = play_kinds(
                policy, pose, force=lambda kind, f=press_force: f if kind != "shove" else 45.0)
            shove, probe = kinds.index("shove"), kinds.index("probe")
            between = kinds[shove:probe]
            ends = stops_from is not None and press_force < 20.0
            assert ("travel" not in between) == ends, (stops_from, press_force, between)
            if ends:
                assert between == ["shove", "back_off"]


class Late(Unsure):
    """:class:`Unsure`, but asked at the first touch itself it has no pose yet: that touch's
    contacts reach the tracker an action late, as in the loop."""

    def __init__(self, pose):
        super().__init__(pose)
        self.asked = 0

    def __call__(self):
        self.asked += 1
        return None if self.asked == 1 else self


def test_probe_once_placed_asks_again_after_the_back_off_and_probes_from_the_first_touch():
    """The box of the test above, the belief placing it only from its second asking (the
    first is at the first touch). By default the policy touches beside once more, and the
    belief asked at that second touch starts the probes; with ``probe_once_placed`` it asks
    again after backing off from the first touch and probes from there, one touch sooner."""
    pose = np.array([0.3, 0.17, np.radians(90)])
    for once_placed in (False, True):
        policy = BeliefRummagingPolicy(BOX, FOOTPRINT, MAX_STEP, START,
                                       RummageParams(coverage=BAND_NEAREST, max_actions=80,
                                                     retouch_back=0.0,
                                                     probe_once_placed=once_placed))
        kinds, _, touches = play_kinds(policy, pose, belief=Late(pose))
        probe = kinds.index("probe")
        assert sum(touches[:probe]) == (1 if once_placed else 2)
        if once_placed:  # straight after the back-off from the touch
            assert kinds[probe - 1] == "back_off" and kinds[probe - 2] == "push"


def test_a_heavy_object_met_is_touched_on_its_flank_before_anything_else():
    """The press of the scene above resists (45 N). With ``flank_depth`` 3 cm the lane is not
    shoved: the gripper backs off, goes right of the box (its contact, y 0.145, was left of
    the centre line), forward until its front is 3 cm past the face (x 0.211), and pushes
    left into the box's -y long face (y 0.14: the footprint's left side there at y 0.09).
    It then backs off and probes, the first shove (if any) after the probe round."""
    pose = np.array([0.3, 0.17, np.radians(90)])

    params = RummageParams(coverage=BAND_NEAREST, max_actions=80, press_step=0.02,
                           shove_resisted_from=20.0, flank_depth=0.03)
    policy = BeliefRummagingPolicy(BOX, FOOTPRINT, MAX_STEP, START, params)
    kinds, positions, _ = play_kinds(policy, pose, force=45.0, contact_y=overlap_middle)
    flank = [i for i, kind in enumerate(kinds) if kind == "flank"]
    assert flank and kinds.index("press") < flank[0]
    assert flank[-1] < kinds.index("probe") < (kinds.index("shove") if "shove" in kinds else 99)
    assert kinds[flank[-1] + 1] == "back_off"
    touch = positions[flank[-1] + 1]  # where the last flank action left the gripper
    assert touch == pytest.approx([0.211, 0.09], abs=2e-3)
    # Contacts known an action late, the first touch's at y 0.06 (as if another object's):
    # the flank is planned once backed off, from the press's contact, and goes as above.
    policy = BeliefRummagingPolicy(BOX, FOOTPRINT, MAX_STEP, START, params)
    touched = []

    def first_elsewhere(y):
        touched.append(y)
        return 0.06 if len(touched) == 1 else overlap_middle(y)

    kinds, positions, _ = play_kinds(policy, pose, force=45.0, contact_y=first_elsewhere,
                                     late=True)
    first = kinds.index("flank")  # the flank's first action: forward, right of the lane
    assert positions[first] == pytest.approx([0.161, 0.08], abs=2e-3)
    assert kinds[first:first + 4] == ["flank"] * 3 + ["back_off"]
    assert positions[first + 3] == pytest.approx([0.211, 0.09], abs=2e-3)
    with pytest.raises(ValueError, match="neither is set"):
        RummageParams(flank_depth=0.03)


def test_a_flank_that_meets_the_object_going_forward_goes_further_out():
    """The box unturned (x 0.27..0.33, y 0.021..0.179) meets the whole front of the gripper
    in lane y 0.10, but its contact is reported at y 0.125, as if the box covered only the
    front's left part (edge 0.10): the flank's first forward move (y 0.04) meets its face
    again at 45 N, and so does the next, 3 cm further out. With ``flank_retries`` 3 the
    third retry (y -0.05) passes, and the push back meets the -y end face (y 0.021, the
    footprint's left side at y -0.029), the gripper's front 3 cm past the face (x 0.30), or
    with ``flank_step_ahead`` 1 cm, 3 cm further forward (x 0.33, the box's far corner);
    with 1 retry the policy gives up after it and asks the belief."""
    pose = np.array([0.30, 0.10, 0.0])
    for retries, ahead in ((1, 0.0), (3, 0.0), (3, 0.01)):
        params = RummageParams(coverage=BAND_NEAREST, max_actions=80, press_step=0.02,
                               shove_resisted_from=20.0, flank_depth=0.03,
                               flank_retries=retries, flank_step_ahead=ahead)  # fmt: skip
        policy = BeliefRummagingPolicy(BOX, FOOTPRINT, MAX_STEP, START, params)
        kinds, positions, _ = play_kinds(policy, pose, force=45.0, contact_y=lambda y: 0.125)
        flank = [i for i, kind in enumerate(kinds) if kind == "flank"]
        last = positions[flank[-1] + 1]  # where the last flank action left the gripper
        assert kinds[flank[-1] + 1] == "back_off" and "probe" in kinds[flank[-1]:]
        if retries == 3:
            assert last[1] + 0.05 == pytest.approx(0.021, abs=2e-3)
            assert last[0] + 0.04 == pytest.approx(0.30 + 3 * ahead, abs=2e-3)
        else:  # stopped at the front face (x 0.27) on the second retry's way forward
            assert last[0] + 0.04 == pytest.approx(0.27, abs=2e-3)
            assert last[1] == pytest.approx(0.01, abs=2e-3)


def test_a_shove_along_what_resisted_ends_after_its_touches_then_flanks():
    """The press of the scene above resists (45 N). With ``shove_resisted_for`` 1 the lane is
    shoved at once, as without the flank, but the shove ends at its first action in contact
    (the gripper sliding along the heavy object's face); the gripper backs off there and
    touches the object's flank, then probes. The setting needs ``shove_resisted_from``."""
    pose = np.array([0.3, 0.17, np.radians(90)])

    params = RummageParams(coverage=BAND_NEAREST, max_actions=80, press_step=0.02,
                           shove_resisted_from=20.0, shove_resisted_for=1, flank_depth=0.03)
    policy = BeliefRummagingPolicy(BOX, FOOTPRINT, MAX_STEP, START, params)
    kinds, _, _ = play_kinds(policy, pose, force=45.0, contact_y=overlap_middle)
    shove, flank, probe = kinds.index("shove"), kinds.index("flank"), kinds.index("probe")
    assert kinds.index("press") < shove < flank < probe
    assert kinds[:probe].count("shove") == 1 and kinds[shove + 1] == "back_off"
    with pytest.raises(ValueError, match="shove_resisted_from, which is not set"):
        RummageParams(shove_resisted_for=3)


def test_the_face_the_flank_met_is_touched_again_further_forward():
    """The flank of the test above meets the box's -y long face (y 0.14) with the gripper's
    front at x 0.251, 3 cm past the near end face (x 0.221). With ``flank_again_ahead`` 5 cm
    it backs off, goes 5 cm further forward beside the face and pushes into it again: the
    gripper stops at x 0.261 (front 0.301, 8 cm along the 15.8 cm face), y 0.09 as before.
    Once only, then it probes."""
    pose = np.array([0.3, 0.17, np.radians(90)])
    params = RummageParams(coverage=BAND_NEAREST, max_actions=80, press_step=0.02,
                           shove_resisted_from=20.0, flank_depth=0.03, flank_again_ahead=0.05)
    policy = BeliefRummagingPolicy(BOX, FOOTPRINT, MAX_STEP, START, params)
    kinds, positions, _ = play_kinds(policy, pose, force=45.0, contact_y=overlap_middle)
    flank = [i for i, kind in enumerate(kinds) if kind == "flank"]
    ends = [i for i in flank if kinds[i + 1] == "back_off"]  # each touch's last action
    assert len(ends) == 2 and flank[-1] < kinds.index("probe")
    assert positions[ends[0] + 1] == pytest.approx([0.211, 0.09], abs=2e-3)
    assert positions[ends[1] + 1] == pytest.approx([0.261, 0.09], abs=2e-3)
