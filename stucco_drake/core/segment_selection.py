"""The steps of :func:`~stucco_drake.core.target_pose.estimate_target_pose`, in its order.

:func:`candidate_groups` (segments, split and joined against the target's size),
:func:`fit_groups` (ICP of each), :func:`shape_evidence` (the shape test),
:func:`choose_segment` (the segment selection rule) and :func:`restart_scores` (the robot
penetration that picks a restart of the chosen segment). Each step's docstring gives its
reasons and the measurements behind them.

These rules were chosen on Table II's own episodes (the seeds their docstrings cite): they fit
those four layouts, and on randomized ones they do not carry over. They are kept to reproduce
``results/table_ii`` (``--target-estimator rules``); the grasps default to the weighted pose
hypotheses (:mod:`~stucco_drake.core.pose_hypotheses`), developed on the development layouts.

Frames and units: contact points and end-effector configs in the world frame W (m); poses
(x, y, yaw) of the target's shape frame O in W (m, m, rad). A candidate group is named by
its members, the tuple of the segment labels whose points it holds (one, or two for a union).
"""

from __future__ import annotations

import dataclasses
import itertools

import numpy as np

from stucco_drake.core.icp import IcpResult, icp_2d
from stucco_drake.core.outline_fit import pooled_noise_variance, shape_excess, shape_sse
from stucco_drake.core.penetration import RobotPenetration
from stucco_drake.core.pose_penetration import penetration_window, restart_penetration
from stucco_drake.core.segment_extent import outline_extent, split_wider_segments, xy_extent
from stucco_drake.core.shapes import BoxSdf, CylinderSdf

#: A candidate group's name: the labels of the segments whose points it holds.
Members = tuple[int, ...]


@dataclasses.dataclass(frozen=True)
class GroupFit:
    """ICP of one candidate group.

    Attributes:
        spread: sum of the unbiased variances of the restarts' x and y (m^2).
        result: every restart's pose and RMS.
        height: the group's mean contact height (m, world z), where the model is posed for
            the penetration check.
        sums: (outline SSE (m^2), best circle-or-line SSE (m^2), point count), the row
            :func:`~stucco_drake.core.outline_fit.shape_excess` takes.
    """

    spread: float
    result: IcpResult
    height: float
    sums: tuple


@dataclasses.dataclass(frozen=True)
class ShapeEvidence:
    """The shape test over the fitted groups (see :func:`shape_evidence`).

    Attributes:
        noise_variance: the sensor's noise variance (m^2), pooled over the fitted segments.
        excess: members -> shape excess (dimensionless); a union's is its fitted members' sum.
        consistent: members -> whether the group passed the test.
    """

    noise_variance: float
    excess: dict
    consistent: dict


def candidate_groups(points, labels, shape: BoxSdf | CylinderSdf, contact_noise: float,
                     min_points: int, *, split: bool, merge: bool):  # fmt: skip
    """(labels, groups, singles): the candidate groups' points (m, W) by members.

    ``singles`` are the segments (label >= 0; negative labels are noise). With ``merge`` the
    union of any two segments whose points span no more than the target's cross-section can
    (:func:`outline_extent` plus 3 ``contact_noise``, the reach) is a candidate too, fitted
    and scored like a segment. The segmentation knows nothing of the target: touched only at
    the two ends of a 16 cm side, a box becomes two segments farther apart than the
    segmentation radius, and either alone leaves the box free to slide along that side. A
    union the outline explains as well pins it (a low spread); one it does not pays for its
    misfit in the outline term (:func:`choose_segment`).

    With ``split`` it works the other way too: a segment whose points span more than that
    reach cannot be the target alone, so it is replaced by its parts, the groups of its points
    that link at the reach (:func:`split_wider_segments`; the returned ``labels``, new parts
    numbered from the largest label + 1), before anything is fitted. The segmentation links
    points closer than its radius (13.5 cm with the paper's l = 0.02 and p_c = 0.4), wider
    than a small target: in scene TC the pushed master chef can's contacts end 10.6-17.9 cm
    from the tomato can's, so the two share a segment in 4 of 20 episodes even with every
    point tracked exactly, and ICP then fits the 7.7 cm can into a 20 cm cloud. Measured on
    the Drake BOR logs (TC, STUCCO with `cone` and the touched-side rule at 5 mm, the 7 merged
    runs of 20) the target's position error fell from 9.9-11.8 cm to 0.4-0.9 cm. A part that
    still spans more than the reach is kept whole: nothing in it links at less. A box target
    is wider than the segmentation radius, so STUCCO's (and DBSCAN's, single linkage at
    5 cm) segments of a box scene are never split.
    """
    reach = outline_extent(shape) + 3.0 * contact_noise
    if split:
        # The segmentation joins the target to a neighbour closer than its linking radius
        # (13.5 cm with the paper's l and p_c: TC's 7.7 cm tomato can beside a pushed 20 cm
        # can); a segment wider than the target cannot be the target alone, its parts can.
        labels = split_wider_segments(points, labels, reach)
    groups = {(int(label),): points[labels == label] for label in np.unique(labels[labels >= 0])}
    singles = list(groups)
    if merge:
        # The segmentation cuts the target in two when it was touched at places farther apart
        # than the segmentation radius (a 16 cm box side touched at both ends); any two
        # segments that together fit within the target's extent compete as one.
        for first, second in itertools.combinations(singles, 2):
            union = np.concatenate([groups[first], groups[second]])
            if len(union) >= min_points and xy_extent(union) <= reach:
                groups[first + second] = union
    return labels, groups, singles


