"""Episode logs of the Drake BOR scenes: recording, planar geometry, replay and grasping."""

from __future__ import annotations

import math

import numpy as np
import pytest
from pydrake.math import RigidTransform, RollPitchYaw

from stucco_drake.bor.log import (
    _planar_spec,
    grasp_from_log,
    grasp_success,
    log_penetration,
    record_episode,
)
from stucco_drake.core.baselines import TRACKER_NAMES
from stucco_drake.core.shapes import BoxSdf, CylinderSdf
from stucco_drake.eval.episode_log import EpisodeLog, PlanarSurface
from stucco_drake.eval.replay import replay

N_ACTIONS = 8  # FB's first 8 actions: two free, then pushes into the target


@pytest.fixture(scope="module")
def fb_log(tmp_path_factory) -> EpisodeLog:
    path = tmp_path_factory.mktemp("logs") / "FB_3.npz"
    record_episode("FB", 3, n_actions=N_ACTIONS).save(path)
    return EpisodeLog.load(path)  # through the file, as the table reads it


def test_fb_log_holds_the_episode(fb_log):
    assert fb_log.scene == "FB" and fb_log.seed == 3 and fb_log.n_actions == N_ACTIONS
    assert fb_log.action_noise == pytest.approx(5e-4)
    names = fb_log.object_names
    assert names[0] == "target" and "robot_pedestal" in names and "table" not in names
    # The mustard bottle is three shapes; every object owns at least one.
    assert np.bincount(fb_log.shape_object, minlength=len(names)).min() >= 1
    assert np.count_nonzero(fb_log.shape_object == names.index("mustard")) == 3
    # The pushes touch the target: most contacts are labelled with it, and the gripper is
    # within a sampling spacing (6 mm) of it after an action whose contact was on it.
    target = names.index("target")
    assert np.mean(fb_log.contact_object == target) >= 0.6, fb_log.contact_object
    for t in range(N_ACTIONS):
        if np.any(fb_log.contacts(t)[2] == target):
            assert fb_log.robot_object_distance[t, target] <= 0.006
    # The pushes nudge the 10 kg target (1.4 mm in 8 actions at seed 3); the walls stay put.
    moved = np.linalg.norm(np.diff(fb_log.object_poses[[0, -1], :, :2], axis=0)[0], axis=1)
    assert moved[target] > 5e-4
    assert moved[names.index("back_wall")] < 1e-9
    # Contact points lie on the touched object's surface at that time (isolation error).
    errors = []
    for t in range(N_ACTIONS):
        points, _, objects = fb_log.contacts(t)
        for p, k in zip(points, objects, strict=True):
            if k >= 0:
                shapes = np.flatnonzero(fb_log.shape_object == k)
                d = min(abs(PlanarSurface(tuple(fb_log.object_shapes[s]),
                                          tuple(fb_log.object_poses[t + 1, k]))(p[None])[0])
                        for s in shapes)  # fmt: skip
                errors.append(d)
    assert len(errors) >= 3 and np.median(errors) < 0.03, errors
    assert fb_log.final_state.size > 2 * 7 and np.all(np.isfinite(fb_log.final_state))
    # Each action's peak force is logged: 0 with no contact, positive with one (its value
    # against an applied force: test_wrench_estimator).
    touched = np.diff(fb_log.contact_offsets) > 0
    assert fb_log.action_peak_force.shape == (N_ACTIONS,) and touched.any()
    assert np.all(fb_log.action_peak_force[touched] > 0.0)
    assert fb_log.first(3).action_peak_force.shape == (3,)


def test_every_method_replays_a_drake_log(fb_log):
    penetration = log_penetration(fb_log)
    rows = {}
    for method in TRACKER_NAMES:
        row = replay(fb_log, method, penetration=penetration if method == "stucco" else None)
        rows[method] = row
        assert row["n_contacts"] == fb_log.n_contacts, method
        assert 0.0 < row["fmi"] <= 1.0, row
    print("\nCE by method (cm):", {m: round(r["ce_cm"], 2) for m, r in rows.items()})
    # Measured: STUCCO, BIRCH and k-means 0.12 cm, GM-PHD 0.33, DBSCAN 0.77 (it splits the box's
    # points in two and moves one part with the other's displacement). These 8 actions touch
    # only the 10 kg target, which turns 2 degrees and moves 1 mm, so no method has a reason to
    # carry points off it. 1 cm is the paper's STUCCO CE on FB (0.72 cm, std 0.25, Table II:
    # mean plus one std, rounded up); points moved 2 cm off the box break it.
    for row in rows.values():
        assert row["ce_cm"] <= 1.0, row
    # Every labelled contact is on the box, whose touched face the points cover over 8.5 cm,
    # inside STUCCO's segmentation radius (13.5 cm): one segment.
    assert set(fb_log.contact_object[fb_log.contact_object >= 0]) == {0}
    assert rows["stucco"]["fmi"] == 1.0


