"""GridSdf against analytic distances, its cache, and the parameter loader."""

import numpy as np
import pytest

from stucco_drake.core import BoxSdf, CylinderSdf, GridSdf, RobotPenetration, SoftTrackingParams

RESOLUTION = 0.004


@pytest.fixture(scope="module")
def box_and_grid():
    box = BoxSdf((0.03, 0.02, 0.05), (0.01, 0.0, 0.0))
    return box, GridSdf.build(box, [-0.05, -0.05, -0.08], [0.07, 0.05, 0.08], RESOLUTION)


def test_grid_matches_analytic_sdf_within_half_a_cell(box_and_grid):
    box, grid = box_and_grid
    rng = np.random.default_rng(0)
    points = rng.uniform(grid.lower, grid.upper, (20000, 3))
    error = np.abs(grid(points) - box(points))
    print(f"\nmax |grid - analytic| = {error.max() * 1e3:.3f} mm (half cell {RESOLUTION * 500} mm)")
    assert error.max() <= RESOLUTION / 2


def test_grid_treats_points_outside_as_far_away(box_and_grid):
    _, grid = box_and_grid
    assert np.all(np.isinf(grid(np.array([[1.0, 0.0, 0.0], [0.0, -0.2, 0.0]]))))


def test_grid_gradient_points_away_from_the_surface():
    cylinder = CylinderSdf(0.02, 0.05)
    grid = GridSdf.build(cylinder, [-0.04, -0.04, -0.07], [0.04, 0.04, 0.07], 0.002)
    points = np.array([[0.03, 0.0, 0.0], [0.0, -0.025, 0.01], [0.0, 0.0, 0.06]])
    expected = np.array([[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, 1.0]])
    np.testing.assert_allclose(grid.gradient(points), expected, atol=0.05)


def test_grid_cache_round_trip_is_keyed_by_content(tmp_path):
    cylinder = CylinderSdf(0.02, 0.05)
    args = ([-0.03, -0.03, -0.06], [0.03, 0.03, 0.06], 0.005)
    calls = []

    def counted(points):
        calls.append(len(points))
        return cylinder(points)

    first = GridSdf.load_or_build(counted, *args, source_description="disc v1", cache_dir=tmp_path)
    again = GridSdf.load_or_build(counted, *args, source_description="disc v1", cache_dir=tmp_path)
    other = GridSdf.load_or_build(counted, *args, source_description="disc v2", cache_dir=tmp_path)
    assert len(calls) == 2  # the second load came from disk
    np.testing.assert_array_equal(first.values, again.values)
    assert first.key == again.key != other.key
    assert len(list(tmp_path.glob("*.npz"))) == 2


def test_penetration_is_depth_inside_the_robot_at_each_config():
    grid = GridSdf.build(CylinderSdf(0.02, 0.05), [-0.03, -0.03, -0.06], [0.03, 0.03, 0.06], 0.001)
    penetration = RobotPenetration(grid)
    configs = np.array([[0.0, 0.0, 0.0], [0.1, 0.0, 0.0]])
    points = np.array([[0.005, 0.0, 0.0], [0.1, 0.015, 0.0], [0.5, 0.0, 0.0]])
    depth = penetration(configs[:, None, :], points[None, :, :])
    assert depth.shape == (2, 3)
    np.testing.assert_allclose(depth[0, 0], 0.015, atol=5e-4)  # 1.5 cm deep
    np.testing.assert_allclose(depth[1, 1], 0.005, atol=5e-4)
    assert depth[0, 2] == 0.0 and depth[0, 1] == 0.0  # outside the grid / outside the disc


