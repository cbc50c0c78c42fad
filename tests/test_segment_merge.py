"""The target-pose estimator's unions of two segments (a target cut in two by the segmentation)
and its splits of a segment wider than the target (a target joined to a neighbour)."""

import numpy as np
import pytest

from stucco_drake.core import BoxSdf, CylinderSdf
from stucco_drake.core.icp import transform
from stucco_drake.core.segment_extent import outline_extent, split_wider_segments, xy_extent
from stucco_drake.core.segmentation import connected_components
from stucco_drake.core.target_pose import NoSegmentToFit, estimate_target_pose

#: The BC target cracker box (half extents, m).
CRACKER = BoxSdf((0.0329, 0.079, 0.1037))

#: Scene BC, seed 0, final tracked points (m, world): label 0 a patch on the tomato can, labels
#: 1 and 2 the target box's long side touched near its two ends, 15 cm apart (farther than the
#: segmentation radius). True target pose (0.2504, 0.0498, 1.2171).
BC_TARGET_IN_TWO = np.array(
    [
        [0.1727, 0.2826, 0.1161], [0.1993, 0.2498, 0.1545], [0.1843, 0.2776, 0.1165],
        [0.2194, 0.2295, 0.0980], [0.2078, 0.2303, 0.0976], [0.1819, 0.2826, 0.1165],
        [0.1735, 0.2996, 0.1159], [0.2022, 0.2698, 0.1102], [0.2111, 0.2656, 0.1135],
        [0.3173, -0.0080, 0.1191], [0.3043, -0.0112, 0.1282], [0.2970, -0.0092, 0.1665],
        [0.3165, -0.0080, 0.1933], [0.3120, -0.0079, 0.1786], [0.3139, -0.0096, 0.1884],
        [0.2951, -0.0112, 0.1278], [0.1678, 0.0459, 0.1000], [0.1676, 0.0542, 0.1376],
    ]
)  # fmt: skip
BC_LABELS = np.repeat([0, 1, 2], [9, 7, 2])
BC_TRUTH = np.array([0.2504, 0.0498, 1.2171])


#: Scene BC, seed 5, final tracked points (m, world): label 0 on the master chef can, spread
#: by the tracker (and ReplaceBad's copies) into two clumps that no circle or line fits,
#: label 1 on the tomato can, labels 2 and 3 the target's long side near its two ends. True
#: target pose (0.2503, 0.0498, 1.2111).
BC_SPREAD_CAN = np.array(
    [
        [0.2346, -0.1927, 0.1174], [0.2346, -0.1896, 0.1174], [0.2346, -0.1927, 0.1174],
        [0.2291, -0.2135, 0.1226], [0.2200, 0.2217, 0.1137], [0.2204, 0.2278, 0.1568],
        [0.2162, 0.2201, 0.1134], [0.2377, 0.2045, 0.1164], [0.2200, 0.2217, 0.1137],
        [0.2041, 0.2656, 0.1138], [0.2114, 0.2656, 0.1141], [0.2166, 0.2545, 0.1128],
        [0.2114, 0.2656, 0.1141], [0.2882, -0.1916, 0.1822], [0.2900, -0.1887, 0.1823],
        [0.2343, -0.1858, 0.1174], [0.2343, -0.1858, 0.1174], [0.2346, -0.1927, 0.1174],
        [0.2322, -0.1931, 0.1173], [0.2291, -0.2135, 0.1226], [0.2343, -0.1858, 0.1174],
        [0.2295, -0.1962, 0.1173], [0.2249, -0.2198, 0.1224], [0.2900, -0.1887, 0.1823],
        [0.3197, -0.1853, 0.1825], [0.3102, -0.0055, 0.1214], [0.3038, -0.0137, 0.1187],
        [0.3073, -0.0086, 0.1704], [0.3114, -0.0105, 0.1911], [0.3082, -0.0086, 0.1811],
        [0.3044, -0.0093, 0.1847], [0.3038, -0.0137, 0.1187], [0.1685, 0.0467, 0.1000],
        [0.1668, 0.0509, 0.1374],
    ]
)  # fmt: skip
BC_SPREAD_CAN_LABELS = np.repeat([0, 1, 0, 2, 3], [4, 9, 12, 7, 2])


