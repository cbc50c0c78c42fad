"""The ``stucco-drake summary`` subcommand: table folders read together with their spread
(:mod:`stucco_drake.eval.summary`), as Markdown on stdout and optionally in a file."""

from __future__ import annotations

import argparse

from stucco_drake.core.inputs import InputError, prepare_output_file, probability
from stucco_drake.eval.sets import CONFIDENT_FROM
from stucco_drake.eval.summary import (
    against_lines,
    calibration_lines,
    grasp_lines,
    load_estimates,
    load_runs,
    paired_lines,
)
from stucco_drake.eval.table import METHOD_LABELS


def add_summary_command(subparsers) -> None:
    """Adds ``summary`` to the CLI's subparsers."""
    command = subparsers.add_parser(
        "summary", help="read table folders together: grasp success with its interval, "
                        "paired comparisons, calibration")
    command.add_argument("--tables", nargs="+", required=True, metavar="DIR",
                         help="`stucco-drake table` output folders made with one setting, "
                              "pooled (no run in two of them)")
    command.add_argument("--reference", default="stucco", metavar="METHOD",
                         help="the method the others are paired with and whose calibration "
                              "and --against comparison are given (default stucco)")
    command.add_argument("--against", nargs="+", default=None, metavar="DIR",
                         help="table folders of other layouts (e.g. the paper's) to compare "
                              "the reference's grasp success with, family by family")
    command.add_argument("--confident-from", type=probability, default=CONFIDENT_FROM,
                         metavar="P",
                         help="the confidence from which a run counts as confident (default: "
                              "the project's threshold, stucco_drake.eval.sets.CONFIDENT_FROM)")
    command.add_argument("--out", default=None, metavar="FILE.md",
                         help="also write the summary to this file")
    command.set_defaults(run=run_summary)


def summary_text(tables, reference: str = "stucco", against=None,
                 confident_from: float = CONFIDENT_FROM) -> str:
    """The summary of the folders ``tables`` (see :mod:`stucco_drake.eval.summary`) as
    Markdown; InputError (one line) on folders that cannot be pooled."""
    rows = load_runs(tables)
    other_rows = load_runs(against) if against else None
    families = list(dict.fromkeys(row["family"] for row in rows))
    present = {row["method"] for row in rows}
    if reference not in present:
        raise InputError(f"--reference {reference}: no run of it in --tables "
                         f"(methods: {', '.join(sorted(present))})")
    methods = [m for m in METHOD_LABELS if m in present] + sorted(present - set(METHOD_LABELS))
    lines = [f"Tables: {', '.join(map(str, tables))}.", "",
             *grasp_lines(rows, families, methods), ""]
    if len(methods) > 1:
        lines += [*paired_lines(rows, families, reference, methods), ""]
    estimates = load_estimates(tables, reference)
    if estimates is None:
        lines += [f"No calibration: a folder has no estimates_{reference}.csv "
                  f"(`stucco-drake estimates --table DIR --method {reference}` writes it).", ""]
    else:
        lines += [*calibration_lines(estimates, families, confident_from), ""]
    if other_rows is not None:
        lines += [*against_lines(rows, other_rows, families, reference), ""]
    return "\n".join(lines)


def run_summary(args: argparse.Namespace) -> int:
    """Handler of ``stucco-drake summary``."""
    out = prepare_output_file("--out", args.out)
    text = summary_text(args.tables, args.reference, args.against, args.confident_from)
    print(text)
    if out is not None:
        out.write_text(text + "\n", encoding="utf-8")
    return 0
