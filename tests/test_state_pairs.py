"""The in-contact penetration check over distinct states: exact rounding and exact sums."""

from fractions import Fraction

import numpy as np
import pytest

from stucco_drake.core import BoxSdf, GridSdf, RobotPenetration
from stucco_drake.core.deep_region import axial_slack2, deep_region
from stucco_drake.core.float32_frames import fused_multiply_add_float32, in_frame_float32
from stucco_drake.core.state_pairs import column_states, float_bits, penetrating_entries


def exactly_rounded(a, b, c) -> np.float32:
    """a * b + c in exact rational arithmetic, rounded to the nearest float32 (ties to even)."""
    exact = Fraction(float(a)) * Fraction(float(b)) + Fraction(float(c))
    guess = np.float32(float(exact))
    candidates = [np.nextafter(guess, np.float32(-np.inf)), guess,
                  np.nextafter(guess, np.float32(np.inf))]  # fmt: skip
    error = [abs(Fraction(float(x)) - exact) for x in candidates]
    best = min(error)
    ties = [x for x, e in zip(candidates, error, strict=True) if e == best]
    return min(ties, key=lambda x: int(np.array(x).view(np.uint32)) & 1)  # even mantissa


def midpoint_cases(rng, count):
    """(a, b, c) whose float64 sum lands exactly on a float32 midpoint though the exact sum lies
    just above it: a * b = 2^-24 + d with 0 < d < 2^-53 and c = 1, so rounding the float64 sum
    again (ties to even: down to 1) gives the wrong neighbour."""
    cases = []
    while len(cases) < count:
        m1 = int(rng.integers(1 << 23, 1 << 24))
        m2 = -(-(1 << 47) // m1)  # the smallest m2 with m1 * m2 > 2^47 (or equal)
        excess = m1 * m2 - (1 << 47)  # d = excess * 2^-71
        if excess == 0 or excess >= 1 << 18:
            continue
        cases.append((np.float32(m1 * 2.0**-35), np.float32(m2 * 2.0**-36), np.float32(1.0)))
    return cases


def test_fused_multiply_add_rounds_once_like_the_exact_result():
    rng = np.random.default_rng(0)
    triples = [tuple(np.float32(v) for v in rng.normal(0, 0.1, 3)) for _ in range(3000)]
    triples += [tuple(np.float32(np.round(v * 64) / 64) for v in rng.normal(0, 1, 3))
                for _ in range(500)]  # fmt: skip  # coarse values: exact ties
    hard = midpoint_cases(rng, 50)
    for a, b, c in triples + hard:
        got = fused_multiply_add_float32(np.array([a]), np.array([b]), np.array([c]))[0]
        assert got == exactly_rounded(a, b, c), (a, b, c)
    # The hard cases do defeat rounding twice (float64, then float32), so they test something.
    naive = [np.float32(float(a) * float(b) + float(c)) for a, b, c in hard]
    assert all(n != exactly_rounded(*t) for n, t in zip(naive, hard, strict=True))


def test_frame_coordinates_are_the_chained_fused_products():
    rng = np.random.default_rng(1)
    yaw = 0.3
    rotation_t = np.array([[np.cos(yaw), np.sin(yaw), 0.0], [-np.sin(yaw), np.cos(yaw), 0.0],
                           [0.0, 0.0, 1.0]], dtype=np.float32)  # fmt: skip
    vectors = rng.normal(0, 0.2, (3, 200)).astype(np.float32)
    got = in_frame_float32(rotation_t, vectors)
    for i in range(3):
        for k in range(200):
            acc = np.float32(rotation_t[i, 0] * vectors[0, k])
            acc = exactly_rounded(rotation_t[i, 1], vectors[1, k], acc)
            acc = exactly_rounded(rotation_t[i, 2], vectors[2, k], acc)
            assert got[i, k] == acc
    # Within float32 rounding of the float64 product.
    np.testing.assert_allclose(got, rotation_t.astype(np.float64) @ vectors, atol=1e-7)


def test_column_states_group_exactly_equal_entries():
    rng = np.random.default_rng(2)
    base = rng.normal(size=(3, 1, 40)).astype(np.float32)
    choice = rng.integers(0, 3, (64, 40))
    values = (base + choice[None] * np.float32(1e-7)).astype(np.float32)
    values[:, 5, 7] = -0.0 * values[:, 5, 7]  # a sign-of-zero difference is a different entry
    states = column_states([float_bits(values[a]) for a in range(3)])
    held = values[:, states.holders[states.ids], np.arange(40)[None, :]]
    assert np.array_equal(float_bits(held), float_bits(values))  # each state holds one value
    for column in range(40):  # and distinct entries get distinct states
        distinct = {tuple(float_bits(values[:, i, column])) for i in range(64)}
        assert states.counts[column] == len(distinct)


def shared_belief(rng, n_particles, n, n_slots, tilt=0.0):
    """Particles that are perturbed copies of a few ancestors, with a few orientation slots
    (turned about the vertical; the last also tilted by ``tilt`` rad about x)."""
    ancestors = rng.normal(0, 0.02, (2, 3, 3, n))
    pick = rng.integers(0, 3, n_particles)
    moved = rng.random((n_particles, n)) < 0.15
    shift = rng.normal(0, 0.004, 3)[:, None, None] * moved[None]
    points = (ancestors[0][:, pick] + shift).astype(np.float32)
    configs = (ancestors[1][:, pick] + shift).astype(np.float32)
    slots = rng.integers(0, n_slots, (3, n))[pick]
    slots[rng.random(slots.shape) < 0.05] = 0  # a few particles' own orientation per column
    yaws = np.concatenate([[0.0], rng.uniform(-0.5, 0.5, n_slots - 1)])
    rotations = np.array([[[np.cos(y), -np.sin(y), 0], [np.sin(y), np.cos(y), 0], [0, 0, 1]]
                          for y in yaws])  # fmt: skip
    c, s = np.cos(tilt), np.sin(tilt)
    rotations[-1] = rotations[-1] @ np.array([[1, 0, 0], [0, c, -s], [0, s, c]])
    return points, configs, slots.astype(np.int32), rotations


@pytest.mark.parametrize(("n_slots", "tilt"), [(1, 0.0), (4, 0.0), (4, 0.3), (4, 1e-4)])
def test_state_pair_sums_equal_a_brute_force_pass_and_the_per_orientation_pass(n_slots, tilt):
    """Turned about the vertical, a slot is screened by its layer reach; tilted 0.3 rad, by
    the ball around the deep region; tilted 1e-4 rad, by the layer reach with its slack."""
    grid = GridSdf.build(BoxSdf((0.02, 0.01, 0.015)), [-0.03, -0.02, -0.025], [0.03, 0.02, 0.025],
                         1e-3)  # fmt: skip
    penetration = RobotPenetration(grid)
    rng = np.random.default_rng(3 + n_slots)
    tolerance = 0.002
    points, configs, slots, rotations = shared_belief(rng, 100, 30, n_slots, tilt)
    region = deep_region(grid, tolerance)
    layer_screened, _ = axial_slack2(rotations, region, grid.resolution)
    assert layer_screened[-1] == (tilt < 0.01)  # the case covers the screen it names
    entries = penetrating_entries(grid, tolerance, region, points, configs, slots, rotations,
                                  1 << 20)  # fmt: skip
    assert entries is not None  # shared enough for the state pairs (no per-particle pass)
    per_particle, per_point = penetration.all_pairs_excess_sums(points, configs, slots, rotations,
                                                                tolerance)  # fmt: skip
    expected = np.zeros(per_point.shape)
    for i in range(points.shape[1]):  # every config, in its own orientation, vs every point
        for j in range(points.shape[2]):
            depth = penetration(configs[:, i, j], points[:, i, :].T, rotations[slots[i, j]])
            expected[i] += np.maximum(depth - tolerance, 0.0)
    assert (expected > 0).sum() > 100  # plenty of penetrating pairs
    np.testing.assert_allclose(per_point, expected, atol=1e-5)
    np.testing.assert_allclose(per_particle, expected.sum(axis=1), atol=1e-4)
    # Bit for bit the per-orientation pass's sums (same pairs, same order of additions).
    slow_particle, slow_point = penetration._per_orientation_sums(points, configs, slots,
                                                                  rotations, tolerance)  # fmt: skip
    assert np.array_equal(per_particle, slow_particle)
    assert np.array_equal(per_point, slow_point)