#: Scene BC, seed 3, STUCCO with the touched-side rule, final tracked points (m, world):
#: label 0 on the master chef can, 1 on the tomato can (with one point that touched
#: nothing), 2 the target's long side near one end and 3 two points near the other end.
#: The cans' points scatter by about 5 mm about any outline. True target pose
#: (0.2502, 0.0498, 1.2082).
BC_SCATTERED_CANS = np.array(
    [
        [0.2610, -0.1932, 0.1158], [0.2602, -0.1910, 0.1158], [0.2619, -0.2123, 0.1293],
        [0.2516, -0.2341, 0.1336], [0.2596, -0.1955, 0.1157], [0.2602, -0.1910, 0.1158],
        [0.2610, -0.1932, 0.1158], [0.2610, -0.1881, 0.1158], [0.2610, -0.1932, 0.1158],
        [0.2458, -0.2107, 0.1161], [0.2515, -0.2290, 0.1336], [0.2458, -0.2107, 0.1161],
        [0.2458, -0.2107, 0.1161], [0.2458, -0.2107, 0.1161], [0.2911, -0.1910, 0.1812],
        [0.3252, -0.1870, 0.1830], [0.2253, 0.2472, 0.1083], [0.2136, 0.2162, 0.1542],
        [0.2253, 0.2523, 0.1083], [0.2431, 0.2107, 0.1155], [0.2380, 0.2152, 0.0986],
        [0.1879, 0.2753, 0.1148], [0.1879, 0.2753, 0.1148], [0.2253, 0.2472, 0.1083],
        [0.2133, 0.2657, 0.1148], [0.2962, -0.0135, 0.1182], [0.3076, -0.0109, 0.1148],
        [0.3125, -0.0085, 0.1835], [0.3179, -0.0059, 0.1897], [0.3125, -0.0085, 0.1835],
        [0.3125, -0.0085, 0.1835], [0.3049, -0.0102, 0.1148], [0.1651, 0.0473, 0.1000],
        [0.1669, 0.0529, 0.1376],
    ]
)  # fmt: skip
BC_SCATTERED_CANS_LABELS = np.repeat([0, 1, 2, 3], [16, 9, 7, 2])

def errors(pose, truth):
    """Position error (m) and yaw error (deg) modulo the box's half turn."""
    yaw = np.degrees(np.angle(np.exp(2j * (pose[2] - truth[2]))) / 2)
    return float(np.linalg.norm(pose[:2] - truth[:2])), abs(float(yaw))


def test_extents():
    assert outline_extent(CRACKER) == pytest.approx(2 * np.hypot(0.0329, 0.079))
    assert xy_extent(np.array([[0.0, 0.0, 5.0], [0.3, 0.4, -1.0], [0.1, 0.1, 0.0]])) == 0.5


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_union_pins_a_target_the_segmentation_cut_in_two(seed):
    """The 7-point end alone leaves the box free to slide along its side (3.8-7 cm off over
    these seeds); joined with the 2 points at the other end, the restarts agree about 15 times
    better and the union is chosen. The remaining 2-3 cm and 20 deg are the tracked points'
    own distortion: they lie up to 9 mm off the true face."""
    merged = estimate_target_pose(np.random.default_rng(seed), BC_TARGET_IN_TWO, BC_LABELS, CRACKER)
    alone = estimate_target_pose(
        np.random.default_rng(seed), BC_TARGET_IN_TWO, BC_LABELS, CRACKER, merge_segments=False
    )
    assert alone.members == (1,) and merged.members == (1, 2) and merged.segment == 1
    # The can is 23 cm and more from the target's points, beyond the box's 17 cm diagonal.
    (union,) = merged.unions
    assert union.members == (1, 2) and union.n_points == 9 and union.consistent
    side = merged.segments[1]
    assert union.position_variance < 0.12 * side.position_variance
    # The single segments are fitted exactly as without unions (same generator draws).
    assert merged.segments == alone.segments
    position, yaw = errors(merged.pose, BC_TRUTH)
    assert position < 0.03 and yaw < 25.0
    assert position < errors(alone.pose, BC_TRUTH)[0] - 0.005


