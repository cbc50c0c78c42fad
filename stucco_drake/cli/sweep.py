"""The ``stucco-drake sweep`` subcommand: tune a method's parameters on the training set.

See :mod:`stucco_drake.eval.sweep` for what it writes (``OUT/logs``, ``OUT/sweep.csv``,
``OUT/tuned_<method>.yaml``) and :mod:`stucco_drake.training` for the Drake training trials.
"""

from __future__ import annotations

import argparse
import functools
import sys
from collections.abc import Mapping

from stucco_drake.core.baselines import TRACKER_NAMES
from stucco_drake.core.contact_motion import DX_MODELS, DX_MODELS_SUMMARY
from stucco_drake.core.inputs import InputError, positive_int, prepare_output_folder
from stucco_drake.eval.cli_table import check_names
from stucco_drake.eval.results import RunResults
from stucco_drake.eval.runner import RunInterrupted, make_executor
from stucco_drake.eval.sources import SYNTHETIC_SOURCES, EpisodeSource
from stucco_drake.eval.sweep import AMBIGUOUS, parse_grid, run_sweep, tuned_path
from stucco_drake.training import TRAINING_SCENES, TRAINING_SOURCES

SWEEP_SOURCES = {**TRAINING_SOURCES, **SYNTHETIC_SOURCES}


def add_sweep_command(subparsers, sources: Mapping[str, EpisodeSource] = SWEEP_SOURCES) -> None:
    """Adds ``sweep`` to the CLI's subparsers, over the scenes of ``sources``."""
    sweep = subparsers.add_parser(
        "sweep", help="sweep a method's parameters on the training trials; write the tuned ones"
    )
    sweep.add_argument("--method", required=True, choices=TRACKER_NAMES, help="tracking method")
    sweep.add_argument("--scenes", nargs="+", default=list(TRAINING_SCENES),
                       help=f"scene names (default: {' '.join(TRAINING_SCENES)}; "
                            f"known: {', '.join(sources)})")
    sweep.add_argument("--trials", type=positive_int, default=40,
                       help="trials (seeds 0..N-1) per scene")
    sweep.add_argument("--out", required=True,
                       help="output folder (logs, sweep.csv, tuned_<method>.yaml)")
    sweep.add_argument("--workers", type=positive_int, default=None,
                       help="parallel worker processes (default: one per CPU)")
    sweep.add_argument("--dx-model", choices=DX_MODELS, default="ee",
                       help=f"how contact points move in the replays ({DX_MODELS_SUMMARY})")
    sweep.add_argument("--grid", action="append", default=None, metavar="NAME=V1,V2,...",
                       help="values of one parameter (repeatable; default: the method's "
                            "primary parameter around its paper value)")
    sweep.set_defaults(run=functools.partial(run_sweep_command, sources=sources))


def run_sweep_command(args: argparse.Namespace,
                      sources: Mapping[str, EpisodeSource] = SWEEP_SOURCES) -> int:
    """Handler of ``stucco-drake sweep``: 0 done, 1 interrupted (rerun resumes); a bad input
    raises InputError (the CLI's main reports it) before any simulation, as does a sweep
    whose every trial is discarded (after simulating them)."""
    try:
        check_names(args.scenes, [args.method], sources)
        grid = parse_grid(args.method, args.grid)
    except ValueError as error:
        raise InputError(str(error)) from None
    out = prepare_output_folder("--out", args.out)
    try:
        RunResults(out / "sweep.csv").rows()  # one of another version is refused now
    except ValueError as error:
        raise InputError(str(error)) from None
    executor = make_executor("process", args.workers)
    try:
        with executor:
            tuned = run_sweep(args.method, args.scenes, args.trials, out, executor, grid,
                              sources, dx_model=args.dx_model)
    except RunInterrupted as error:
        print(f"stucco-drake sweep: {error}", file=sys.stderr)
        return 1
    except ValueError as error:  # every trial discarded: nothing to tune on
        raise InputError(str(error).splitlines()[0]) from None
    amb = tuned["ambiguous"]
    print(f"{args.method}: tuned {tuned['swept']} on {tuned['n_kept_trials']} of "
          f"{tuned['n_trials']} trials: median FMI {tuned['median_fmi']:.3f}, median CE "
          f"{tuned['median_ce_cm']:.2f} cm; ambiguous (>= {AMBIGUOUS}, {amb['n_runs']} runs): "
          f"median FMI {amb['median_fmi']:.3f}, median CE {amb['median_ce_cm']:.2f} cm")
    for entry in tuned["combinations"]:
        gap = entry.get("ce_gap_to_tuned")
        gap_text = ("" if gap is None else f"; median CE {gap['gap']:+.2f} cm against the tuned "
                    f"(95 % interval {gap['low']:+.2f} to {gap['high']:+.2f}, lower on "
                    f"{gap['n_lower']} of {gap['n']} trials)")
        print(f"  {entry['params']}: median FMI {entry['median_fmi']:.3f}, median CE "
              f"{entry['median_ce_cm']:.2f} cm{gap_text}")
    print(f"written {tuned_path(out, args.method, args.dx_model)} and {out / 'sweep.csv'}")
    return 0
