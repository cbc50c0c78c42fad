"""SoftTracker on synthetic planar pushes: the paper's key case, ReplaceBad, likelihood, seeds."""

import numpy as np
import pytest

from stucco_drake.core import SoftTracker, SoftTrackingParams, contact_error, fowlkes_mallows
from stucco_drake.core.clustering_tracker import ClusteringTracker, single_linkage
from stucco_drake.core.synthetic import separation_scenario


def run_separation(tracker, seed):
    """Feed the key-case scenario to ``tracker``; return (CE in m, FMI)."""
    world, actions = separation_scenario()
    rng = np.random.default_rng(seed)
    truth = []
    for obs in actions:
        tracker.update(rng, obs.ee_position, obs.contact_points, obs.contact_dx)
        truth.extend(obs.contact_objects)
    assert len(truth) == 16  # eight nudges of each box, one contact each
    error = contact_error(tracker.map_points(), world.object_surfaces())
    return error, fowlkes_mallows(truth, tracker.segment())


def test_key_case_soft_tracking_beats_hard_clustering(disc_penetration):
    """Two boxes touched 4.5 cm apart, then separated: STUCCO revises, hard clustering cannot."""
    seeds = range(8)
    soft = [run_separation(SoftTracker(disc_penetration), seed) for seed in seeds]
    radius = SoftTrackingParams.sim().segmentation_radius
    hard_ce, hard_fmi = run_separation(ClusteringTracker(single_linkage(radius)), 0)
    soft_ce = np.array([ce for ce, _ in soft])
    soft_fmi = np.array([fmi for _, fmi in soft])
    print(f"\nSTUCCO   CE mm {np.round(soft_ce * 1e3, 2)}  FMI {np.round(soft_fmi, 3)}")
    print(f"hard-SL  CE mm {hard_ce * 1e3:.2f}  FMI {hard_fmi:.3f}")
    # Every seed tracks the points onto the true surfaces (within 5 mm); the segmentation is
    # right on average and on at least 7 of 8 seeds (a seed may merge one early point).
    assert soft_ce.max() <= 0.005
    assert soft_fmi.mean() >= 0.9
    assert np.sum(soft_fmi >= 0.9) >= 7
    # The single estimate never revises: its points sit centimetres off the surfaces.
    assert hard_ce >= 0.02
    assert hard_ce >= 4 * soft_ce.max()
    assert hard_fmi < soft_fmi.mean()


def test_same_seed_gives_bit_identical_particles(disc_penetration):
    def particles(seed):
        tracker = SoftTracker(disc_penetration)
        run_separation(tracker, seed)
        return tracker.points, tracker.configs, tracker.log_weights

    first, again, other = particles(3), particles(3), particles(4)
    for a, b in zip(first, again, strict=True):
        assert np.array_equal(a, b)
    assert not np.array_equal(first[0], other[0])


def test_replace_bad_moves_a_penetrating_point_to_its_nearest_consistent_neighbour(
    disc_penetration,
):
    params = SoftTrackingParams(n_particles=4)
    tracker = SoftTracker(disc_penetration, params)
    rng = np.random.default_rng(0)
    # Three contacts made from a disc at the origin's left: points well apart along y.
    for y in (0.0, 0.05, 0.30):
        tracker.update(rng, [-0.05, y, 0.0], [[-0.03, y, 0.0]], [[0.0, 0.0, 0.0]])
    before = tracker.points
    # The disc now sits where the middle point is: that point is inconsistent in every particle.
    tracker.update(rng, [-0.03, 0.05, 0.0])
    after = tracker.points
    assert tracker.n_contacts == 3
    # The bad point (index 1) became a copy of its nearest good point (index 0, 5 cm away, not
    # index 2 at 25 cm), config included; the others are untouched.
    np.testing.assert_array_equal(after[:, 1], before[:, 0])
    np.testing.assert_array_equal(tracker.configs[:, 1], tracker.configs[:, 0])
    np.testing.assert_array_equal(after[:, [0, 2]], before[:, [0, 2]])


def test_replace_bad_off_leaves_the_penetrating_point_and_only_weighs_it(disc_penetration):
    params = SoftTrackingParams(n_particles=2, resample_ess_fraction=0.01, replace_bad=False)
    tracker = SoftTracker(disc_penetration, params)
    rng = np.random.default_rng(0)
    for y in (0.0, 0.05):
        tracker.update(rng, [-0.05, y, 0.0], [[-0.03, y, 0.0]], [[0.0, 0.0, 0.0]])
    tracker._points[0, 1, 1] += 0.04  # particle 1 believes the second point moved 4 cm along +x
    before = tracker.points
    # The disc (radius 2 cm) now covers x in [-0.01, 0.03] at y = 0.05: particle 1's second
    # point (x = 0.01) lies 2 cm inside it, particle 0's (x = -0.03) on its surface.
    tracker.update(rng, [0.01, 0.05, 0.0])
    np.testing.assert_array_equal(tracker.points, before)  # nothing copied
    weights = np.exp(tracker.log_weights)
    np.testing.assert_allclose(weights[1] / weights[0], np.exp(-(0.018**2) / 0.002), rtol=0.02)


def test_replace_bad_must_be_a_bool():
    with pytest.raises(ValueError, match="replace_bad"):
        SoftTrackingParams(replace_bad="no")


