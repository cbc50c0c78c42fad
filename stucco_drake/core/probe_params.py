"""The settings of the guarded face probes (:class:`~stucco_drake.core.probing.FaceProbePolicy`)."""

from __future__ import annotations

import dataclasses

import numpy as np


@dataclasses.dataclass(frozen=True)
class ProbeParams:
    """Settings of :class:`FaceProbePolicy` (m unless noted).

    Attributes:
        standoff: gap between the gripper's footprint and the hypothesised face at the
            stand-off point.
        clearance: extra room around the hypothesised target when travelling past it.
        travel_step: longest step while travelling and approaching (a bump pushes what it
            meets by up to a step: less than the controller's own clip).
        approach_step: planar step per action towards the face.
        overshoot: how far past the hypothesised face the approach goes before giving up.
        back_off: step away from the face after a touch.
        arrive_tolerance: distance at which a travel waypoint counts as reached.
        max_actions: actions the probing may take in all.
        max_bumps: contacts while travelling to one probe (each backed off from and the
            probe planned again) before that probe is given up.
        direct_only: make only the probes whose stand-off point the gripper reaches in a
            straight line, clear of the hypothesised target: going round it leads into
            clutter nothing has been sensed of.
        long_face_offsets: where along a box's long face (fractions of its half length) it
            is touched.
        cylinder_angles: directions (rad) either side of the gripper's from which a cylinder
            is touched.
        end_face_first: touch a box's nearer short face before its long face (default:
            after). A box the script turned about the corner nearest the gripper keeps that
            corner on the believed long face, where the long-face touches meet it; its short
            face is where the turn shows (``results/development/README.md``, tenth look).
        discriminate: choose each probe where the pose hypotheses disagree on its outcome
            (:mod:`~stucco_drake.core.probe_choice`), among the faces of the likeliest
            ``max_rivals`` hypotheses apart from one another, while one gains at least
            ``min_gain`` nats; then the likeliest pose's probes as without it. At most
            ``max_probes`` probes in all. On by default since the development layouts'
            thirteenth look (``results/development/README.md``); off: the likeliest pose's
            probes in a fixed order, as every probe-policy folder before
            ``results/report_layouts_3/`` was made.
        rival_temperature: divides the hypotheses' cost differences when the gain is judged.
        outcome_tolerance: approach distances counting as one outcome.
        extent_margin: keep the gripper's origin out of the hypothesised target grown by the
            footprint's extent along the target's own axes (and start the approach that far
            out along the face's normal), instead of by the footprint's radius on every side.
            Both keep the footprint off the target; the extent is the tighter for a
            footprint longer than it is wide, and shortens every travel and approach. Off:
            as every probe-policy folder before the development layouts' eighteenth look.
        face_step: with ``discriminate``, the candidate touches of each rival box are every
            face's, the gripper's origin every ``face_step`` along it out to where its
            footprint just overlaps the face, nearest travel first
            (:func:`~stucco_drake.core.probe_choice.face_probe_points`): the touch beside an
            end face where a turned box would stand is among them. None (the default): the
            probes :func:`plan_probes` makes of each, as every folder before the development
            layouts' thirty-first look.
        felt_obstacles: with ``discriminate``, every hypothesis's outcome of a probe counts
            what was felt as standing where it was felt (the hypotheses' ``felt`` points):
            a probe through it, whose outcome is known already, gains nothing. Off (the
            default): only the posed target is met, as every folder before the development
            layouts' thirty-second look.
        gain_per_action: with ``discriminate``, choose the probe of most gain per action it
            takes (its travel, approach and retreat) rather than of most gain: under a budget
            of actions a near touch that tells fewer hypotheses apart may be worth more than
            a far one. The gain itself must still reach ``min_gain``.
    """

    standoff: float = 0.02
    clearance: float = 0.03
    travel_step: float = 0.02
    approach_step: float = 0.01
    overshoot: float = 0.03
    back_off: float = 0.02
    arrive_tolerance: float = 0.005
    max_actions: int = 40
    max_bumps: int = 1
    direct_only: bool = True
    long_face_offsets: tuple[float, ...] = (-0.5, 0.5)
    cylinder_angles: tuple[float, ...] = (np.pi / 4, -np.pi / 4)
    end_face_first: bool = False
    discriminate: bool = True
    max_rivals: int = 6
    rival_temperature: float = 5.0
    outcome_tolerance: float = 0.015
    min_gain: float = 0.1
    max_probes: int = 6
    extent_margin: bool = False
    face_step: float | None = None
    felt_obstacles: bool = False
    gain_per_action: bool = False

    @property
    def action_budget(self) -> int:
        """The most actions a run may take (``max_actions``; as ``RummageParams``')."""
        return self.max_actions

    def __post_init__(self):
        if self.face_step is not None and not self.face_step > 0:
            raise ValueError(f"face_step: expected a positive step (m) or null, "
                             f"got {self.face_step!r}")