def test_union_with_clutter_the_outline_cannot_explain_loses():
    """A box face and the arc of a 3 cm can standing off its end span less than the box's
    diagonal. The union is rejected twice over: its arc fails the shape test on its own
    (a circle explains it better), and with that test switched off the union's outline
    misfit (6.5 mm RMS over 20 points) still costs it the choice."""
    rng = np.random.default_rng(5)
    truth = np.array([0.3, 0.0, 0.2])
    hx = CRACKER.half_extents[0]
    face = np.column_stack([np.full(12, hx), np.linspace(-0.04, 0.03, 12)])
    angle = np.linspace(np.pi, 1.5 * np.pi, 8)
    arc = np.column_stack([hx + 0.045 + 0.03 * np.cos(angle), 0.09 + 0.03 * np.sin(angle)])
    points = transform(truth[None], np.vstack([face, arc]))[0]
    points = np.column_stack([points + rng.normal(0, 0.001, points.shape), np.full(20, 0.1)])
    labels = np.repeat([0, 1], [12, 8])
    assert xy_extent(points) < outline_extent(CRACKER)
    for threshold in (9.0, np.inf):
        estimate = estimate_target_pose(
            np.random.default_rng(0), points, labels, CRACKER, shape_threshold=threshold
        )
        (union,) = estimate.unions
        assert union.best_rms > 0.005 and union.consistent == (threshold == np.inf)
        assert estimate.members == (0,)
        # One face pins the box's yaw, not where along the face it lies.
        assert errors(estimate.pose, truth)[1] < 3.0


def test_paper_rule_never_merges():
    estimate = estimate_target_pose(
        np.random.default_rng(0), BC_TARGET_IN_TWO, BC_LABELS, CRACKER, selection="paper"
    )
    assert estimate.unions == () and len(estimate.members) == 1


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_outline_evidence_is_capped_at_the_gate(seed):
    """The box's outline explains the spread can's clumps far better than any circle or line
    (excess -52 to -63), which says they are not an arc, not that they are the target: counted
    in full, that evidence would outweigh the target union's 10-fold better spread."""
    estimate = estimate_target_pose(
        np.random.default_rng(seed), BC_SPREAD_CAN, BC_SPREAD_CAN_LABELS, CRACKER
    )
    can = estimate.segments[0]
    assert can.consistent and can.shape_excess < -45.0
    assert estimate.members == (2, 3)
    position, yaw = errors(estimate.pose, np.array([0.2503, 0.0498, 1.2111]))
    assert position < 0.03 and yaw < 30.0


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_outline_misfit_is_judged_at_the_pooled_noise(seed):
    """The cans' tracked points scatter by about 5 mm, so the pooled noise is 5.2 mm. Judged
    at the 2 mm floor instead, the union's 2.1 mm RMS over 9 points cost it 5 nats against
    0.2 for the near end's 7 points alone, which won with an 8 times larger spread and lay
    3-16 cm and 51 deg off (the estimator before the pooled outline term)."""
    estimate = estimate_target_pose(
        np.random.default_rng(seed), BC_SCATTERED_CANS, BC_SCATTERED_CANS_LABELS, CRACKER
    )
    (union,) = estimate.unions
    near_end = estimate.segments[2]
    assert union.members == (2, 3) and union.consistent
    assert 0.0015 < union.best_rms < 0.0025
    assert union.position_variance < 0.2 * near_end.position_variance
    assert estimate.members == (2, 3)
    position, yaw = errors(estimate.pose, np.array([0.2502, 0.0498, 1.2082]))
    assert position < 0.035 and yaw < 25.0


#: The TC target, the tomato can at 1.2 scale (m).
TOMATO = CylinderSdf(radius=0.0384, half_height=0.06)

#: Scene TC, seed 4, STUCCO (`cone`, touched-side rule at 5 mm), final tracked points (m,
#: world), all in one segment: points 0-8 and 18-19 on the master chef can (20 cm across,
#: pushed 12 cm), 9-17 on the target or touching nothing. The nearest target and can points
#: lie 10 cm apart, under the segmentation's 13.5 cm radius. True target pose (0.2271, 0.0576).
TC_TARGET_AND_CAN = np.array(
    [
        [0.1559, -0.0471, 0.1534], [0.1853, -0.0453, 0.1536], [0.1272, -0.1037, 0.1166],
        [0.1394, -0.1150, 0.1168], [0.1257, -0.0995, 0.1777], [0.1178, -0.1189, 0.1071],
        [0.1245, -0.1289, 0.1072], [0.1094, -0.1414, 0.1125], [0.1149, -0.1524, 0.1112],
        [0.1827, 0.0489, 0.0724], [0.1843, 0.0436, 0.1156], [0.1840, 0.0471, 0.0878],
        [0.1839, 0.0507, 0.1154], [0.1845, 0.0570, 0.0930], [0.1827, 0.0489, 0.0724],
        [0.1836, 0.0550, 0.1120], [0.1902, 0.0243, 0.0819], [0.2057, 0.0270, 0.0665],
        [0.1933, -0.1124, 0.1798], [0.1933, -0.1116, 0.1809],
    ]
)  # fmt: skip
TC_TRUTH_XY = np.array([0.2271, 0.0576])


