"""A logged episode cut after its first k actions (``EpisodeLog.first``, ``stucco-drake
estimates --after-actions``): what a policy stopping there would have had, counted
independently, action by action, from the whole log."""

import shutil
from pathlib import Path

import numpy as np
import pytest

from stucco_drake.cli import main
from stucco_drake.eval.episode_log import EpisodeLog

#: A committed development log: TC-L1001 with the probing finish, 42 actions, 24 contacts.
SOURCE = Path(__file__).resolve().parents[1] / "results" / "development" / "probe"
LOG = SOURCE / "logs" / "TC-L1001_0.npz"


def test_a_cut_holds_the_contacts_sensed_and_the_poses_reached_by_then():
    log = EpisodeLog.load(LOG)
    for k in (1, 17, log.n_actions):
        cut = log.first(k)
        assert cut.n_actions == k
        # The contacts of actions 0..k-1, gathered one action at a time from the whole log.
        points = [log.contacts(t)[0] for t in range(k)]
        objects = [log.contacts(t)[2] for t in range(k)]
        np.testing.assert_array_equal(cut.contact_points, np.concatenate(points))
        np.testing.assert_array_equal(cut.contact_object, np.concatenate(objects))
        assert [len(cut.contacts(t)[0]) for t in range(k)] == [len(p) for p in points]
        # The objects where they stood at the end of action k: the truth a stop there faces.
        np.testing.assert_array_equal(cut.object_poses[-1], log.object_poses[k])
        np.testing.assert_array_equal(cut.ee_position[-1], log.ee_position[k - 1])
        assert cut.final_state.shape == (0,) and cut.info["first_actions"] == k
    with pytest.raises(ValueError, match="actions: expected 1 to 42, got 43"):
        log.first(43)


def test_estimates_after_actions_scores_each_cut_and_the_last_as_the_whole(tmp_path):
    """Rows per cut, in order, each counting the target contacts of its first k actions (by
    hand from the log); the cut at the log's length scores what the whole episode does, and a
    cut beyond it is left out."""
    (tmp_path / "logs").mkdir()
    shutil.copy(LOG, tmp_path / "logs")
    for name in ("table_config.yaml", "runs.csv"):
        shutil.copy(SOURCE / name, tmp_path / name)
    assert main(["estimates", "--table", str(tmp_path)]) == 0
    whole = _rows(tmp_path / "estimates_stucco.csv")[0]
    assert main(["estimates", "--table", str(tmp_path), "--after-actions", "42", "12",
                 "60"]) == 0  # fmt: skip
    rows = _rows(tmp_path / "estimates_stucco_after_12_42_60.csv")
    log = EpisodeLog.load(LOG)
    assert [int(row["after_actions"]) for row in rows] == [12, 42]
    for row in rows:
        k = int(row["after_actions"])
        on_target = sum(int(np.sum(log.contacts(t)[2] == 0)) for t in range(k))
        assert int(row["target_contacts"]) == on_target
    last = rows[1]
    for key in ("target_contacts", "hypotheses_outline_m", "hypotheses_closes", "confidence",
                "rules_outline_m"):
        assert last[key] == whole[key], key
    # The whole episode's grasp is carried under its own name: it is not the cut's.
    assert last["episode_grasped"] == whole["grasp_success"]


def test_cuts_no_log_reaches_are_refused_before_any_replay(tmp_path, capsys):
    (tmp_path / "logs").mkdir()
    shutil.copy(LOG, tmp_path / "logs")
    for name in ("table_config.yaml", "runs.csv"):
        shutil.copy(SOURCE / name, tmp_path / name)
    assert main(["estimates", "--table", str(tmp_path), "--after-actions", "50", "80"]) != 0
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["stucco-drake estimates: error: --after-actions: no log reaches 50 actions "
                   "(the longest has 42)"]
    assert not list(tmp_path.glob("estimates_*.csv"))


def _rows(path: Path) -> list[dict]:
    import csv

    with path.open(encoding="utf-8") as file:
        return list(csv.DictReader(file))