def test_out_of_contact_step_lowers_weight_of_particles_the_robot_passes_through(
    disc_penetration,
):
    params = SoftTrackingParams(n_particles=2, resample_ess_fraction=0.01)
    tracker = SoftTracker(disc_penetration, params)
    rng = np.random.default_rng(0)
    tracker.update(rng, [-0.05, 0.0, 0.0], [[-0.03, 0.0, 0.0]], [[0.0, 0.0, 0.0]])
    # Make the two particles disagree: particle 1 believes the point moved 4 cm along +x.
    tracker._points[0, 1, 0] += 0.04
    tracker.update(rng, [0.01, 0.0, 0.0])  # the disc now covers x in [-0.01, 0.03]
    weights = np.exp(tracker.log_weights)
    # Particle 1's point is 2 cm deep (1.8 cm beyond tolerance): w1/w0 = exp(-0.018^2/0.002).
    np.testing.assert_allclose(weights[1] / weights[0], np.exp(-(0.018**2) / 0.002), rtol=0.02)
    assert tracker.map_index == 0


def test_no_contacts_yet_gives_empty_segmentation(disc_penetration):
    tracker = SoftTracker(disc_penetration)
    tracker.update(np.random.default_rng(0), [0.0, 0.0, 0.0])
    assert tracker.n_contacts == 0
    assert tracker.segment().shape == (0,)
    assert tracker.map_points().shape == (0, 3)


@pytest.mark.parametrize(
    ("kwargs", "name"),
    [
        ({"ee_position": [0.0, np.nan, 0.0]}, "ee_position"),
        ({"ee_position": [0.0, 0.0]}, "ee_position"),
        (
            {"contact_points": [[0.0, 0.0, np.inf]], "contact_dx": [[0.0, 0.0, 0.0]]},
            "contact_points",
        ),
        ({"contact_points": [[0.0, 0.0]], "contact_dx": [[0.0, 0.0, 0.0]]}, "contact_points"),
        ({"contact_points": [[0.0, 0.0, 0.0]], "contact_dx": [[0.0, np.nan, 0.0]]}, "contact_dx"),
        ({"contact_points": [[0.0, 0.0, 0.0]], "contact_dx": np.zeros((2, 3))}, "contact_dx"),
        ({"ee_rotation": np.diag([1.0, 1.0, -1.0])}, "ee_rotation"),
    ],
)
def test_bad_input_raises_value_error_naming_the_argument(disc_penetration, kwargs, name):
    tracker = SoftTracker(disc_penetration)
    arguments = {"ee_position": [0.0, 0.0, 0.0], **kwargs}
    with pytest.raises(ValueError, match=name):
        tracker.update(np.random.default_rng(0), **arguments)
    assert tracker.n_contacts == 0  # nothing half-applied


def test_several_contacts_in_one_step_each_follow_their_own_displacement(disc_penetration):
    params = SoftTrackingParams(n_particles=50)
    tracker = SoftTracker(disc_penetration, params)
    rng = np.random.default_rng(1)
    points = [[0.5, 0.0, 0.0], [-0.5, 0.0, 0.0]]
    dx = [[0.01, 0.0, 0.0], [0.0, -0.02, 0.0]]
    tracker.update(rng, [0.0, 0.0, 0.0], points, dx)
    np.testing.assert_allclose(tracker.points, np.broadcast_to(points, (50, 2, 3)), atol=1e-6)
    # Configs are the pre-motion EE positions moved by each contact's dx: they end on x_t.
    np.testing.assert_allclose(tracker.configs, 0.0, atol=1e-6)


def test_penetration_sums_over_many_orientations_equal_the_pairwise_depths():
    """A closed-loop run senses nearly every contact at its own end-effector orientation: the
    tracker's sums (one pass per orientation, only its configs) must equal pxpen summed pair by
    pair with each config's own rotation (float32 grid lookups: within 1e-5 m)."""
    from stucco_drake.core import BoxSdf, GridSdf, RobotPenetration

    def rotation_about_z(yaw):
        c, s = np.cos(yaw), np.sin(yaw)
        return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])

    grid = GridSdf.build(BoxSdf((0.03, 0.01, 0.02)), [-0.04, -0.02, -0.03], [0.04, 0.02, 0.03],
                         1e-3)  # fmt: skip
    penetration = RobotPenetration(grid)
    tracker = SoftTracker(penetration, SoftTrackingParams(n_particles=6))
    rng = np.random.default_rng(5)
    yaws = [0.0, 0.3, 0.3, 1.1, -0.7, 2.0, 0.3, 1.1]  # repeats share a slot
    for k, yaw in enumerate(yaws):
        ee = np.array([0.01 * k, 0.0, 0.0])
        tracker.update(rng, ee, [ee + np.array([0.0, 0.011, 0.0])], [[0.004, 0.0, 0.0]],
                       ee_rotation=rotation_about_z(yaw))  # fmt: skip
    assert len(tracker._rotations) == 5
    # Scatter the particles' points so that many (config, point) pairs penetrate, and give
    # each particle's pairs orientations of their own (as ReplaceBad's copies do), so a
    # column holds several orientations across particles.
    n = tracker.n_contacts
    tracker._points[:, :, :n] += rng.uniform(-0.015, 0.015, (3, 6, n)).astype(np.float32)
    tracker._rotation_index[:, :n] = rng.integers(0, 5, (6, n))
    per_particle, per_point = tracker._penetration_all_pairs()

    points, configs = tracker.points, tracker.configs
    rotations = tracker._rotations[tracker._rotation_index[:, :n]]
    tolerance = tracker.params.intersection_tolerance
    expected = np.zeros((6, n))
    for j in range(n):  # every config, with its own orientation, against every point
        for i in range(6):
            depth = penetration(configs[i, j], points[i], rotations[i, j])
            expected[i] += np.maximum(depth - tolerance, 0.0)
    assert expected.sum(axis=1).min() > 0.01  # every particle has penetrating pairs
    np.testing.assert_allclose(per_point, expected, atol=1e-5)
    np.testing.assert_allclose(per_particle, expected.sum(axis=1), atol=1e-4)
