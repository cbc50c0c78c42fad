"""The paper's baseline trackers (Sec. V-A) and a factory for every tracker by name.

BIRCH, DBSCAN and incremental k-means re-cluster all points at every contact step and move
the clusters of the new points (single estimate, no hindsight). GM-PHD tracks objects with a
Gaussian-mixture PHD filter and labels points by their nearest object. Defaults are the
authors' simulation settings.
"""

from __future__ import annotations

from collections.abc import Mapping

from stucco_drake.core.baselines.gmphd import GmPhdClustering, GmPhdFilter
from stucco_drake.core.baselines.online import (
    BaselineTracker,
    BirchClustering,
    DbscanClustering,
    IncrementalKMeans,
    OnlineClustering,
)
from stucco_drake.core.baselines.params import BirchParams, DbscanParams, GmPhdParams, KMeansParams
from stucco_drake.core.params import SoftTrackingParams
from stucco_drake.core.penetration import RobotPenetration
from stucco_drake.core.soft_tracker import SoftTracker
from stucco_drake.core.tracker import Tracker

#: Baseline name -> (parameter class, clustering built from those parameters).
_BASELINES = {
    "birch": (BirchParams, BirchClustering),
    "dbscan": (DbscanParams, DbscanClustering),
    "kmeans": (KMeansParams, IncrementalKMeans),
    "gmphd": (GmPhdParams, GmPhdClustering),
}
TRACKER_NAMES = ("stucco", *_BASELINES)


def make_tracker(name: str, params=None, penetration: RobotPenetration | None = None) -> Tracker:
    """A fresh tracker by name: 'stucco', 'birch', 'dbscan', 'kmeans' or 'gmphd'.

    Args:
        name: the method.
        params: its parameters: the method's dataclass (``SoftTrackingParams`` for STUCCO), a
            mapping of overrides of the paper defaults (unknown keys raise), or None.
        penetration: pxpen of the robot; required by STUCCO, unused by the baselines.
    """
    if name == "stucco":
        if penetration is None:
            raise ValueError("make_tracker: 'stucco' needs a penetration (the robot's pxpen)")
        if isinstance(params, Mapping):
            params = SoftTrackingParams.from_mapping(params)
        elif params is not None and not isinstance(params, SoftTrackingParams):
            raise ValueError(
                f"make_tracker: 'stucco' params must be SoftTrackingParams or a mapping, "
                f"got {type(params).__name__}"
            )
        return SoftTracker(penetration, params)
    if name not in _BASELINES:
        raise ValueError(
            f"make_tracker: unknown tracker {name!r} (known: {', '.join(TRACKER_NAMES)})"
        )
    params_class, clustering = _BASELINES[name]
    if not isinstance(params, params_class):
        params = params_class.from_mapping(params)
    return BaselineTracker(clustering(params))


__all__ = [
    "TRACKER_NAMES",
    "BaselineTracker",
    "BirchClustering",
    "BirchParams",
    "DbscanClustering",
    "DbscanParams",
    "GmPhdClustering",
    "GmPhdFilter",
    "GmPhdParams",
    "IncrementalKMeans",
    "KMeansParams",
    "OnlineClustering",
    "make_tracker",
]
