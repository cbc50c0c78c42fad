"""``stucco-drake summary`` and its statistics: intervals and tests against published and
hand-worked values, counts against tables written by hand."""

import math

import pytest
import yaml

from stucco_drake.cli import main
from stucco_drake.eval.results import RunResults
from stucco_drake.eval.sets import CONFIDENT_FROM
from stucco_drake.eval.summary import (
    calibration_lines,
    fisher_p,
    layout_family,
    paired_p,
    wilson_interval,
)


@pytest.mark.parametrize("successes, runs, low, high", [
    # Newcombe (1998), "Two-sided confidence intervals for the single proportion", Stat. Med.
    # 17:857-872, Table I, method 3 (Wilson's score interval, no continuity correction).
    (81, 263, 0.2553, 0.3662),
    (15, 148, 0.0624, 0.1605),
    (0, 20, 0.0, 0.1611),
    (1, 29, 0.0061, 0.1718),
])  # fmt: skip
def test_wilson_interval_matches_the_published_examples(successes, runs, low, high):
    assert wilson_interval(successes, runs) == pytest.approx((low, high), abs=1e-4)


def test_wilson_interval_of_no_runs_is_undefined_and_of_all_reaches_one():
    assert all(math.isnan(v) for v in wilson_interval(0, 0))
    assert wilson_interval(20, 20)[1] == 1.0


def test_paired_and_fisher_p_against_hand_worked_values():
    # McNemar's exact test: all 6 discordant pairs one way, 2 * 0.5**6; 5 and 1: 2 * 7/64.
    assert paired_p(6, 0) == pytest.approx(0.03125, abs=1e-12)
    assert paired_p(5, 1) == pytest.approx(14 / 64, abs=1e-12)
    assert paired_p(1, 1) == pytest.approx(1.0) and paired_p(0, 0) == 1.0
    # Fisher's tea-tasting table (3 of 4 right, 1 of 4 wrong): two-sided p = 34/70.
    assert fisher_p(3, 4, 1, 4) == pytest.approx(34 / 70, abs=1e-12)


def test_a_layout_names_its_family_and_any_other_scene_itself():
    from stucco_drake.scenes.randomize import layout_name

    assert layout_family(layout_name("FB", 9020)) == "FB"
    assert layout_family(layout_name("my-L-scene", 3)) == "my-L-scene"
    assert [layout_family(s) for s in ("FB", "SELECT1", "a-Lx")] == ["FB", "SELECT1", "a-Lx"]


def _calibration_counts(lines):
    """family -> [confident grasped, confident runs, others, others touched, others grasped]."""
    counts = {}
    for line in lines[4:]:
        cells = [c.strip() for c in line.strip("|").split("|")]
        sure = cells[1].split()[0].split("/") if cells[1] != "n/a" else ["0", "0"]
        counts[cells[0]] = [int(sure[0]), int(sure[1]), *map(int, cells[2:])]
    return counts


def test_confident_runs_and_touches_are_counted_per_family_and_in_all():
    rows = [
        {"family": "FB", "confidence": CONFIDENT_FROM, "grasp_success": True, "target_contacts": 3},
        {"family": "FB", "confidence": 0.9999, "grasp_success": False, "target_contacts": 5},
        {"family": "IB", "confidence": 0.5, "grasp_success": True, "target_contacts": 2},
        {"family": "IB", "confidence": 0.0, "grasp_success": None, "target_contacts": 0},
    ]
    counts = _calibration_counts(calibration_lines(rows, ["FB", "IB"]))
    assert counts == {"FB": [1, 2, 0, 0, 0], "IB": [0, 0, 2, 1, 1], "all": [1, 2, 2, 1, 1]}
    # From 0.5 the IB run at 0.5 is confident too (and grasped); the one at 0 is not.
    counts = _calibration_counts(calibration_lines(rows, ["FB", "IB"], 0.5))
    assert counts == {"FB": [1, 2, 0, 0, 0], "IB": [1, 1, 1, 0, 0], "all": [2, 3, 1, 0, 0]}


