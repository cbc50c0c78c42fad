"""The thirty-eighth look's diagnosis: which of STUCCO's inputs to the pose hypotheses (its
tracked points or its segments) makes them miss where k-means' do not, on the same episode.

For each layout it replays STUCCO and k-means at the table's settings, then prints:
- the hypotheses' estimate (cm from the target's true final position, and confidence) from
  each method's points with each method's segment labels;
- how far the target's tracked points lie from where the points truly are at the end (each
  sensed point carried with the target's true motion since it was sensed), for both methods
  and for the points where sensed;
- STUCCO's estimate searched at some of the motion scales only;
- STUCCO's particles at the end (how far apart they put the target's points), and the actions
  at which the MAP particle's earlier target points moved most, against the target's true
  motion in that action and what the action touched (object indices, -1: unknown).

With ``--all``, instead, over every log of the three folders: per family, the median over
layouts of how far the target's points lie from their true place (median over the points),
where sensed, as STUCCO tracks them and as k-means does. Arguments after ``--all`` change
STUCCO's parameters, e.g. ``replace_bad=false`` (the thirty-ninth look).

Run from the repository's root:
    .venv/bin/python results/development/inputs_swap.py [--all [NAME=VALUE ...]]
"""

import dataclasses
import sys
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import yaml

from stucco_drake.bor import log as bor_log
from stucco_drake.cli.estimates import _table_settings
from stucco_drake.core.baselines import make_tracker
from stucco_drake.core.hypothesis_params import HypothesisParams
from stucco_drake.core.pose_hypotheses import tracker_spread
from stucco_drake.eval.episode_log import EpisodeLog
from stucco_drake.eval.replay import observed_dx, replay
from stucco_drake.eval.summary import layout_family
from stucco_drake.eval.target_estimates import hypotheses_estimate, log_target_shape, point_steps

HERE = Path(__file__).parent
LAYOUTS = [("probe_disc_fb", "FB-L1017"), ("probe_disc_fb", "FB-L1029"),
           ("probe_disc", "IB-L1027"), ("probe_disc", "IB-L1028"), ("probe_disc", "IB-L1029")]


def tracked(log, folder: Path, method: str, changes=None):
    """(points (n, 3) m, segment labels (n,)) of ``method`` replayed on ``log`` as the table
    did (STUCCO's parameters with ``changes``, a dict of SoftTrackingParams fields)."""
    dx_model, params, stream, _ = _table_settings(folder)
    params = dataclasses.replace(params, **(changes or {}))
    kept = {}

    def keep(_, tracker):
        kept["out"] = (np.array(tracker.map_points()), np.array(tracker.segment()))

    replay(log, method, log.seed + 1000 * stream, params if method == "stucco" else None,
           penetration=bor_log.log_penetration(log), dx_model=dx_model, grasp=keep)
    return kept["out"]


def carried(log) -> np.ndarray:
    """(n, 2) each contact point carried from where it was sensed with the true motion of the
    object it touched (pose at the end of its action to the final pose), m, W."""
    out = log.contact_points[:, :2].copy()
    for i, (step, obj) in enumerate(zip(point_steps(log), log.contact_object, strict=True)):
        if obj < 0:
            continue
        (x, y, a), (fx, fy, fa) = log.object_poses[step + 1, obj], log.object_poses[-1, obj]
        c, s = np.cos(fa - a), np.sin(fa - a)
        d = out[i] - (x, y)
        out[i] = (fx + c * d[0] - s * d[1], fy + s * d[0] + c * d[1])
    return out


def estimate(log, points, labels, hypothesis_params, scales=None) -> str:
    tracker = SimpleNamespace(map_points=lambda: points, segment=lambda: labels)
    kwargs = {} if scales is None else {"scales": scales}
    found = hypotheses_estimate(np.random.default_rng([log.seed, 1]), log, tracker,
                                log_target_shape(log), bor_log.log_penetration(log),
                                hypothesis_params, **kwargs)  # fmt: skip
    truth = log.object_poses[-1, 0][:2]
    return f"{np.hypot(*(found.pose[:2] - truth)) * 100:4.1f} cm ({found.confidence:.2f})"


