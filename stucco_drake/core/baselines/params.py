"""Parameters of the paper's baseline trackers, with the authors' simulation settings."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping


class _Loadable:
    """Shared by the parameter dataclasses: range checks and loading from a mapping."""

    #: Field names that must be finite and > 0, and those that must lie in (0, 1].
    _positive: tuple[str, ...] = ()
    _probability: tuple[str, ...] = ()

    def _check(self) -> None:
        name = type(self).__name__
        for field in self._positive:
            value = getattr(self, field)
            if (
                isinstance(value, bool)
                or not isinstance(value, int | float)
                or not (math.isfinite(value) and value > 0)
            ):
                raise ValueError(f"{name}.{field}: must be a positive number, got {value!r}")
        for field in self._probability:
            value = getattr(self, field)
            if not (isinstance(value, int | float) and 0.0 < value <= 1.0):
                raise ValueError(f"{name}.{field}: must lie in (0, 1], got {value!r}")

    @classmethod
    def from_mapping(cls, mapping: Mapping | None):
        """Build from field overrides on top of the paper defaults; unknown keys raise."""
        if mapping is None:
            return cls()
        if not isinstance(mapping, Mapping):
            raise ValueError(f"{cls.__name__}: expected a mapping, got {type(mapping).__name__}")
        known = [field.name for field in dataclasses.fields(cls)]
        for key in mapping:
            if key not in known:
                raise ValueError(f"{cls.__name__}: unknown key {key!r} (known: {', '.join(known)})")
        return cls(**mapping)


def _integer(owner: str, name: str, value, minimum: int) -> None:
    if isinstance(value, bool) or not isinstance(value, int) or value < minimum:
        raise ValueError(f"{owner}.{name}: must be an integer >= {minimum}, got {value!r}")


@dataclasses.dataclass(frozen=True)
class BirchParams(_Loadable):
    """BIRCH refitted on all points at every contact step (no global clustering step).

    Attributes:
        threshold: largest radius (m) of a leaf subcluster; each subcluster is one object.
    """

    threshold: float = 0.08
    _positive = ("threshold",)

    def __post_init__(self):
        self._check()


@dataclasses.dataclass(frozen=True)
class DbscanParams(_Loadable):
    """DBSCAN refitted on all points at every contact step.

    Attributes:
        eps: neighbourhood radius (m).
        min_samples: neighbours (self included) that make a core point; 1 = single linkage.
    """

    eps: float = 0.05
    min_samples: int = 1
    _positive = ("eps",)

    def __post_init__(self):
        self._check()
        _integer(type(self).__name__, "min_samples", self.min_samples, 1)


@dataclasses.dataclass(frozen=True)
class KMeansParams(_Loadable):
    """k-means whose k starts at 1 and grows when one more cluster pays off.

    Attributes:
        inertia_ratio: switch to k + 1 when inertia(k + 1) < inertia_ratio * inertia(k)
            (0.2: the paper's "5x improvement").
        min_points: no new cluster before this many points are stored.
        n_init: k-means restarts per fit (10, scikit-learn's default when the paper was run).
    """

    inertia_ratio: float = 0.2
    min_points: int = 5
    n_init: int = 10
    _probability = ("inertia_ratio",)

    def __post_init__(self):
        self._check()
        _integer(type(self).__name__, "min_points", self.min_points, 1)
        _integer(type(self).__name__, "n_init", self.n_init, 1)


@dataclasses.dataclass(frozen=True)
class GmPhdParams(_Loadable):
    """Gaussian-mixture PHD filter over planar (x, y) contact positions (Vo & Ma 2006).

    Attributes:
        birth_weight: total birth intensity per step (expected new objects), spread evenly
            over the birth grid.
        birth_grid: birth components per axis of ``birth_bounds`` (a grid of birth_grid^2).
        birth_bounds: (x_min, y_min, x_max, y_max) of the birth grid (m, world).
        birth_covariance: variance (m^2) of each birth component, per axis.
        survival: probability that an object persists to the next contact step.
        detection: probability that a contact step observes a given object.
        clutter_rate: expected false contacts per step over ``birth_bounds``; the clutter
            intensity is this over the bounds' area (3 / 4 m^2 = 0.75 per m^2).
        process_noise: q (m^2), Q = q I: objects are static between steps (F = I).
        observation_noise: r (m^2), R = r I: a contact observes the object directly (H = I).
        truncate: components lighter than this are dropped.
        merge: squared Mahalanobis distance under which components merge.
        max_components: components kept after pruning, heaviest first.
        bias: objects extracted = round(bias * total weight), doubled until >= 1.
        update_covariance: give detected components the Kalman posterior covariance (Vo & Ma).
            False reproduces the authors' copy of the filter, which kept the predicted one.
    """

    birth_weight: float = 0.001
    birth_grid: int = 20
    birth_bounds: tuple[float, float, float, float] = (-1.0, -1.0, 1.0, 1.0)
    birth_covariance: float = 1e-3
    survival: float = 0.95
    detection: float = 0.3
    clutter_rate: float = 3.0
    process_noise: float = 5e-5
    observation_noise: float = 5e-5
    truncate: float = 1e-6
    merge: float = 0.005
    max_components: int = 10
    bias: float = 4.0
    update_covariance: bool = True
    _positive = (
        "birth_weight", "birth_covariance", "clutter_rate", "process_noise",
        "observation_noise", "truncate", "merge", "bias",
    )  # fmt: skip
    _probability = ("survival", "detection")

    def __post_init__(self):
        name = type(self).__name__
        self._check()
        _integer(name, "birth_grid", self.birth_grid, 2)
        _integer(name, "max_components", self.max_components, 1)
        if not isinstance(self.update_covariance, bool):
            raise ValueError(
                f"{name}.update_covariance: must be true or false, got {self.update_covariance!r}"
            )
        try:
            bounds = tuple(float(v) for v in self.birth_bounds)
        except (TypeError, ValueError):
            bounds = ()
        if len(bounds) != 4 or not (bounds[0] < bounds[2] and bounds[1] < bounds[3]):
            raise ValueError(
                f"{name}.birth_bounds: expected (x_min, y_min, x_max, y_max) with min < max, "
                f"got {self.birth_bounds!r}"
            )
        object.__setattr__(self, "birth_bounds", bounds)  # a YAML list becomes a tuple

    @property
    def clutter_intensity(self) -> float:
        """Clutter intensity kappa (false contacts per step per m^2)."""
        x0, y0, x1, y1 = self.birth_bounds
        return self.clutter_rate / ((x1 - x0) * (y1 - y0))

    @classmethod
    def training(cls) -> GmPhdParams:
        """The authors' values on the tracking training set (BOR uses the defaults)."""
        return cls(bias=1.0, process_noise=0.1, observation_noise=0.1)
