"""The forty-third look's replay: would one more point on the flanked long face, further along
it, place BC's box, from STUCCO's tracked points or from the points where they were sensed?

For each log it re-estimates the target's pose with the hypotheses (the folder's
``hypothesis_params.yaml``) four ways: STUCCO's tracked points with its own segment labels, as
the table did; the same with the target's points told apart by the truth; the points where
sensed with STUCCO's labels; and each of these with one more target point added, on the long
face the flank touches (the box's +x face in its own frame, +y in the world for BC's layouts),
``ALONG`` from the corner nearest the robot (the true final pose, the contacts' median height).
Prints each estimate's distance from the target's true final position (cm) and confidence.

Run from the repository's root:
    .venv/bin/python results/development/flank_point_replay.py FOLDER SCENE [SCENE ...]
"""

import dataclasses
import sys
from pathlib import Path

import numpy as np
import yaml
from inputs_swap import estimate, tracked

from stucco_drake.core.hypothesis_params import HypothesisParams
from stucco_drake.core.settings import settings_with
from stucco_drake.eval.episode_log import EpisodeLog
from stucco_drake.eval.target_estimates import log_target_shape

ALONG = 0.10  # m from the near corner, past the box's 6.6 cm end face


def with_flank_point(log) -> EpisodeLog:
    """``log`` with one more contact on the target, sensed in its last action (see above)."""
    x, y, yaw = log.object_poses[-1, 0]
    hx, hy, _ = log_target_shape(log).half_extents
    c, s = np.cos(yaw), np.sin(yaw)
    z = float(np.median(log.contact_points[log.contact_object == 0, 2]))
    point = np.array([x + c * hx - s * (hy - ALONG), y + s * hx + c * (hy - ALONG), z])
    offsets = log.contact_offsets.copy()
    offsets[-1] += 1
    return dataclasses.replace(
        log, contact_points=np.vstack([log.contact_points, point]), contact_offsets=offsets,
        contact_dx=np.vstack([log.contact_dx, np.zeros((1, log.contact_dx.shape[1]))]),
        contact_object=np.append(log.contact_object, 0))


def main() -> None:
    folder = Path(sys.argv[1])
    params = settings_with(HypothesisParams(),
                           yaml.safe_load((folder / "hypothesis_params.yaml").read_text()))
    for scene in sys.argv[2:]:
        log = EpisodeLog.load(folder / "logs" / f"{scene}_0.npz")
        points, labels = tracked(log, folder, "stucco")
        on_target = (log.contact_object == 0) & (labels >= 0)
        target = np.bincount(labels[on_target]).argmax()
        row = []
        for extra in (False, True):
            ext = with_flank_point(log) if extra else log
            pts = np.vstack([points, ext.contact_points[-1]]) if extra else points
            own = np.append(labels, target) if extra else labels
            truth = np.where(ext.contact_object == 0, target, -1)
            row += [estimate(ext, pts, own, params), estimate(ext, pts, truth, params),
                    estimate(ext, ext.contact_points, own, params)]
        print(scene, "|", " | ".join(row), flush=True)


if __name__ == "__main__":
    main()
