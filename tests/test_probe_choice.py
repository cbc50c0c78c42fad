"""Choosing the probe the pose hypotheses disagree on (core/probe_choice.py), against geometry
done by hand: where a square footprint first meets a box on a straight approach, the entropy of
outcomes of known weights, the candidate touches along a face, and a policy that, of two rival
poses, probes where they differ."""

import dataclasses

import numpy as np
import pytest

from stucco_drake.core.hypothesis_weights import distinct_rivals
from stucco_drake.core.probe_choice import (
    BUMP,
    face_probe_points,
    footprint_meets,
    footprint_outline,
    outcome_entropy,
    probe_outcomes,
)
from stucco_drake.core.probe_params import ProbeParams
from stucco_drake.core.probing import FaceProbePolicy
from stucco_drake.core.shapes import BoxSdf

# A box 6 cm by 15.8 cm in plan (m), and a square gripper footprint 8 cm on a side.
BOX = BoxSdf(half_extents=(0.03, 0.079, 0.105))
FOOTPRINT = np.array([[sx * 0.04, sy * 0.04] for sx in (-1, 1) for sy in (-1, 1)])


def test_the_footprint_meets_the_box_exactly_when_their_rectangles_overlap():
    """Box at the origin, unturned: x in [-0.03, 0.03]. The footprint centred at x spans
    [x - 0.04, x + 0.04]: it meets the box for x < 0.07 (1 mm either side of that, by hand),
    and a footprint that swallows a corner of a turned box meets it too."""
    outline, planes = footprint_outline(FOOTPRINT, spacing=0.002)
    pose = np.array([[0.0, 0.0, 0.0]])
    meets = footprint_meets([[0.069, 0.0], [0.071, 0.0], [0.0, 0.118], [0.0, 0.12]], outline,
                            planes, pose, BOX)  # fmt: skip
    assert meets.tolist() == [[True, False, True, False]]
    # Small box entirely inside the footprint: no footprint boundary point is inside it, but
    # its outline is inside the footprint.
    small = BoxSdf(half_extents=(0.01, 0.01, 0.01))
    assert footprint_meets([[0.0, 0.0]], outline, planes, [[0.005, 0.0, 0.3]], small)[0, 0]


def test_each_hypothesis_predicts_where_the_approach_first_touches_it():
    """The footprint approaches along +x from x = -0.2 (normal (-1, 0)), 0.3 m of travel.
    A box at x = 0 is met when the footprint's leading edge reaches x = -0.03: after
    0.2 - 0.04 - 0.03 = 0.13 m (the first 2.5 mm sample past touching); a box 0.2 m to the
    side is never met; one on the travel path is bumped."""
    outline, planes = footprint_outline(FOOTPRINT)
    poses = np.array([[0.0, 0.0, 0.0], [0.0, 0.2, 0.0], [-0.3, -0.2, 0.0]])
    path = np.column_stack([np.full(20, -0.3), np.linspace(-0.4, 0.0, 20)])
    outcomes = probe_outcomes(path, np.array([-0.2, 0.0]), np.array([-1.0, 0.0]), 0.3, poses,
                              BOX, outline, planes)  # fmt: skip
    assert 0.13 < outcomes[0] <= 0.13 + 0.0025 + 1e-9
    assert outcomes[1] == np.inf
    assert outcomes[2] == BUMP


def test_what_was_felt_is_met_whatever_the_hypothesis():
    """The approach of the test above with a point felt at (-0.1, 0): the footprint's leading
    edge (x + 0.04) holds it 5 mm deep from x = -0.135, 0.065 m into the approach, so every
    hypothesis's outcome is that (the box at the origin, met at 0.13, included). A point felt
    on the travel path bumps under every hypothesis; one 1 cm beside the footprint's path
    changes nothing."""
    outline, planes = footprint_outline(FOOTPRINT)
    poses = np.array([[0.0, 0.0, 0.0], [0.0, 0.2, 0.0], [-0.3, -0.2, 0.0]])
    path = np.column_stack([np.full(20, -0.3), np.linspace(-0.4, 0.0, 20)])
    args = (np.array([-0.2, 0.0]), np.array([-1.0, 0.0]), 0.3, poses, BOX, outline, planes)
    ahead = probe_outcomes(path, *args, felt=np.array([[-0.1, 0.0]]))
    np.testing.assert_allclose(ahead[:2], 0.065, atol=0.0025 + 1e-9)
    assert ahead[2] == BUMP
    assert np.all(probe_outcomes(path, *args, felt=np.array([[-0.3, -0.1]])) == BUMP)
    beside = probe_outcomes(path, *args, felt=np.array([[-0.1, 0.05]]))
    np.testing.assert_array_equal(beside, probe_outcomes(path, *args))


