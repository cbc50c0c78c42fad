"""A grasp at the target's true final pose (``bor.log.grasp_true_pose``, ``stucco-drake
estimates --grasp-truth``): what an episode's end allows a perfect estimate; and a grasp made
again at the estimate with other settings (``--regrasp``). Checked on committed development
logs against the layouts' own geometry: where no other object stands in the open fingers'
footprints the box is lifted; where a can stands in one, a finger going straight down lands on
it and the box is not, and going down beyond the box's end lifts it."""

import csv
import shutil
from pathlib import Path

import numpy as np

from stucco_drake.bor.log import grasp_true_pose
from stucco_drake.cli import main
from stucco_drake.eval.episode_log import EpisodeLog

ROOT = Path(__file__).resolve().parents[1]
#: The twenty-eighth look's belief runs, stopped at 24 actions.
SOURCE = ROOT / "results" / "development" / "belief_loc_24_b"
LAYOUTS = ROOT / "results" / "layouts" / "development"


def _finger_room(log: EpisodeLog) -> float:
    """The least signed distance (m) from any other movable object, extruded, to the open
    fingers' footprints at a grasp over the box's centre across its short side: each finger
    from 5.5 cm (the open bubble's apex) to 10 cm (its backing plate's back) out along the
    closing axis, 8 cm wide (the bubble gripper's drawing). Negative: an object stands there."""
    x, y, yaw = log.object_poses[-1, 0]
    spec = log.object_shapes[log.shape_object == 0][0]
    closing = yaw + (0.0 if spec[1] <= spec[2] else np.pi / 2)
    u = np.array([np.cos(closing), np.sin(closing)])
    v = np.array([-u[1], u[0]])
    out, across = np.meshgrid(np.linspace(0.055, 0.1, 10), np.linspace(-0.04, 0.04, 17))
    points = np.concatenate([(x, y) + side * out.reshape(-1, 1) * u + across.reshape(-1, 1) * v
                             for side in (1.0, -1.0)])  # fmt: skip
    points = np.column_stack([points, np.zeros(len(points))])
    movable = [k for k, name in enumerate(log.object_names)
               if k > 0 and not any(w in str(name) for w in ("wall", "table", "pedestal"))]
    return min(float(surface(points).min())
               for surface, k in zip(log.final_surfaces(), log.shape_object, strict=True)
               if k in movable)  # fmt: skip


def _table_of(source: Path, log_name: str, folder: Path) -> None:
    """Makes ``folder`` a table folder holding one log of the table folder ``source``."""
    (folder / "logs").mkdir()
    shutil.copy(source / "logs" / log_name, folder / "logs")
    for name in ("table_config.yaml", "runs.csv"):
        shutil.copy(source / name, folder / name)


def test_a_box_with_room_beside_it_is_lifted_at_its_true_pose():
    log = EpisodeLog.load(SOURCE / "logs" / "FB-L1006_0.npz")
    assert _finger_room(log) > 0.0  # 5 mm to the potted meat can
    result = grasp_true_pose(log, LAYOUTS / "FB-L1006.yaml")
    assert result.success and result.lift_height >= 0.05, result.reason


def test_a_box_flush_against_a_can_is_not_lifted_and_the_table_says_so(tmp_path, capsys):
    """IB-L1008 at 24 actions: the double-size tomato can (6.4 cm radius) stands 6 cm into
    one finger's footprint. Without the layout's file the command refuses in one line; with
    it, the row says the true pose's grasp failed."""
    log = EpisodeLog.load(SOURCE / "logs" / "IB-L1008_0.npz")
    assert _finger_room(log) < -0.05
    _table_of(SOURCE, "IB-L1008_0.npz", tmp_path)
    assert main(["estimates", "--table", str(tmp_path), "--grasp-truth"]) != 0
    assert capsys.readouterr().err.strip().splitlines() == [
        "stucco-drake estimates: error: --grasp-truth: no scene file for IB-L1008; give it, "
        "or its folder, with --scenes"]
    assert main(["estimates", "--table", str(tmp_path), "--grasp-truth", "--scenes",
                 str(LAYOUTS / "IB-L1008.yaml")]) == 0  # fmt: skip
    with (tmp_path / "estimates_stucco_grasp_truth.csv").open(encoding="utf-8") as file:
        (row,) = list(csv.DictReader(file))
    assert row["scene"] == "IB-L1008" and row["true_pose_grasped"] == "False"


def test_the_box_flush_against_a_can_is_lifted_when_approached_beyond_its_end():
    """The same IB-L1008 end, the box gone down on beyond an end and slid along
    (``box_approach="end"``): the open fingers pass either side of the box and the one beside
    the can shoves it along; the box is lifted (the can's footprint overlap as above)."""
    log = EpisodeLog.load(SOURCE / "logs" / "IB-L1008_0.npz")
    result = grasp_true_pose(log, LAYOUTS / "IB-L1008.yaml", box_approach="end")
    assert result.success and result.lift_height >= 0.05, result.reason
    assert result.geometric_ok, result.reason


def test_regrasp_measures_a_grasp_only_change_on_the_same_episode(tmp_path):
    """IB-L1010 of the thirtieth look (``box_approach: end`` in the loop): the hypotheses' pose
    closes on the box by the paper's criterion (``hypotheses_closes``, against the true final
    pose), and the double-size can stands 5.7 cm into a finger's footprint there. Grasped
    again from the same end, straight down the finger lands on the can and the box is not
    lifted; beyond its end it is."""
    source = ROOT / "results" / "development" / "belief_r1_end_24_b"
    log = EpisodeLog.load(source / "logs" / "IB-L1010_0.npz")
    assert _finger_room(log) < -0.05
    _table_of(source, "IB-L1010_0.npz", tmp_path)
    rows = {}
    for approach in ("top", "end"):
        settings = ROOT / "results" / "development" / f"box_approach_{approach}.yaml"
        assert main(["estimates", "--table", str(tmp_path), "--regrasp", "--hypothesis-params",
                     str(settings), "--scenes", str(LAYOUTS / "IB-L1010.yaml")]) == 0
        path = tmp_path / f"estimates_stucco_box_approach_{approach}_regrasp.csv"
        with path.open(encoding="utf-8") as file:
            (rows[approach],) = list(csv.DictReader(file))
    assert rows["end"]["hypotheses_closes"] == rows["top"]["hypotheses_closes"] == "True"
    assert rows["top"]["regrasped"] == "False" and rows["end"]["regrasped"] == "True"


def test_grasp_truth_is_refused_where_it_cannot_apply(tmp_path, capsys):
    _table_of(SOURCE, "IB-L1008_0.npz", tmp_path)
    for extra, message in (
        (["--grasp-truth", "--after-actions", "12"],
         "--grasp-truth: not with --after-actions (a log holds the plant's state only at its "
         "end)"),
        (["--regrasp", "--after-actions", "12"],
         "--regrasp: not with --after-actions (a log holds the plant's state only at its end)"),
        (["--scenes", str(LAYOUTS / "IB-L1008.yaml")],
         "--scenes: only with --grasp-truth or --regrasp"),
    ):
        assert main(["estimates", "--table", str(tmp_path), *extra]) != 0
        assert capsys.readouterr().err.strip().splitlines() == [
            f"stucco-drake estimates: error: {message}"]
    assert not list(tmp_path.glob("estimates_*.csv"))
