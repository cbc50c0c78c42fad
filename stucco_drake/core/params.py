"""Parameters of the STUCCO soft tracker, with the paper's Table I presets."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from pathlib import Path

from stucco_drake.core.settings import yaml_file_data, yaml_text_data


@dataclasses.dataclass(frozen=True)
class SoftTrackingParams:
    """Parameters of :class:`~stucco_drake.core.soft_tracker.SoftTracker` (paper Table I).

    Attributes:
        length: characteristic length l (m^2: it enters as exp(-d^2 / l), so the 1/e distance is
            sqrt(l), 0.141 m in sim). Sets how likely two contact points are to be connected.
        penetration_length: lambda (m^2), scales the observation likelihood exp(-eps^2 / lambda)
            of a particle whose points penetrate the robot by a total of eps metres.
        n_particles: number of particles N.
        connection_threshold: p_c, the connection probability above which segmentation links two
            points (Algorithm 3). With l = 0.02 that is a distance below 0.135 m.
        intersection_tolerance: penetration (m) that is ignored before a pair counts: contact
            isolation error, or the first millimetres of a soft bubble's deformation.
        resample_ess_fraction: resample when the effective sample size falls below this fraction
            of N. 1.0 resamples at every step as the paper's text does; the authors' code uses 0.8.
        touched_side_margin: None (the paper) or a distance (m) that turns on the touched-side
            rule of the prediction: a push moves only points that can lie on the object it
            touched. That object is convex and lies beyond the robot's tangent plane at the
            contact, so a point more than ``touched_side_margin + d * s`` behind that plane
            (d its distance to the contact, s the normal's uncertainty, see
            :func:`~stucco_drake.core.contact_motion.normal_spread`) stays where it is.
        touched_side_softness: 0 (a hard rule) or a distance sigma (m) that softens it: a
            point e metres further behind than that bound still follows, with its connection
            probability times exp(-(e / sigma)^2), so a point of the touched object that lags
            a little behind its object can catch up in some particles. Has no effect while
            ``touched_side_margin`` is None.
        normal_probe_radius: how far (m) around a contact the robot's normal is compared to
            judge its uncertainty s: about the contact isolation's error.
        replace_bad: True (the paper's Algorithm 2) replaces each point that penetrates one of
            its particle's configs by the nearest consistent point of that particle after every
            update; False leaves it where it is, so penetration only lowers the particle's
            weight. A point pressed into the robot's rigid model by a compressed bubble, or
            carried into it by a push the object did not follow, is otherwise copied onto
            another point of the same face, centimetres away along it.
    """

    length: float = 0.02
    penetration_length: float = 0.002
    n_particles: int = 100
    connection_threshold: float = 0.4
    intersection_tolerance: float = 0.002
    resample_ess_fraction: float = 0.8
    touched_side_margin: float | None = None
    touched_side_softness: float = 0.0
    normal_probe_radius: float = 0.003
    replace_bad: bool = True

    def __post_init__(self):
        for name in ("length", "penetration_length"):
            value = getattr(self, name)
            if not (isinstance(value, int | float) and math.isfinite(value) and value > 0):
                raise ValueError(
                    f"SoftTrackingParams.{name}: must be a positive number, got {value!r}"
                )
        if not (isinstance(self.n_particles, int) and self.n_particles >= 1):
            raise ValueError(
                f"SoftTrackingParams.n_particles: must be an integer >= 1, got {self.n_particles!r}"
            )
        if not 0.0 < self.connection_threshold < 1.0:
            raise ValueError(
                "SoftTrackingParams.connection_threshold: must lie in (0, 1), "
                f"got {self.connection_threshold!r}"
            )
        if not (math.isfinite(self.intersection_tolerance) and self.intersection_tolerance >= 0):
            raise ValueError(
                "SoftTrackingParams.intersection_tolerance: must be >= 0, "
                f"got {self.intersection_tolerance!r}"
            )
        margin = self.touched_side_margin
        if margin is not None and not (
            isinstance(margin, int | float) and math.isfinite(margin) and margin >= 0
        ):
            raise ValueError(
                f"SoftTrackingParams.touched_side_margin: must be None or >= 0, got {margin!r}"
            )
        softness = self.touched_side_softness
        if not (isinstance(softness, int | float) and math.isfinite(softness) and softness >= 0):
            raise ValueError(
                f"SoftTrackingParams.touched_side_softness: must be >= 0, got {softness!r}"
            )
        if not (math.isfinite(self.normal_probe_radius) and self.normal_probe_radius > 0):
            raise ValueError(
                "SoftTrackingParams.normal_probe_radius: must be > 0, "
                f"got {self.normal_probe_radius!r}"
            )
        if not isinstance(self.replace_bad, bool):
            raise ValueError(
                f"SoftTrackingParams.replace_bad: must be true or false, got {self.replace_bad!r}"
            )
        if not 0.0 < self.resample_ess_fraction <= 1.0:
            raise ValueError(
                "SoftTrackingParams.resample_ess_fraction: must lie in (0, 1], "
                f"got {self.resample_ess_fraction!r}"
            )

    @property
    def segmentation_radius(self) -> float:
        """Distance (m) below which Algorithm 3 links two points: exp(-d^2/l) > p_c."""
        return math.sqrt(-self.length * math.log(self.connection_threshold))

    @classmethod
    def sim(cls) -> SoftTrackingParams:
        """Table I, simulation column (intersection tolerance from the authors' sim config)."""
        return cls(
            length=0.02,
            penetration_length=0.002,
            n_particles=100,
            connection_threshold=0.4,
            intersection_tolerance=0.002,
        )

    @classmethod
    def real(cls) -> SoftTrackingParams:
        """Table I, real-robot column; the first 10 mm of bubble penetration are ignored."""
        return cls(
            length=0.006,
            penetration_length=0.002,
            n_particles=100,
            connection_threshold=0.4,
            intersection_tolerance=0.010,
        )

    @classmethod
    def from_mapping(cls, mapping: Mapping, *, preset: str = "sim") -> SoftTrackingParams:
        """Build from a mapping of field overrides on top of ``preset`` ('sim' or 'real').

        A ``preset`` key inside the mapping selects the base preset. Unknown keys raise.
        """
        if not isinstance(mapping, Mapping):
            raise ValueError(
                f"SoftTrackingParams: expected a mapping, got {type(mapping).__name__}"
            )
        values = dict(mapping)
        preset = values.pop("preset", preset)
        presets = {"sim": cls.sim, "real": cls.real}
        if preset not in presets:
            raise ValueError(f"SoftTrackingParams: unknown preset {preset!r} (known: sim, real)")
        known = {field.name for field in dataclasses.fields(cls)}
        unknown = sorted(set(values) - known)
        if unknown:
            raise ValueError(
                f"SoftTrackingParams: unknown key(s) {', '.join(unknown)} "
                f"(known: preset, {', '.join(sorted(known))})"
            )
        if "n_particles" in values and isinstance(values["n_particles"], float):
            if not values["n_particles"].is_integer():
                raise ValueError("SoftTrackingParams.n_particles: must be an integer")
            values["n_particles"] = int(values["n_particles"])
        return dataclasses.replace(presets[preset](), **values)

    @classmethod
    def from_yaml(cls, source: str | Path) -> SoftTrackingParams:
        """Load from a YAML file (a path object, or a one-line string ending in .yaml or .yml)
        or a YAML string holding a mapping (see from_mapping)."""
        is_file = not isinstance(source, str) or (
            "\n" not in source and Path(source).suffix in (".yaml", ".yml")
        )
        if is_file:
            data = yaml_file_data(source, "SoftTrackingParams")
            where = str(source)
        else:
            data, where = yaml_text_data(source, "SoftTrackingParams", "<string>"), "<string>"
        try:
            return cls.from_mapping(data if data is not None else {})
        except ValueError as error:
            raise ValueError(f"{where}: {error}") from None

    def to_mapping(self) -> dict:
        """The parameters as a plain dict (for saving beside results)."""
        return dataclasses.asdict(self)