def fit_groups(rng: np.random.Generator, groups: dict, model, shape: BoxSdf | CylinderSdf,
               min_points: int, *, n_restarts: int, max_iterations: int, tolerance: float,
               initial_pose, start: str) -> dict[Members, GroupFit]:  # fmt: skip
    """Members -> :class:`GroupFit` of every group with at least ``min_points`` points.

    Each is fitted by :func:`~stucco_drake.core.icp.icp_2d` with ``n_restarts`` starts against
    the target's ``model`` outline (m, 2, frame O) at contact height (three contacts are the
    fewest that can pin a planar pose), drawing from ``rng`` in the groups' order.
    """
    fits = {}
    for members, group in groups.items():
        if len(group) < min_points:
            continue
        result = icp_2d(
            rng, group[:, :2], model, n_restarts, max_iterations, tolerance, initial_pose, start
        )
        spread = float(np.sum(np.var(result.poses[:, :2], axis=0, ddof=1)))
        sse = shape_sse(group[:, :2], result.poses, shape)
        # The model is posed at the segment's mean contact height for the penetration check.
        fits[members] = GroupFit(spread, result, float(group[:, 2].mean()), (*sse, len(group)))
    return fits


def shape_evidence(fits: dict[Members, GroupFit], singles: list[Members], selection: str,
                   contact_noise: float, shape_threshold: float) -> ShapeEvidence:  # fmt: skip
    """The shape test of every fitted group (with ``selection="paper"`` every group passes).

    With ``selection="shape"``, segments whose points a circle or a line explains much better
    than the target's outline are set aside: the segment's :func:`shape_excess`, a
    log-likelihood-ratio statistic with a noise scale pooled over the segments and floored at
    ``contact_noise`` (m), must not exceed ``shape_threshold`` (9: a likelihood ratio of
    e^4.5, about 90, or 3 sigma; both fits have 3 parameters, so no complexity penalty is
    needed). A union is not compared with a circle or line (two patches of one box need not
    lie on one curve); it carries its members' shape evidence instead: each fitted member must
    pass the test, and its statistic is theirs summed.
    """
    fitted = [members for members in singles if members in fits]
    # One noise model for the whole estimate: the sensor's, pooled over the segments.
    sums = [fits[m].sums for m in fitted]
    noise_variance = pooled_noise_variance(sums, contact_noise) if fitted else contact_noise**2
    statistics = shape_excess(sums, contact_noise, noise_variance) if fitted else []
    excess = dict(zip(fitted, statistics, strict=True))
    consistent = {
        members: selection == "paper" or bool(excess[members] <= shape_threshold)
        for members in fitted
    }
    for members in fits.keys() - excess.keys():
        # Two patches of one box need not lie on one circle or line, so comparing a union with
        # a curve says nothing (an L-shaped face and a can arc fit none: a large, meaningless
        # negative excess). A union carries its members' own evidence: each fitted member must
        # pass the test, and their statistics add (independent points, log-likelihoods add).
        own = [(label,) for label in members if (label,) in excess]
        excess[members] = float(sum(excess[m] for m in own))
        consistent[members] = all(consistent[m] for m in own)
    return ShapeEvidence(noise_variance, excess, consistent)