def _table(folder, grasps: dict, config: dict, estimates: dict | None = None):
    """A table folder: runs of (scene, method) -> grasped, one seed, with ``config``; with
    ``estimates`` (scene -> (confidence, grasped, target contacts)), its estimates file."""
    folder.mkdir()
    (folder / "table_config.yaml").write_text(yaml.safe_dump(config))
    results = RunResults(folder / "runs.csv")
    for (scene, method), grasped in grasps.items():
        results.append({"scene": scene, "seed": 0, "method": method, "grasp_success": grasped,
                        "ce_cm": 1.0, "fmi": 1.0, "ambiguity": 0.0, "n_contacts": 5,
                        "wall_time_s": 1.0})
    if estimates is not None:
        lines = ["scene,seed,target_contacts,confidence,grasp_success"]
        lines += [f"{scene},0,{touches},{confidence},{grasped}"
                  for scene, (confidence, grasped, touches) in estimates.items()]
        (folder / "estimates_stucco.csv").write_text("\n".join(lines) + "\n")
    return str(folder)


def test_two_folders_are_pooled_by_family_and_paired_layout_by_layout(tmp_path, capsys):
    """Two folders of one setting (one recorded before the hypothesis settings were), and
    the paper's layout against them: counts, intervals and tests worked by hand."""
    config = {"dx_model": "cone", "stucco_params": {}, "policy": "probe"}
    # FB: STUCCO grasps L1, L2, L3 and not L4; BIRCH only L4. IB: both grasp L1.
    first = _table(tmp_path / "a", {("FB-L1", "stucco"): True, ("FB-L1", "birch"): False,
                                    ("FB-L2", "stucco"): True, ("FB-L2", "birch"): False,
                                    ("IB-L1", "stucco"): True, ("IB-L1", "birch"): True},
                   config, {"FB-L1": (1.0, True, 4), "FB-L2": (0.2, True, 0),
                            "IB-L1": (0.5, True, 3)})
    second = _table(tmp_path / "b", {("FB-L3", "stucco"): True, ("FB-L3", "birch"): False,
                                     ("FB-L4", "stucco"): False, ("FB-L4", "birch"): True},
                    {**config, "hypothesis_params": {}},  # recorded once the key existed
                    {"FB-L3": (0.9995, False, 2), "FB-L4": (0.1, False, 1)})
    paper = _table(tmp_path / "p", {("FB", "stucco"): True}, config)
    out = tmp_path / "summary.md"
    assert main(["summary", "--tables", first, second, "--against", paper,
                 "--out", str(out)]) == 0  # fmt: skip
    text = capsys.readouterr().out
    assert out.read_text() == text
    lines = text.splitlines()
    stucco = next(line for line in lines if line.startswith("| ours (STUCCO) | 3/4"))
    assert "| 3/4 (75 %, 30-95) | 1/1 (100 %, 21-100) |" in stucco  # Wilson, by hand
    assert "| 3/1, p 0.62 | 0/0, p 1.00 |" in text  # BIRCH: 3 layouts to STUCCO, 1 to it
    calibration = lines[lines.index("Calibration of the target confidence."):][:7]
    assert _calibration_counts(calibration) == {
        "FB": [1, 2, 2, 1, 1], "IB": [0, 0, 1, 1, 1], "all": [1, 2, 3, 2, 2]}
    assert "| FB | 3/4 (75 %, 30-95) | 1/1 (100 %, 21-100) | -25 | 1.00 |" in text


@pytest.mark.parametrize("case, fragment", [
    ("no runs", "no runs.csv"),
    ("other settings", "dx_model differs"),
    ("a run twice", "is in"),
    ("no such method", "--reference gmphd: no run of it"),
])  # fmt: skip
def test_folders_that_cannot_be_pooled_are_one_error_line(tmp_path, capsys, case, fragment):
    config = {"dx_model": "cone", "stucco_params": {}}
    first = _table(tmp_path / "a", {("FB-L1", "stucco"): True}, config)
    argv = ["summary", "--tables", first]
    if case == "no runs":
        (tmp_path / "empty").mkdir()
        argv.append(str(tmp_path / "empty"))
    elif case == "other settings":
        argv.append(_table(tmp_path / "b", {("FB-L2", "stucco"): True},
                           {**config, "dx_model": "ee"}))
    elif case == "a run twice":
        argv.append(_table(tmp_path / "b", {("FB-L1", "stucco"): False}, config))
    else:
        argv += ["--reference", "gmphd"]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.startswith("stucco-drake summary: error: ") and err.count("\n") == 1, err
    assert fragment in err, err
