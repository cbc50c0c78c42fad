"""STUCCO's touched-side rule: a push moves only points that can lie on the object it touched."""

import argparse
import dataclasses

import numpy as np
import pytest

from stucco_drake.core import BoxSdf, SoftTracker, SoftTrackingParams
from stucco_drake.core.contact_motion import normal_spread
from stucco_drake.core.inputs import InputError
from stucco_drake.core.penetration import RobotPenetration
from stucco_drake.core.sdf import GridSdf
from stucco_drake.eval.cli_table import add_table_command

A = [0.10, 0.0, 0.0]  # on one object, touched first by the robot's +x face
D = [0.21, 0.09, 0.0]  # on a second object, touched next


@pytest.fixture(scope="module")
def box_penetration() -> RobotPenetration:
    """A 4 x 2 x 2 cm box end effector in its frame E, as a 1 mm grid: flat faces, sharp edges."""
    grid = GridSdf.build(
        BoxSdf((0.02, 0.01, 0.01)), [-0.03, -0.02, -0.02], [0.03, 0.02, 0.02], 1e-3
    )
    return RobotPenetration(grid)


def test_normal_spread_is_zero_on_a_face_and_one_across_an_edge(box_penetration):
    points = np.array([
        [0.02, 0.0, 0.0],  # middle of the +x face: every normal within 3 mm is +x
        [0.02, 0.009, 0.0],  # 1 mm from the +x/+y edge: 3 mm away the normal is +y
        [0.5, 0.0, 0.0],  # off the grid: nothing known
    ])  # fmt: skip
    spread = normal_spread(box_penetration.robot_sdf, points, np.zeros(3), radius=0.003)
    assert spread[0] <= 1e-6
    assert spread[1] >= 0.99
    assert spread[2] == 0.0


def push_second_object(penetration, margin, edge_offset=0.0, seed=0, softness=0.0):
    """A and D are sensed; then the robot's +x face pushes D's object 1 cm along +x, at
    ``edge_offset`` (m) from the face's middle towards its +y edge (1 cm away). A lies 10 cm
    behind that contact's tangent plane, D 1 cm in front of it."""
    params = dataclasses.replace(SoftTrackingParams.sim(), touched_side_margin=margin,
                                 touched_side_softness=softness)  # fmt: skip
    tracker = SoftTracker(penetration, params)
    rng = np.random.default_rng(seed)
    tracker.update(rng, [0.08, 0.0, 0.0], [A], [[0.0, 0.0, 0.0]])
    tracker.update(rng, [0.19, 0.09, 0.0], [D], [[0.0, 0.0, 0.0]])
    contact = [0.21, 0.05 + edge_offset, 0.0]
    tracker.update(rng, [0.19, 0.05, 0.0], [contact], [[0.01, 0.0, 0.0]])
    return tracker.points


def test_a_push_does_not_move_points_behind_the_contact(box_penetration):
    gated = push_second_object(box_penetration, margin=0.002)
    paper = push_second_object(box_penetration, margin=None)
    moved = np.isclose(paper[:, 0, 0], A[0] + 0.01, atol=1e-6)
    # The paper connects A (11 cm from the contact, p = 0.54) in about half the particles...
    assert 30 <= moved.sum() <= 75
    assert np.allclose(paper[~moved, 0], A, atol=1e-6)
    # ...the rule in none: A lies on an object the robot's flat face cannot have pushed.
    assert np.allclose(gated[:, 0], A, atol=1e-6)
    # D, in front of the contact, follows in the very same particles (the rule draws nothing).
    assert np.array_equal(gated[:, 1:], paper[:, 1:])
    assert np.isclose(gated[:, 1, 0], D[0] + 0.01, atol=1e-6).sum() >= 80


def test_the_rule_yields_where_the_robot_normal_is_uncertain(box_penetration):
    """At the robot's +x/+y edge the touched object's normal could be anywhere from +x to +y,
    so A is not ruled out and moves exactly as the paper's filter moves it."""
    gated = push_second_object(box_penetration, margin=0.002, edge_offset=0.009)
    paper = push_second_object(box_penetration, margin=None, edge_offset=0.009)
    assert np.array_equal(gated, paper)
    assert not np.allclose(paper[:, 0], A, atol=1e-6)


def test_a_soft_rule_lets_a_point_follow_less_the_further_behind_it_lies(box_penetration):
    """A lies 10 cm behind the contact's plane, 9.8 cm beyond the 2 mm margin: with softness
    sigma it follows in the particles whose draw falls below p_paper * exp(-(0.098 / sigma)^2),
    a subset of those in which the paper's filter moves it, and D is untouched."""
    paper = push_second_object(box_penetration, margin=None)
    moved_paper = np.isclose(paper[:, 0, 0], A[0] + 0.01, atol=1e-6)
    counts = {}
    for softness in (0.03, 0.1, 1.0):
        soft = push_second_object(box_penetration, margin=0.002, softness=softness)
        moved = np.isclose(soft[:, 0, 0], A[0] + 0.01, atol=1e-6)
        assert np.allclose(soft[~moved, 0], A, atol=1e-6)
        assert not (moved & ~moved_paper).any()  # the same draws, a smaller probability
        assert np.array_equal(soft[:, 1:], paper[:, 1:])
        counts[softness] = int(moved.sum())
    # exp(-(0.098/sigma)^2): 2.3e-5 at 3 cm, 0.38 at 10 cm, 0.99 at 1 m, of about 54 % (p_paper)
    assert counts[0.03] == 0
    assert 8 <= counts[0.1] <= 35
    assert counts[1.0] >= int(moved_paper.sum()) - 2


def test_softness_zero_is_the_hard_rule(box_penetration):
    hard = push_second_object(box_penetration, margin=0.002)
    assert np.array_equal(push_second_object(box_penetration, 0.002, softness=0.0), hard)
    assert np.allclose(hard[:, 0], A, atol=1e-6)


@pytest.mark.parametrize(
    ("override", "name"),
    [({"touched_side_margin": -0.001}, "touched_side_margin"),
     ({"touched_side_margin": float("nan")}, "touched_side_margin"),
     ({"touched_side_softness": -0.01}, "touched_side_softness"),
     ({"touched_side_softness": float("inf")}, "touched_side_softness"),
     ({"normal_probe_radius": 0.0}, "normal_probe_radius")],
)  # fmt: skip
def test_bad_rule_parameters_raise_naming_them(override, name):
    with pytest.raises(ValueError, match=name):
        SoftTrackingParams.from_mapping(override)


def test_the_rule_loads_from_yaml_and_the_table_command_takes_it(tmp_path):
    path = tmp_path / "stucco.yaml"
    path.write_text("touched_side_margin: 0.002\n")
    assert SoftTrackingParams.from_yaml(path).touched_side_margin == 0.002
    assert SoftTrackingParams.sim().touched_side_margin is None  # off in the paper's preset
    parser = argparse.ArgumentParser()
    add_table_command(parser.add_subparsers())
    path.write_text("touched_side: 0.002\n")  # misspelt
    args = parser.parse_args(["table", "--scenes", "SYN2", "--out", str(tmp_path / "out"),
                              "--stucco-params", str(path)])  # fmt: skip
    with pytest.raises(InputError, match=r"unknown key.*touched_side") as error:
        args.run(args)
    assert "\n" not in str(error.value)
    assert not (tmp_path / "out").exists()  # refused before anything was made