def test_outcome_entropy_counts_outcomes_within_the_tolerance_as_one():
    half = np.array([0.5, 0.5])
    assert outcome_entropy([0.01, 0.05], half, 0.015) == pytest.approx(np.log(2))
    assert outcome_entropy([0.01, 0.02], half, 0.015) == pytest.approx(0.0)
    assert outcome_entropy([np.inf, np.inf], half, 0.015) == pytest.approx(0.0)
    assert outcome_entropy([BUMP, np.inf], half, 0.015) == pytest.approx(np.log(2))
    # Three groups of weights 0.25, 0.25, 0.5: -(2 * 0.25 ln 0.25 + 0.5 ln 0.5) = 1.5 ln 2.
    weights = np.array([0.25, 0.25, 0.25, 0.25])
    assert outcome_entropy([BUMP, 0.03, np.inf, np.inf], weights, 0.015) == pytest.approx(
        1.5 * np.log(2))  # fmt: skip


def test_rivals_skip_variants_of_a_pose_taken_already():
    poses = np.array([[0.0, 0.0, 0.0], [0.005, 0.0, np.pi], [0.1, 0.0, 0.0], [0.0, 0.0, 1.0]])
    costs = np.array([0.0, 1.0, 2.0, 3.0])
    # The second is the first turned by a half turn, 5 mm away: the same box.
    assert distinct_rivals(poses, costs, 6).tolist() == [0, 2, 3]
    assert distinct_rivals(poses, costs, 2).tolist() == [0, 2]


@dataclasses.dataclass
class Hypotheses:
    poses: np.ndarray
    costs: np.ndarray
    pose: np.ndarray
    felt: np.ndarray | None = None


def planned_outcomes(policy, poses, path=None, felt=None) -> np.ndarray:
    """Each of ``poses``'s outcome of the probe ``policy`` has just planned: its approach from
    the travel's last waypoint, as far as the policy goes past the face (``path``, the travel
    to check for bumps: None for none)."""
    probe, far = policy._probe, policy._waypoints[-1]
    support = float(np.max(FOOTPRINT @ -probe.normal))
    travel = float((far - probe.point) @ probe.normal) - support + policy.params.overshoot
    outline, planes = footprint_outline(FOOTPRINT)
    return probe_outcomes(np.zeros((0, 2)) if path is None else path, far, probe.normal,
                          travel, poses, BOX, outline, planes, felt=felt)  # fmt: skip


def test_of_two_rival_poses_the_policy_probes_where_they_differ():
    """The likelier pose (cost 0) has the box's long axis along x (x in [0.121, 0.279], y in
    [-0.03, 0.03]), its rival (cost 2) along y (x in [0.14, 0.2], y in [-0.03, 0.128]): their
    lower faces are in line. The gripper is below both. Without discrimination the first
    probe is the likelier pose's lower face at x = 0.1605, where the rival is met at the same
    distance: it tells nothing. With it, the first probe's outcomes differ under the two (one
    met, the other not, or met 1.5 cm or more apart)."""
    likely = np.array([0.2, 0.0, np.pi / 2])
    rival = np.array([0.17, 0.049, 0.0])
    hypotheses = Hypotheses(np.array([likely, rival]), np.array([0.0, 2.0]), likely)
    start = np.array([0.2, -0.3])
    for discriminate in (False, True):
        params = ProbeParams(discriminate=discriminate, direct_only=False)
        policy = FaceProbePolicy(BOX, FOOTPRINT, max_step=0.03, params=params)
        assert policy.next_step(start, False, hypotheses) is not None
        outcomes = planned_outcomes(policy, hypotheses.poses)
        differ = (np.isfinite(outcomes).sum() == 1
                  or abs(outcomes[0] - outcomes[1]) >= params.outcome_tolerance)
        assert differ == discriminate, (discriminate, outcomes)


def test_candidate_touches_run_along_each_face_while_the_footprint_overlaps_it():
    """The box unturned at (0.3, 0.1): its +x face at x = 0.33 spans y in [0.021, 0.179]
    (half length 0.079). The footprint reaches 0.04 either way along y, so the gripper's
    origin may go 0.079 + 0.04 - 0.01 = 0.109 either side of the face's middle: every 2 cm
    from -0.10 to 0.10, 11 touches. The +y face (half length 0.03 along x) gets every 2 cm
    within 0.03 + 0.04 - 0.01 = 0.06 (exclusive): -0.04 to 0.04, 5 touches. Turned by a
    quarter turn, the same touches turn with the box."""
    points, normals = face_probe_points([0.3, 0.1], np.array([0.03, 0.079]), 0.0, FOOTPRINT,
                                        0.02)  # fmt: skip
    plus_x = np.all(np.isclose(normals, [1.0, 0.0]), axis=1)
    plus_y = np.all(np.isclose(normals, [0.0, 1.0]), axis=1)
    assert len(points) == 2 * 11 + 2 * 5
    np.testing.assert_allclose(points[plus_x, 0], 0.33)
    np.testing.assert_allclose(np.sort(points[plus_x, 1]), 0.1 + np.linspace(-0.1, 0.1, 11),
                               atol=1e-12)  # fmt: skip
    np.testing.assert_allclose(points[plus_y, 1], 0.179)
    np.testing.assert_allclose(np.sort(points[plus_y, 0]), 0.3 + np.linspace(-0.04, 0.04, 5),
                               atol=1e-12)  # fmt: skip
    turned_points, turned_normals = face_probe_points([0.0, 0.0], np.array([0.03, 0.079]),
                                                      np.pi / 2, FOOTPRINT, 0.02)  # fmt: skip
    # The box's +x face now faces +y, at y = 0.03, its touches along x.
    faces_y = np.all(np.isclose(turned_normals, [0.0, 1.0]), axis=1)
    np.testing.assert_allclose(turned_points[faces_y, 1], 0.03)
    assert np.count_nonzero(faces_y) == 11