def choose_segment(fits: dict[Members, GroupFit], evidence: ShapeEvidence, selection: str,
                   shape_threshold: float) -> Members:  # fmt: skip
    """The members of the group taken as the target.

    ``selection="paper"``: the group whose restarts' positions vary least (sum of unbiased x
    and y variances, m^2), as in the paper; also when every group failed the shape test.
    Position, not yaw, is compared, so a box's 180-degree symmetry does not count as spread.
    ``selection="shape"``: of the groups kept, the one with the lowest
    ``max(shape_excess, -shape_threshold) / 2 + ln(variance) + sse / (2 sigma^2)``: the
    paper's spread, the shape evidence (a log-likelihood ratio) and the target outline's own
    fit (its negative log-likelihood under the sensor's noise, ``sse`` the outline's squared
    residuals, m^2, sigma^2 the noise variance pooled by :func:`shape_evidence`) as
    log-scores, so a segment the box explains e-fold better than a curve may have an e-fold
    larger spread, and a segment the outline misses by several noise widths loses to one it
    fits to within the noise. Evidence for the outline counts up to the threshold only: it
    says a segment is not an arc or a line, not which of the segments that are not is the
    target. Uncapped, tracked points on a can that the tracker had spread into no curve's
    shape won on it alone (scene BC, seeds 1 and 5: excess -61 and -59 on cans; IB seed 5).

    Why the shape test is the default: the variance rule measures how well ICP pins a pose, not
    whether the segment is the target. A long arc of a large can pins a box better (a box corner
    wraps a 1.6 rad arc of a 10 cm can, restarts agreeing within ~3-4 cm) than a few contacts on
    one face of the true box, along which the box slides, so the paper's rule returns the can
    (scene BC, seed 0: the 32-point can segment, 23 cm from the target). A gate on the ICP RMS
    alone cannot tell them apart at a few millimetres of noise (there: 6.2 mm on the can, whose
    points scatter by 5.5 mm about their best circle). The residuals of a box on an arc are
    structured, though: a circle explains them better, and judged against the sensor's noise
    pooled over all segments (2.2 mm there) rather than the arc's own scatter, the evidence is
    decisive (statistic 48 on the can; -5.5 and -0.2 on the target's face and a tomato can;
    ~30-100 against ~0 for 1 mm synthetic arcs and faces). Clutter that the target's outline
    fits as well as a circle or a line does (another box, a small can's short arc, a flat face)
    passes the gate. Among what passes, the variance alone is a near coin flip when the
    target is touched on a few points (BC: an 11-point L-shaped patch of the tomato can,
    excess -0.2, spread 3.2e-3 m^2, beat the target's 8 points, excess -5.5, spread
    4.0e-3 m^2); the shape evidence breaks such ties (score -5.9 against -8.3 for the target),
    while clear differences in spread still decide between segments of equal evidence.
    The outline's own fit settles a case both miss (scene TC, seed 0): a 12-point cloud of
    tracked points on a large can, which neither the target's 3.8 cm circle nor any curve fits
    (8.5 mm RMS), had the lower spread (4.6e-4 against 1.5e-3 m^2 for the 7 target points
    fitted to 1.4 mm) and an excess near 0; its outline term, SSE / (2 sigma^2) with the
    pooled 7.0 mm noise, decides (8.8 against 0.13 for the target). On the Drake BOR logs
    (seeds 0-5, STUCCO) the target estimate was within 2 cm in 6 of 6 TC runs with this term
    and 3 of 6 without; FB, IB and BC kept their choices or improved (BC median position
    error 28 -> 12 cm).

    The outline term's sigma is the pooled one, not the floor ``contact_noise``: one noise
    model for the whole estimate. Tracked points scatter more than the sensor's contacts (the
    tracker moves them), and a term at the floor charged every point of a candidate for
    that scatter, so fewer points won: scene BC, seed 3 (touched-side rule), the box's near
    end alone (7 points, spread 4.9e-3 m^2, 16 cm off) beat its union with the far end's 2
    points (spread 6.0e-4 m^2, 2.1 mm RMS) on outline terms of 0.2 against 5.0 at 2 mm; at
    the pooled 5.2 mm they are 0.03 and 0.7 and the union (2.9 cm off) is taken. Over the
    Drake BOR logs of the four scenes, 20 seeds, every method and both contact motions (960
    estimates) the choice changed in 103, 50 of them in BC, mostly to such a union.

    Every case above is an episode of the paper's own layouts, the runs Table II reports: the
    rule was fitted on them, and its Table II results are not held out. On the report
    layouts' scripted episodes its estimate closes on the target in 19 of 80 runs, the weighted
    pose hypotheses' (developed on development layouts, the grasps' default) in 34 of 80
    (``results/report_layouts/estimates_stucco.csv``). It stays for reproducing Table II.
    """
    excess, noise_variance = evidence.excess, evidence.noise_variance
    candidates = [members for members in fits if evidence.consistent[members]]
    if selection == "paper" or not candidates:
        # With every segment inconsistent the shape says nothing about which one is the target.
        return min(fits, key=lambda members: fits[members].spread)
    # All criteria as log-scores: half the shape statistic is a log-likelihood ratio, the
    # log makes the variance scale-free, so a factor in spread trades against a factor in
    # likelihood, and the outline's SSE over the known noise is its own negative log
    # likelihood. The last is what rejects a scattered cloud: the relative test pools its
    # noise over the segments, so a cloud no model fits inflates the pool and passes, and
    # a small circle slid into it converges to one place (a low spread). It also keeps a
    # union honest: joining a segment the outline cannot also explain costs its misfit.
    # The shape evidence is capped where the gate is (see the docstring).
    # The variance is floored to keep a degenerate spread from being -inf.
    return min(
        candidates,
        key=lambda members: (
            0.5 * max(excess[members], -shape_threshold)
            + np.log(max(fits[members].spread, 1e-12))
            + 0.5 * fits[members].sums[0] / noise_variance
        ),
    )


