"""Where the episodes of a table come from: a producer per scene, and how to replay its logs.

An :class:`EpisodeSource` bundles, for one family of scenes, the function that simulates an
episode into an :class:`~stucco_drake.eval.episode_log.EpisodeLog`, the robot's pxpen for
STUCCO when the log carries no primitive robot shape, and the grasp attempted after replay.
Its callables are module-level functions, so a source can be sent to worker processes.
"""

from __future__ import annotations

import dataclasses
import functools
import inspect
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

    def with_hypothesis_params(self, params, name: str) -> EpisodeSource:
        """This source with ``params`` (the target pose estimator's
        :class:`~stucco_drake.core.hypothesis_params.HypothesisParams`) given to both its
        ``produce`` (the live estimator, which a closed-loop policy reads) and its ``grasp``
        (the grasps after replay), as their ``hypothesis_params`` keyword; ValueError naming
        the scene ``name`` when either cannot take it (no grasp, or not a keyword of theirs)."""
        takes = self.grasp is not None and all(
            _takes_hypothesis_params(f) for f in (self.produce, self.grasp)
        )
        if not takes:
            raise ValueError(
                f"--hypothesis-params: scene {name} has no target pose estimator "
                "to set (its episodes and grasps do not take the settings)"
            )
        return dataclasses.replace(
            self,
            produce=functools.partial(self.produce, hypothesis_params=params),
            grasp=functools.partial(self.grasp, hypothesis_params=params),
        )


def _takes_hypothesis_params(function) -> bool:
    """Whether ``function`` (or a partial of it) accepts a ``hypothesis_params`` keyword."""
    try:
        parameters = inspect.signature(function).parameters.values()
    except (TypeError, ValueError):  # a callable without a signature to read
        return False
    return any(
        p.kind is p.VAR_KEYWORD
        or (p.name == "hypothesis_params" and p.kind in (p.POSITIONAL_OR_KEYWORD, p.KEYWORD_ONLY))
        for p in parameters
    )


#: The synthetic planar scenes (no Drake): no grasp.
SYNTHETIC_SOURCES: dict[str, EpisodeSource] = {
    name: EpisodeSource(synthetic_episode) for name in SYNTHETIC_SCENES
}