def test_params_presets_and_yaml(tmp_path):
    sim, real = SoftTrackingParams.sim(), SoftTrackingParams.real()
    assert (sim.length, sim.penetration_length, sim.n_particles) == (0.02, 0.002, 100)
    assert (real.length, real.intersection_tolerance) == (0.006, 0.010)
    assert sim.segmentation_radius == pytest.approx(0.1354, abs=1e-4)
    path = tmp_path / "tracker.yaml"
    path.write_text("preset: real\nn_particles: 50\n")
    loaded = SoftTrackingParams.from_yaml(path)
    assert (loaded.length, loaded.n_particles) == (0.006, 50)


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("lenght: 0.02\n", "unknown key.*lenght"),
        ("preset: lab\n", "unknown preset"),
        ("length: -1\n", "length"),
        ("[1, 2]\n", "expected a mapping"),
        ("length: [0.1\n", "not valid YAML"),
    ],
)
def test_params_reject_bad_yaml_with_one_line_naming_it(tmp_path, text, message):
    path = tmp_path / "bad.yaml"
    path.write_text(text)
    with pytest.raises(ValueError, match=message) as info:
        SoftTrackingParams.from_yaml(path)
    assert "bad.yaml" in str(info.value)
    assert "\n" not in str(info.value)


def test_cell_coordinate_lookup_matches_point_lookup(box_and_grid):
    _, grid = box_and_grid
    rng = np.random.default_rng(3)
    points = rng.uniform(grid.lower - 0.01, grid.upper + 0.01, (5000, 3))
    cells = ((points - grid.lower) / grid.resolution).astype(np.float32).T
    fast, reference = grid.at_cell_coordinates(*cells), grid(points)
    np.testing.assert_array_equal(np.isinf(fast), np.isinf(reference))
    finite = np.isfinite(reference)
    np.testing.assert_allclose(fast[finite], reference[finite], atol=1e-6)  # float32 rounding


@pytest.mark.parametrize("spread", [0.0, 0.002, 0.03])
def test_deduplicated_penetration_sums_equal_the_per_particle_path(spread):
    """Particles sharing most contacts (spread 0), a few variants, and all distinct."""
    grid = GridSdf.build(CylinderSdf(0.02, 0.05), [-0.03, -0.03, -0.06], [0.03, 0.03, 0.06], 0.001)
    rng = np.random.default_rng(11)
    n_particles, n = 60, 40
    base_points = rng.uniform(-0.1, 0.1, (3, 1, n)).astype(np.float32)
    base_configs = rng.uniform(-0.1, 0.1, (3, 1, n)).astype(np.float32)
    variants = rng.integers(0, 3, (n_particles, n))  # three candidate values per contact
    shifts = rng.uniform(-spread, spread, (3, 3, 1, n)).astype(np.float32)
    points = base_points + np.take_along_axis(shifts, variants[None, None], axis=1)[:, 0]
    configs = base_configs + np.take_along_axis(shifts[::-1], variants[None, None], axis=1)[:, 0]
    if spread == 0.03:
        points = points + rng.uniform(-0.01, 0.01, points.shape).astype(np.float32)
    fast = RobotPenetration(grid).excess_sums(points, configs, 0.002)
    slow = RobotPenetration(grid, deduplicate=False).excess_sums(points, configs, 0.002)
    assert slow[0].max() > 0.0  # the case has penetrating pairs
    np.testing.assert_allclose(fast[0], slow[0], rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(fast[1], slow[1], rtol=1e-9, atol=1e-12)


def test_pxpen_refuses_a_grid_that_cuts_the_robot():
    """Beyond its grid a point counts as outside the robot: exact only if the grid encloses
    the robot. A 2 cm-radius cylinder on a grid reaching only 1.5 cm from its axis is refused."""
    cylinder = CylinderSdf(0.02, 0.05)
    cut = GridSdf.build(cylinder, [-0.015, -0.015, -0.06], [0.015, 0.015, 0.06], 0.002)
    with pytest.raises(ValueError, match="does not enclose the robot") as info:
        RobotPenetration(cut)
    assert "\n" not in str(info.value)
    enclosing = GridSdf.build(cylinder, [-0.03, -0.03, -0.06], [0.03, 0.03, 0.06], 0.002)
    pxpen = RobotPenetration(enclosing)
    # A point 4 cm from the axis, beyond the grid: the cylinder's own distance says outside.
    beyond = np.array([[0.04, 0.0, 0.0]])
    assert cylinder(beyond)[0] > 0
    assert pxpen(np.zeros(3), beyond)[0] == 0.0
    # Inside: the grid's depth matches the cylinder's (1 cm deep at 1 cm from the axis).
    np.testing.assert_allclose(pxpen(np.zeros(3), [[0.01, 0.0, 0.0]]), [0.01], atol=1e-3)