def stucco_moves(log, folder: Path, shown: int = 4) -> None:
    """Replays STUCCO as :func:`tracked` does, printing its particles' spread on the target's
    points at the end and the ``shown`` actions that moved the MAP particle's earlier target
    points most."""
    dx_model, params, stream, _ = _table_settings(folder)
    penetration = bor_log.log_penetration(log)
    dx_all = observed_dx(log, dx_model, penetration)
    tracker = make_tracker("stucco", params, penetration)
    rng = np.random.default_rng(log.seed + 1000 * stream)
    target = np.flatnonzero(log.contact_object == 0)
    moves, before = [], None
    for t in range(log.n_actions):
        points, _, objects = log.contacts(t)
        lo, hi = log.contact_offsets[t], log.contact_offsets[t + 1]
        tracker.update(rng, log.ee_position[t], points, dx_all[lo:hi], log.ee_rotation[t])
        now, earlier = tracker.map_points(), target[target < lo]
        if len(earlier) and before is not None:
            moved = np.linalg.norm(now[earlier, :2] - before[earlier, :2], axis=1).mean()
            truly = np.linalg.norm(np.diff(log.object_poses[t:t + 2, 0, :2], axis=0))
            moves.append((moved, t, truly, sorted(set(objects.tolist()))))
        before = now.copy()
    spread = tracker_spread(tracker)[target]
    print(f"  particles' spread on the target's points: median {np.median(spread) * 100:.2f} cm")
    for moved, t, truly, objects in sorted(moves, reverse=True)[:shown]:
        print(f"  action {t}: target points moved {moved * 100:.2f} cm (mean), the target "
              f"{truly * 100:.2f} cm; touched {objects}")


def all_layouts(changes=None) -> None:
    """Per family: the target points' distance from their true place, three ways (STUCCO's
    parameters with ``changes``)."""
    gaps = {}
    for name in ("probe_disc_fb", "probe_disc_fb_more", "probe_disc"):
        folder = HERE / name
        for path in sorted((folder / "logs").glob("*.npz")):
            log = EpisodeLog.load(path)
            on_target = log.contact_object == 0
            if not on_target.any():
                continue
            truth = carried(log)[on_target]
            row = [float(np.median(np.linalg.norm(points[on_target, :2] - truth, axis=1)))
                   for points in (log.contact_points, tracked(log, folder, "stucco", changes)[0],
                                  tracked(log, folder, "kmeans")[0])]  # fmt: skip
            gaps.setdefault(layout_family(log.scene), []).append(row)
    for family, rows in gaps.items():
        rows = np.array(rows) * 100
        sensed, stucco, kmeans = np.median(rows, axis=0)
        print(f"{family} ({len(rows)} layouts): sensed {sensed:.2f} cm, STUCCO {stucco:.2f}, "
              f"k-means {kmeans:.2f}; STUCCO nearer than sensed in "
              f"{int(np.sum(rows[:, 1] < rows[:, 0]))}, k-means in "
              f"{int(np.sum(rows[:, 2] < rows[:, 0]))}")


def main() -> None:
    for name, scene in LAYOUTS:
        folder = HERE / name
        log = EpisodeLog.load(folder / "logs" / f"{scene}_0.npz")
        params = _table_settings(folder)[3] or HypothesisParams()
        got = {m: tracked(log, folder, m) for m in ("stucco", "kmeans")}
        print(f"{scene}:")
        for points_of in got:
            cells = [estimate(log, got[points_of][0], got[labels_of][1], params)
                     for labels_of in got]  # fmt: skip
            print(f"  {points_of}'s points, stucco's / kmeans' labels: " + " / ".join(cells))
        on_target, truth = log.contact_object == 0, carried(log)[log.contact_object == 0]
        for what, points in (("sensed", log.contact_points), *((m, got[m][0]) for m in got)):
            gap = np.linalg.norm(points[on_target, :2] - truth, axis=1) * 100
            print(f"  target points {what}: {np.median(gap):.2f} cm from their true place "
                  f"(max {gap.max():.2f})")
        for scales in ((0.0,), (0.0, 0.5, 1.0), (1.0,)):
            print(f"  stucco at scales {scales}: "
                  + estimate(log, got["stucco"][0], got["stucco"][1], params, scales))
        stucco_moves(log, folder)


def changes_of(texts) -> dict:
    """SoftTrackingParams changes from ``name=value`` texts (value read as YAML)."""
    return {name: yaml.safe_load(value) for name, _, value in (t.partition("=") for t in texts)}


if __name__ == "__main__":
    if sys.argv[1:2] == ["--all"]:
        all_layouts(changes_of(sys.argv[2:]))
    else:
        main()