def restart_scores(
    fit: GroupFit, fill, n_restarts: int, penetration: RobotPenetration | None, configs,
    config_rotation, touched, *, penetration_configs, penetration_tolerance: float,
    touch_tolerance: float | None,
) -> np.ndarray:  # fmt: skip
    """(n_restarts,) each restart's summed robot penetration (m); zeros without
    ``penetration`` or ``configs`` (the restart is then chosen by RMS alone).

    The caller takes the restart that penetrates the end-effector configs least, ties
    (typically several restarts that penetrate nothing) broken by the lowest ICP RMS. This
    is the paper's rule; the authors' code instead takes the smallest |min signed distance|
    to the gripper (closest to just touching) with no RMS tie-break.

    Penetration is the robot's own: :class:`RobotPenetration` depth of the posed target's
    cross-section (``fill``: outline plus interior, m, frame O, at the group's height) at every
    config (``configs`` (k, 3) in W, oldest first, one ``config_rotation`` R_WE), summed
    beyond ``penetration_tolerance`` (m) per pair. The robot's geometry is used, not the
    target's SDF at the config origins, because the gripper reaches centimetres beyond its
    origin: a pose lying across the fingers must count. The tolerance (default: the sim's
    intersection tolerance) forgives the millimetres a correct, touching pose sinks into the
    gripper through contact noise, so such poses tie at zero and the ICP error decides between
    them. ``penetration_configs`` picks which configs count (see :func:`penetration_window`):
    ``"all"`` as the authors' code, ``"latest"`` (x_t only) as the paper's text, or
    ``"since_touch"``, a deviation: only the configs from the chosen segment's last contact
    on (``touched``: the config index of each of its points). The target may have been pushed
    since an earlier config, which then overlaps where it lies now and rejects the true pose.
    Measured on the Drake BOR episodes FB, BC, IB (seeds 0-2) with the true target contacts
    projected onto its final surface and segmented correctly (so only this rule is tested),
    the position error was 4.6-6.6 cm with all configs (about 90 deg off in 7 of 9), 0.0-7.3 cm
    with x_t alone (too few configs to rule out the mirror image of a touched face: 6.6 and
    7.3 cm on BC) and 0.0-3.3 cm since the last touch (yaw within 1 deg in all 9).

    The configs left out of that window at which the chosen segment's points were sensed
    (``touched``) still count, forgiving ``touch_tolerance`` (m) per pair instead (None: they
    do not count): the robot touched the target there, so the target's surface was at the
    robot's then, and it can overlap that config now only by as much as it has moved since.
    A target pushed further than that is the case the window is for; one that was only rocked
    or nudged keeps the evidence of every face the robot slid along. Configs at which the robot
    touched nothing of the segment stay out (the target may have been pushed into where the
    robot once swept). Measured on the Drake BOR logs (20 seeds of each scene, STUCCO with
    the `normal` contact motion and the touched-side rule): scene FB's 10 kg box, rocked
    about 6 mm by each push, was within 4 cm and 12 deg in 8 of 20 runs with the window alone
    (ICP turned the box across the cloud of its face's tracked points in the rest, and the
    configs since its last touch, all at its narrow end, did not rule that out), and in 11,
    12, 11 and 8 with the touched configs at 5, 10, 15 and 20 mm. The other scenes' estimates
    were as good or better (BC within 4 cm and 25 deg: 13 -> 14 of 20). Its grasps in the
    tables: 8 -> 14 of 20 on FB, 13 -> 14 on BC (5 -> 10 on FB without the rule); of the 960
    runs of every method, 223 estimates changed and 40 grasps, 34 of them gains.
    """
    scores = np.zeros(n_restarts)
    if penetration is None or configs is None:
        return scores

    def penetrating(selected, tolerance):
        return restart_penetration(
            penetration, fit.result.poses, fill, fit.height, configs[selected], config_rotation,
            tolerance,
        )  # fmt: skip

    window = penetration_window(len(configs), penetration_configs, touched)
    scores = penetrating(window, penetration_tolerance)
    if touch_tolerance is not None and touched is not None:
        # Points sensed after the last config passed belong to it (as in the window).
        earlier = np.unique(np.minimum(touched, len(configs) - 1))
        earlier = earlier[earlier < window.start]
        scores = scores + penetrating(earlier, max(touch_tolerance, penetration_tolerance))
    return scores