def test_split_wider_segments():
    """Two clumps 12 cm apart in one segment part at an 8 cm reach; the new part takes the
    next free label. A chain of points 5 cm apart spanning 20 cm links throughout and keeps
    its label, as do a narrow segment and noise (negative labels)."""
    clump = np.array([[0.0, 0.0, 0.1], [0.02, 0.0, 0.1], [0.0, 0.02, 0.12]])
    chain = np.column_stack([np.linspace(0.5, 0.7, 5), np.zeros(5), np.full(5, 0.1)])
    far = clump + np.array([0.12, 0.0, 0.0])
    points = np.vstack([clump, far, chain, [[1.0, 1.0, 0.1]], [[2.0, 0, 0]]])
    labels = np.array([3, 3, 3, 3, 3, 3, 0, 0, 0, 0, 0, 5, -1])
    split = split_wider_segments(points, labels, 0.08)
    assert split.tolist() == [3, 3, 3, 6, 6, 6, 0, 0, 0, 0, 0, 5, -1]
    assert labels.tolist() == [3, 3, 3, 3, 3, 3, 0, 0, 0, 0, 0, 5, -1]  # not modified
    assert split_wider_segments(points, labels, 0.15).tolist() == labels.tolist()


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_split_frees_a_target_the_segmentation_joined_to_a_can(seed):
    """Fitted whole, the 20-point cloud draws the 7.7 cm can 11-12 cm from where it stands;
    split at the can's reach (its diameter plus 3 noise widths), the target's own part is
    chosen and the estimate is within 1.5 cm. Linked in plan only, the two cans' points
    would chain (a can point above the target's contacts' height overlaps them in plan), so
    the parts link in 3-D as the segmentation does."""
    labels = np.zeros(len(TC_TARGET_AND_CAN), dtype=np.int64)
    whole = estimate_target_pose(
        np.random.default_rng(seed), TC_TARGET_AND_CAN, labels, TOMATO, split_segments=False
    )
    split = estimate_target_pose(np.random.default_rng(seed), TC_TARGET_AND_CAN, labels, TOMATO)
    assert np.linalg.norm(whole.pose[:2] - TC_TRUTH_XY) > 0.08
    assert np.linalg.norm(split.pose[:2] - TC_TRUTH_XY) < 0.015
    reach = outline_extent(TOMATO) + 3 * 0.002
    assert xy_extent(TC_TARGET_AND_CAN) > reach
    assert split.labels.tolist() == [0] * 9 + [1] * 9 + [0] * 2
    assert split.members == (1,) and len(split.segments) == 2
    assert connected_components(TC_TARGET_AND_CAN[:, :2], reach).max() == 0
    assert whole.labels.tolist() == labels.tolist()


def test_paper_rule_never_splits():
    labels = np.zeros(len(TC_TARGET_AND_CAN), dtype=np.int64)
    estimate = estimate_target_pose(
        np.random.default_rng(0), TC_TARGET_AND_CAN, labels, TOMATO, selection="paper"
    )
    assert estimate.labels.tolist() == labels.tolist() and len(estimate.segments) == 1


def test_a_segment_wider_than_the_target_in_small_pieces_has_nothing_to_fit():
    # One segment of four points 40 cm apart: wider than the cracker box (17 cm across its
    # diagonal), so it is split, and no piece holds three points. The live estimator keeps
    # its last estimate on this error; a log's grasp gets no estimate.
    points = np.array([[0.4 * k, 0.0, 0.1] for k in range(4)])
    with pytest.raises(NoSegmentToFit, match="no segment has at least 3 points"):
        estimate_target_pose(np.random.default_rng(0), points, np.zeros(4, dtype=int), CRACKER,
                             min_points=3)
