"""The ``stucco-drake policies`` subcommand: ways of choosing the actions compared on the same
layouts (:mod:`stucco_drake.eval.policy_compare`), as Markdown on stdout and optionally in a
file."""

from __future__ import annotations

import argparse

from stucco_drake.core.inputs import InputError, prepare_output_file
from stucco_drake.eval.policy_compare import compare_text


def add_policies_command(subparsers) -> None:
    """Adds ``policies`` to the CLI's subparsers."""
    command = subparsers.add_parser(
        "policies", help="compare ways of choosing the actions on the same layouts: grasp "
                         "success with its interval, median actions, paired comparisons")
    command.add_argument("--set", nargs="+", action="append", required=True,
                         metavar=("NAME", "DIR"), dest="sets",
                         help="a name and the `stucco-drake table` folders of one way of "
                              "choosing the actions, pooled; repeat for each, the first the "
                              "one the others are paired with")
    command.add_argument("--method", default="stucco",
                         help="the method whose grasps are compared (default stucco)")
    command.add_argument("--out", default=None, metavar="FILE.md",
                         help="also write the comparison to this file")
    command.set_defaults(run=run_policies)


def run_policies(args: argparse.Namespace) -> int:
    """Handler of ``stucco-drake policies``."""
    for values in args.sets:
        if len(values) < 2:
            raise InputError(f"--set {values[0]}: a name and at least one table folder")
    out = prepare_output_file("--out", args.out)
    text = compare_text([(values[0], values[1:]) for values in args.sets], args.method)
    print(text)
    if out is not None:
        out.write_text(text + "\n", encoding="utf-8")
    return 0
