"""The calibration lines of ``stucco-drake estimates``: counted by hand on four rows."""

from stucco_drake.cli.estimates import _calibration
from stucco_drake.eval.sets import CONFIDENT_FROM


def test_confident_runs_and_touches_are_counted_per_base_and_in_all():
    rows = [
        {"base": "FB", "confidence": CONFIDENT_FROM, "grasp_success": True, "target_contacts": 3},
        {"base": "FB", "confidence": 0.9999, "grasp_success": False, "target_contacts": 5},
        {"base": "IB", "confidence": 0.5, "grasp_success": True, "target_contacts": 2},
        {"base": "IB", "confidence": 0.0, "grasp_success": None, "target_contacts": 0},
    ]
    lines = {line.split()[0]: [int(v) for v in line.split()[1:]]
             for line in _calibration(rows).splitlines()[1:]}
    # confident runs, of them grasped; other runs, of them with the target touched
    assert lines == {"FB": [2, 1, 0, 0], "IB": [0, 0, 2, 1], "all": [2, 1, 2, 1]}
