"""Where the episodes of a table come from: a producer per scene, and how to replay its logs.

An :class:`EpisodeSource` bundles, for one family of scenes, the function that simulates an
episode into an :class:`~stucco_drake.eval.episode_log.EpisodeLog`, the robot's pxpen for
STUCCO when the log carries no primitive robot shape, and the grasp attempted after replay.
Its callables are module-level functions, so a source can be sent to worker processes.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable

from stucco_drake.core.penetration import RobotPenetration
from stucco_drake.eval.episode_log import EpisodeLog
from stucco_drake.eval.replay import GraspCheck
from stucco_drake.eval.synthetic_episode import SYNTHETIC_SCENES, synthetic_episode


@dataclasses.dataclass(frozen=True)
class EpisodeSource:
    """How to make and replay one scene's episodes.

    Attributes:
        produce: ``produce(scene, seed) -> EpisodeLog`` simulates one episode.
        penetration: ``penetration(log) -> RobotPenetration`` for STUCCO (None: the log's
            primitive ``robot_shape``).
        grasp: ``grasp(log, tracker) -> bool`` run after replay (None: no grasp, the row's
            grasp success stays empty).
        scene_set: the evaluation set the scene belongs to (see :mod:`stucco_drake.eval.sets`).
        family: the column group of the scene in a table: a randomized layout's base scene
            (its layouts are tabled together); empty: the scene's own name.
        scene_file: the scene file the episodes are of (empty: a built-in scene, by name);
            what a closed-loop policy's producer simulates (see ``table --policy``).
    """

    produce: Callable[[str, int], EpisodeLog]
    penetration: Callable[[EpisodeLog], RobotPenetration] | None = None
    grasp: GraspCheck | None = None
    scene_set: str = "other"
    family: str = ""
    scene_file: str = ""

    def penetration_for(self, log: EpisodeLog, method: str) -> RobotPenetration | None:
        """The pxpen ``method`` needs on ``log``: STUCCO's from ``penetration``; None for the
        other methods, or when the log's primitive robot shape serves (replay builds it)."""
        if method == "stucco" and self.penetration is not None:
            return self.penetration(log)
        return None


#: The synthetic planar scenes (no Drake): no grasp.
SYNTHETIC_SOURCES: dict[str, EpisodeSource] = {
    name: EpisodeSource(synthetic_episode) for name in SYNTHETIC_SCENES
}
