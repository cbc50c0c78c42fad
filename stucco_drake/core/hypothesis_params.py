"""The settings of the target-pose hypotheses (:mod:`~stucco_drake.core.pose_hypotheses`)."""

from __future__ import annotations

import dataclasses

import numpy as np

#: How the grasp of a box goes down (:attr:`HypothesisParams.box_approach`).
BOX_APPROACHES = ("top", "end", "end_aside")
#: Those that go down beyond an end of a box and slide along it.
END_APPROACHES = ("end", "end_aside")


def check_box_approach(value) -> str:
    """``value`` if it is one of :data:`BOX_APPROACHES`; ValueError naming it otherwise."""
    if value not in BOX_APPROACHES:
        raise ValueError(f"box_approach: expected one of {', '.join(BOX_APPROACHES)}, "
                         f"got {value!r}")
    return value


@dataclasses.dataclass(frozen=True)
class HypothesisParams:
    """Settings of :func:`~stucco_drake.core.pose_hypotheses.pose_hypotheses` (m unless noted).

    Attributes:
        contact_noise: standard deviation of a contact point about the touched surface.
        transport_noise: standard deviation of a tracked point's motion per metre of it
            (dimensionless): a point placed at a fraction ``alpha`` of the way from where it
            was sensed to where it is tracked (:mod:`~stucco_drake.core.motion_scale`) is
            uncertain by ``transport_noise * alpha * |tracked - sensed|`` (xy) beyond
            ``contact_noise``, as odometry is by a share of the distance travelled.
        other_object_cost: cost (negative log-likelihood, dimensionless) of a point lying on
            another object; a point within ``contact_noise * sqrt(2 other_object_cost)`` of the
            posed target's surface is cheaper on it (2.0: two standard deviations).
        free_space_tolerance: penetration into the robot ignored per (config, point) pair.
        free_space_scale: penetration beyond the tolerance costing one unit.
        temperature: divides the costs before the weights are formed (dimensionless).
        confidence_temperature: divides the costs when the confidence is formed, over every
            scored pose that explains ``min_explained`` points (the grasp is still chosen on
            the weights above). The costs treat each contact point as an independent draw,
            so a few more touches of one object, or of clutter flush with the target, make
            differences of tens of units that are not evidence: tempered, the confidence
            stops saturating at 1 on poses that miss. None (the default): ``temperature``
            over the weighed hypotheses. See ``results/development/README.md``, twentieth
            look, for what 2 and 3 do on the development logs.
        contact_location_noise: standard deviation (m) across a push of where along the
            gripper's front a contact is sensed about where the pose would meet it
            (:mod:`~stucco_drake.core.contact_location`); None (the default): not scored.
        light_force: a contact point sensed in an action whose peak force (N) stayed below
            this lies on an object that gave way more easily than the target does: it is never
            put on the target (:mod:`~stucco_drake.core.pose_hypotheses`). Keep it at most half
            the target's sliding friction force (friction x mass x g), or a target that slid
            would be read as clutter; the builder refuses more. A touch that ends its action
            can meet little force on anything, so a heavy target's own bound is no guide:
            4.9 N is half that of a 2 kg can at friction 0.5. None (the default): forces are
            not used.
        min_explained: fewest contact points the chosen pose must explain for any confidence.
        n_restarts: ICP starts per proposal group.
        outline_spacing: spacing of the outline points ICP fits.
        fill_spacing: spacing of the cross-section points checked against free space, and
            of the outline on which hypotheses are compared (closer ones count as one).
        grid_spacing, grid_yaw: spacing (m, rad) of the grid of poses searched besides the
            ICP proposals, over every placement that could touch a tracked point.
        n_candidates: grid poses with the lowest contact cost kept as candidates.
        n_polish: candidates (lowest full cost) refitted on the points each explains.
        polish_iterations: refits of each (explain, fit, repeat).
        sweep_spacing: spacing of the configs swept along a push that sensed nothing.
        raster_resolution: cell size of the free-space slice.
        grasp_margin, grasp_angle_margin: how much to spare (m, rad) a grasp needs to count
            as closing under a hypothesis when the grasp is chosen and its confidence formed
            (:func:`~stucco_drake.core.grasp_choice.choose_grasp`).
        box_approach: how the grasp of a box goes down: ``"top"`` straight onto the grasp
            point; ``"end"`` beyond the end whose descent keeps the open fingers off the
            clutter felt, then sliding along the box to the grasp point (straight down, then
            the other end, when a descent or a slide is blocked:
            :mod:`~stucco_drake.core.box_approach`); ``"end_aside"`` as ``"end"``, each end's
            descent shifted sideways off the clutter felt beyond it, back in line before
            the slide (:func:`~stucco_drake.core.box_approach.aside_shifts`).
        withdraw_when_blocked: when every attempt of the grasp is blocked, the gripper rises
            without closing rather than pressing down on what stopped it (pressing on can
            tilt the gripper and knock the target away); False (the default) presses on, as
            every table before it was made.
        still_when_unslidable: search only motion scale 0 (the points where sensed) when
            the gripper's push limit cannot slide the target, by its mass and friction
            (:func:`~stucco_drake.core.motion_scale.scales_under_push_limit`); False (the
            default): every scale.
    """

    contact_noise: float = 0.004
    transport_noise: float = 0.15
    other_object_cost: float = 2.0
    free_space_tolerance: float = 0.002
    free_space_scale: float = 0.002
    temperature: float = 1.0
    confidence_temperature: float | None = None
    contact_location_noise: float | None = None
    light_force: float | None = None
    min_explained: int = 3
    n_restarts: int = 20
    outline_spacing: float = 0.002
    fill_spacing: float = 0.005
    grid_spacing: float = 0.01
    grid_yaw: float = np.radians(5.0)
    n_candidates: int = 300
    n_polish: int = 30
    polish_iterations: int = 5
    sweep_spacing: float = 0.005
    raster_resolution: float = 0.0025
    grasp_margin: float = 0.01
    grasp_angle_margin: float = np.radians(5.0)
    box_approach: str = "top"
    withdraw_when_blocked: bool = False
    still_when_unslidable: bool = False

    def __post_init__(self):
        check_box_approach(self.box_approach)
        if self.light_force is not None and not self.light_force > 0:
            raise ValueError(f"light_force: expected > 0 N or None, got {self.light_force!r}")
