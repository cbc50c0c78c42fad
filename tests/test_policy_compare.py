"""``stucco-drake policies``: ways of choosing the actions compared on the same layouts, the
counts, intervals and action medians against tables and logs written by hand."""

import numpy as np
import pytest
from test_summary import _table

from stucco_drake.cli import main

CONFIG = {"dx_model": "cone", "stucco_params": {}}


def _policy_table(folder, runs: dict, config=None) -> str:
    """A table folder of STUCCO runs, scene -> (grasped, actions), each with a log of that
    many actions (only the end effector's positions, all the comparison reads)."""
    path = _table(folder, {(scene, "stucco"): g for scene, (g, _) in runs.items()},
                  config or CONFIG)
    (folder / "logs").mkdir()
    for scene, (_, actions) in runs.items():
        np.savez(folder / "logs" / f"{scene}_0.npz", ee_position=np.zeros((actions, 3)))
    return path


def test_sets_are_pooled_and_paired_with_the_first(tmp_path, capsys):
    """The belief policy in two folders of other budgets (FB at 24 and 30 actions, BC at 61)
    against the prescribed scripts (54 and 102 actions) on the same three layouts."""
    belief = [_policy_table(tmp_path / "b24", {"FB-L1": (True, 24), "FB-L2": (True, 30)}),
              _policy_table(tmp_path / "b61", {"BC-L1": (True, 61)},
                            {**CONFIG, "policy": "belief"})]
    script = _policy_table(tmp_path / "s", {"FB-L1": (False, 54), "FB-L2": (True, 54),
                                            "BC-L1": (False, 102)})
    out = tmp_path / "policies.md"
    assert main(["policies", "--set", "belief", *belief, "--set", "prescribed", script,
                 "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert out.read_text() == text
    # Wilson's interval by hand: 2 of 2, 34-100 %; 1 of 2, 9-91 %; medians 27 and 54.
    assert "| belief | 1/1 (100 %, 21-100); 61 | 2/2 (100 %, 34-100); 27 |" in text
    assert "| prescribed | 0/1 (0 %, 0-79); 102 | 1/2 (50 %, 9-91); 54 |" in text
    # FB: L1 grasped by the belief only; actions 24/54 and 30/54, median 0.5. BC: 61/102.
    assert "| prescribed | 1/0, p 1.00; actions x0.60 | 1/0, p 1.00; actions x0.50 |" in text


@pytest.mark.parametrize("case, fragment", [
    ("a name alone", "--set b: a name and at least one table folder"),
    ("a name twice", "a name is given twice"),
    ("a run twice", "is in"),
    ("a log missing", "the run's log is missing"),
    ("no run of the method", "no run of method birch"),
])  # fmt: skip
def test_sets_that_cannot_be_read_are_one_error_line(tmp_path, capsys, case, fragment):
    first = _policy_table(tmp_path / "a", {"FB-L1": (True, 24)})
    argv = ["policies", "--set", "a", first]
    if case == "a name alone":
        argv += ["--set", "b"]
    elif case == "a name twice":
        argv += ["--set", "a", first]
    elif case == "a run twice":
        argv.append(_policy_table(tmp_path / "b", {"FB-L1": (False, 30)}))
    elif case == "a log missing":
        (tmp_path / "a" / "logs" / "FB-L1_0.npz").unlink()
    else:
        argv += ["--method", "birch"]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.startswith("stucco-drake policies: error: ") and err.count("\n") == 1, err
    assert fragment in err, err
