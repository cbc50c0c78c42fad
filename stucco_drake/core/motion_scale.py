"""Target-pose hypotheses when how far the target moved is itself in doubt.

The tracker moves each contact point by its model of the touched object's motion: the
end-effector's displacement while in contact, clipped to a friction cone. Where the object
really moved with the gripper (a light can pushed along) that is what makes the points usable;
where it did not (a heavy box the gripper slid along, a soft bubble squeezed against it), it
carries the points into the object by as much as the gripper travelled. A blind robot cannot
tell which from the points alone, so each hypothesis also chooses a **motion scale**
``alpha``: the target's points lie at ``sensed + alpha (tracked - sensed)``, one ``alpha`` for
all of them (the object moved rigidly, by that fraction of what the tracker says; 0: it never
moved, 1: as tracked). Poses are searched at each scale of a fixed set
(:func:`~stucco_drake.core.pose_hypotheses.search_hypotheses`) and pooled under a uniform prior
over the scales, so the scale is weighed like any other unknown of a hypothesis.

How far the tracker carried a point is itself uncertain, the more so the farther (each
contact's motion is a model of the gripper's travel, not a measurement of the object's): at
scale ``alpha`` a point is uncertain by ``transport_noise * alpha * |tracked - sensed|`` (xy)
beyond the sensor's noise. Explaining a point costs the log of that spread
(:func:`~stucco_drake.core.pose_hypotheses.contact_costs`), so where the sensed and the carried
points fit the outline alike, the smaller motion wins; where only the carried ones fit, they
still do. On the development layouts with probes this took the closing estimates from 38 to
46 of 70 (``results/development/README.md``, eighth look).
Units: m, rad; world frame W.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from stucco_drake.core.free_space import FreeSpace
from stucco_drake.core.pose_hypotheses import (
    HypothesisParams,
    PoseHypotheses,
    search_hypotheses,
    weigh_hypotheses,
)
from stucco_drake.core.shapes import BoxSdf, CylinderSdf
from stucco_drake.core.validation import as_finite_array

#: Motion scales searched: from "never moved" to "moved as tracked", in quarters.
MOTION_SCALES = (0.0, 0.25, 0.5, 0.75, 1.0)

#: Standard gravity (m/s^2).
GRAVITY = 9.81


def scales_under_push_limit(mass: float, friction: float, max_push_force: float | None,
                            scales=MOTION_SCALES) -> tuple[float, ...]:  # fmt: skip
    """The motion scales worth searching for a target of ``mass`` (kg) that slides on the
    table with Coulomb ``friction`` (dimensionless), pushed with at most ``max_push_force``
    (N, in the table plane; None: no limit).

    ``(0.0,)`` when the push cannot overcome the target's sliding friction,
    ``friction * mass * g > max_push_force``: it cannot have slid, so the tracker's motion of
    its points is the gripper's slide along it, not the target's. ``scales`` otherwise. A push
    off the target's centre can still turn it (a rotation needs less force than a slide); that
    turn is left to the hypotheses' noise.
    """
    if not (mass > 0 and friction >= 0):
        raise ValueError(f"mass, friction: expected > 0 kg and >= 0, got {mass!r}, {friction!r}")
    if max_push_force is not None and friction * mass * GRAVITY > max_push_force:
        return (0.0,)
    return tuple(float(s) for s in checked_scales(scales))


def check_light_force(light_force: float | None, mass: float, friction: float) -> None:
    """ValueError unless ``light_force`` (N; None passes) is at most half the force that
    slides a target of ``mass`` (kg) with Coulomb ``friction``: a target that slid would
    otherwise be read as clutter (:attr:`HypothesisParams.light_force`)."""
    bound = 0.5 * friction * mass * GRAVITY
    if light_force is not None and light_force > bound:
        raise ValueError(f"light_force: {light_force} N is more than half the force that slides "
                         f"the target ({bound:.2f} N: friction {friction} x {mass} kg x g)")


def checked_scales(scales) -> np.ndarray:
    """``scales`` as a (k,) float array; ValueError unless at least one, each in [0, 1]."""
    scales = np.asarray(scales, dtype=np.float64).reshape(-1)
    if len(scales) == 0 or np.any((scales < 0.0) | (scales > 1.0)):
        raise ValueError(f"scales: expected motion scales in [0, 1], got {scales.tolist()}")
    return scales


def motion_scaled_hypotheses(rng: np.random.Generator, sensed, tracked, labels,
                             shape: BoxSdf | CylinderSdf, *,
                             free_space: FreeSpace | None = None,
                             params: HypothesisParams | None = None,
                             scales=MOTION_SCALES,
                             point_forces=None) -> PoseHypotheses | None:  # fmt: skip
    """Weighted target-pose hypotheses over poses and motion scales (see the module).

    Args:
        rng: caller-seeded generator for the ICP starts (drawn from scale by scale, in order).
        sensed: (n, 3) each contact point where it was sensed (m, W).
        tracked: (n, 3) the same points where the tracker has them now, e.g. its MAP particle's.
        labels: (n,) the tracker's segment labels (negative: noise).
        shape: the target's known geometry in its frame O.
        free_space: where the robot has been (None: contact evidence only).
        params: the search's settings (None: ``HypothesisParams()``).
        scales: the motion scales searched (each in [0, 1]).
        point_forces: (n,) the peak force (N) of the action that sensed each point (NaN:
            unknown), judged against ``params.light_force``; None for none.

    Returns:
        The pooled hypotheses with each one's ``motion_scales``, or None when no placement of
        the target can touch ``min_explained`` points at any scale.

    Raises:
        ValueError: naming the argument (points of different shapes, a scale outside [0, 1],
            no segment with ``min_explained`` points).
    """
    params = params or HypothesisParams()
    sensed = as_finite_array(sensed, "sensed", (None, 3))
    tracked = as_finite_array(tracked, "tracked", sensed.shape)
    scales = checked_scales(scales)
    found = []
    motion = tracked - sensed
    travelled = np.hypot(*motion[:, :2].T)
    # Free space is judged where the points were sensed: the objects slide on the table, and
    # the vertical part of a tracked motion is the contact-motion model's, not the object's.
    # One slice then serves every scale (the free space caches it).
    height = float(sensed[:, 2].mean())
    for scale in scales:
        result = search_hypotheses(rng, sensed + scale * motion, labels, shape,
                                   spread=params.transport_noise * scale * travelled,
                                   free_space=free_space, params=params,
                                   carried=scale * motion, height=height,
                                   point_forces=point_forces)  # fmt: skip
        if result is not None:
            found.append((*result, np.full(len(result[0]), scale)))
    if not found:
        return None
    poses, costs, explained, scale_of = (np.concatenate(part) for part in zip(*found,
                                                                            strict=True))
    found = weigh_hypotheses(poses, costs, explained, shape, params, scale_of)
    felt = sensed + found.motion_scales[found.chosen] * motion
    return dataclasses.replace(found, felt=felt[:, :2])


__all__ = ["GRAVITY", "MOTION_SCALES", "check_light_force", "motion_scaled_hypotheses",
           "scales_under_push_limit"]