class _TrueOutline:
    """A tracker stand-in holding the log's contacts, moved onto the target's final outline
    (one segment), in the log's order (the grasp's pose estimate needs when each was sensed)."""

    def __init__(self, log: EpisodeLog, offset=(0.0, 0.0)):
        x, y, yaw = log.object_poses[-1, 0]
        hx, hy = log.object_shapes[0, 1:3]
        # Two adjacent faces (an L pins the pose), in the target's frame.
        n = log.n_contacts
        short = max(1, n // 3)
        local = [(-hx, v) for v in np.linspace(-hy, hy, n - short)]
        local += [(u, -hy) for u in np.linspace(-hx, hx, short + 1)[1:]]
        c, s = math.cos(yaw), math.sin(yaw)
        self._points = np.array([
            (x + offset[0] + c * u - s * v, y + offset[1] + s * u + c * v, 0.1) for u, v in local
        ])  # fmt: skip

    def map_points(self):
        return self._points

    def segment(self):
        return np.zeros(len(self._points), dtype=np.int64)


@pytest.mark.parametrize("estimator", ["rules", "hypotheses"])
def test_grasp_from_log_lifts_the_target_at_its_outline(fb_log, estimator):
    assert fb_log.n_contacts >= 4
    result = grasp_from_log(fb_log, _TrueOutline(fb_log), estimator=estimator)
    assert result is not None and result.success, result
    assert result.lift_height >= 0.05


def test_grasp_from_log_without_a_segment_is_a_failure(fb_log):
    class Empty(_TrueOutline):
        def segment(self):
            return -np.ones(len(self._points), dtype=np.int64)  # all noise: nothing to fit

    assert grasp_from_log(fb_log, Empty(fb_log)) is None
    assert grasp_from_log(fb_log, Empty(fb_log), estimator="hypotheses") is None


def test_grasp_from_log_weighs_hypotheses_with_the_given_settings(fb_log):
    """The true outline's points make a grasp at the defaults (above); settings asking more
    points of the chosen pose than the log has leave the hypotheses nothing to grasp."""
    from stucco_drake.core.hypothesis_params import HypothesisParams

    strict = HypothesisParams(min_explained=fb_log.n_contacts + 1)
    assert grasp_from_log(fb_log, _TrueOutline(fb_log), estimator="hypotheses",
                          hypothesis_params=strict) is None  # fmt: skip
    assert grasp_success(fb_log, _TrueOutline(fb_log), estimator="hypotheses",
                         hypothesis_params=strict) is False  # fmt: skip


def test_record_episode_builds_its_diagram_with_the_hypothesis_settings(monkeypatch):
    import stucco_drake.bor.log as bor_log
    from stucco_drake.core.hypothesis_params import HypothesisParams

    class Built(Exception):
        pass

    def build(*args, **kwargs):
        raise Built(kwargs.get("hypothesis_params"))

    monkeypatch.setattr(bor_log, "build_bor_diagram", build)
    params = HypothesisParams(temperature=2.0)
    with pytest.raises(Built) as built:
        record_episode("FB", 0, hypothesis_params=params)
    assert built.value.args[0] is params
    with pytest.raises(Built) as built:
        record_episode("FB", 0)
    assert built.value.args[0] is None


def test_planar_specs_of_turned_and_lying_shapes():
    box = _planar_spec(BoxSdf((0.1, 0.2, 0.3)), RigidTransform(RollPitchYaw(0, 0, 0.4), [1, 2, 3]))
    np.testing.assert_allclose(box, [0, 0.1, 0.2, 0.3, 1, 2, 0.4])
    # A box on its side: its y axis is the body's z.
    origin = np.zeros(3)
    side = _planar_spec(BoxSdf((0.1, 0.2, 0.3)),
        RigidTransform(RollPitchYaw(math.pi / 2, 0, 0), origin))
    np.testing.assert_allclose(side[1:4], [0.1, 0.3, 0.2], atol=1e-12)
    lying = _planar_spec(CylinderSdf(0.05, 0.2),
        RigidTransform(RollPitchYaw(0, math.pi / 2, 0), origin))
    np.testing.assert_allclose(lying[:4], [0, 0.2, 0.05, 0.05], atol=1e-12)
    with pytest.raises(ValueError, match="tilted"):
        _planar_spec(BoxSdf((0.1, 0.2, 0.3)), RigidTransform(RollPitchYaw(0.3, 0, 0), origin))


def test_planar_surface_turns_an_offset_shape():
    # A 0.2 x 0.02 box offset 0.1 along the object's x and turned 90 degrees in it; the object
    # itself at (1, 0) turned 90 degrees: the box ends up along world x, centred at (1, 0.1).
    surface = PlanarSurface((0, 0.1, 0.01, 0.05, 0.1, 0.0, math.pi / 2), (1.0, 0.0, math.pi / 2))
    np.testing.assert_allclose(surface(np.array([[1.0, 0.1, 0.0], [1.1, 0.1, 0.0],
                                                 [1.0, 0.12, 0.0]])),
                               [-0.01, 0.0, 0.01], atol=1e-12)  # fmt: skip


def test_the_log_says_whether_the_push_limit_could_slide_the_target(fb_log):
    """FB's target is the 10 kg cracker box (``models/ycb/003_cracker_box_10kg.sdf``: friction
    0.5) under the scene's 30 N push limit: 49 N to slide, so with ``still_when_unslidable``
    its replays search only scale 0, as its live estimator did."""
    import dataclasses

    from stucco_drake.core.hypothesis_params import HypothesisParams
    from stucco_drake.core.motion_scale import MOTION_SCALES
    from stucco_drake.eval.target_estimates import log_motion_scales

    assert fb_log.info["target_slide"] == {"mass": 10.0, "friction": 0.5, "max_push_force": 30.0}
    still = HypothesisParams(still_when_unslidable=True)
    assert log_motion_scales(fb_log, still) == (0.0,)
    assert log_motion_scales(fb_log) == MOTION_SCALES
    older = dataclasses.replace(fb_log, info={k: v for k, v in fb_log.info.items()
                                              if k != "target_slide"})  # fmt: skip
    assert log_motion_scales(older) == MOTION_SCALES
    with pytest.raises(ValueError, match="predates"):
        log_motion_scales(older, still)