def test_touches_along_the_face_tell_an_end_on_box_from_a_turned_one():
    """The end-on box (long axis along x: x in [0.121, 0.279], y in [-0.03, 0.03]) and the
    same box turned (x in [0.121, 0.181], y in [-0.079, 0.079]) share the face in front of the
    gripper, and are equally likely. The probes made of each pose's faces meet both at that
    face (the same outcome); among the touches every 2 cm along the faces there is one beside
    the end face, where only the turned box stands (one met, the other not)."""
    end_on = np.array([0.2, 0.0, np.pi / 2])
    turned = np.array([0.151, 0.0, 0.0])
    hypotheses = Hypotheses(np.array([end_on, turned]), np.array([0.0, 0.0]), end_on)
    for face_step in (None, 0.02):
        params = ProbeParams(face_step=face_step)
        policy = FaceProbePolicy(BOX, FOOTPRINT, max_step=0.03, params=params)
        assert policy.next_step(np.zeros(2), False, hypotheses) is not None
        outcomes = planned_outcomes(policy, hypotheses.poses)
        met = np.isfinite(outcomes)
        if face_step is None:
            assert met.all() and abs(outcomes[0] - outcomes[1]) < params.outcome_tolerance
        else:
            assert met.tolist() == [False, True], outcomes


def test_a_probe_whose_outcome_was_felt_already_is_not_chosen():
    """The end-on and turned boxes of the test above. Something was felt where the touch
    beside the end face meets the turned box: the gripper meets it there whatever the box's
    pose, so that touch tells nothing. Counting what was felt, the policy probes elsewhere,
    where the two poses' outcomes still differ with the felt point standing where it is."""
    end_on = np.array([0.2, 0.0, np.pi / 2])
    turned = np.array([0.151, 0.0, 0.0])

    def first_probe(felt_obstacles, felt):
        hypotheses = Hypotheses(np.array([end_on, turned]), np.zeros(2), end_on, felt)
        params = ProbeParams(face_step=0.02, felt_obstacles=felt_obstacles)
        policy = FaceProbePolicy(BOX, FOOTPRINT, max_step=0.03, params=params)
        assert policy.next_step(np.zeros(2), False, hypotheses) is not None
        path = np.array([np.zeros(2), *policy._waypoints])
        return policy._probe, planned_outcomes(policy, hypotheses.poses, path, felt)

    plain, _ = first_probe(False, None)
    # Where the touch made without anything felt first meets the turned box: the turned
    # box's face point it was planned on (the face's outward normal points at the gripper).
    felt = np.array([plain.point])
    _, known = first_probe(False, felt)
    assert abs(known[0] - known[1]) < 0.015 or np.all(known == BUMP), known
    probe, outcomes = first_probe(True, felt)
    assert np.linalg.norm(probe.point - plain.point) > 0.01
    met = np.isfinite(outcomes) & (outcomes != BUMP)
    assert met.sum() == 1 or abs(outcomes[0] - outcomes[1]) >= 0.015, outcomes


def test_by_gain_per_action_a_near_touch_that_splits_fewer_poses_wins_over_a_far_one():
    """Three equally likely poses: the end-on box, the same box turned (the two of the tests
    above) and the end-on box 5 cm along +y. From (0, 0.05) the probe of most gain travels 10
    steps of 2 cm to touch the end-on boxes' -y sides and the turned box's long face from
    below: three different outcomes, ln 3 nats. Counting what each probe costs, the touch
    one step away in front, beside the first end-on box, wins: it meets the turned and the
    shifted box at the same distance and passes the first, ln 3 - (2/3) ln 2 = 0.64 nats
    for 1 travel step."""
    from stucco_drake.core.coverage import waypoint_steps

    poses = np.array([[0.2, 0.0, np.pi / 2], [0.151, 0.0, 0.0], [0.2, 0.05, np.pi / 2]])
    hypotheses = Hypotheses(poses, np.zeros(3), poses[0])
    start = np.array([0.0, 0.05])
    chosen = {}
    for per_action in (False, True):
        params = ProbeParams(face_step=0.02, direct_only=False, gain_per_action=per_action)
        policy = FaceProbePolicy(BOX, FOOTPRINT, max_step=0.03, params=params)
        assert policy.next_step(start, False, hypotheses) is not None
        steps = len(waypoint_steps(start, policy._waypoints, params.travel_step))
        chosen[per_action] = steps, planned_outcomes(policy, poses)
    steps, outcomes = chosen[False]
    assert steps == 10 and len(np.unique(np.round(outcomes, 3))) == 3, chosen
    steps, outcomes = chosen[True]
    assert steps == 1 and np.isinf(outcomes[0]), chosen
    assert outcomes[1] == pytest.approx(outcomes[2], abs=1e-9)
