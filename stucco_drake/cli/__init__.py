"""The ``stucco-drake`` command line."""

# The top of the package: ``main`` gathers every command. The layers' own commands live with
# their layer (``bor/cli.py``: run, diagram; ``scenes/cli_sim.py``: sim; ``eval/cli_table.py``:
# table; ``eval/cli_summary.py``: summary); those that combine layers live here (``scenes``,
# ``estimates``, ``sweep``).
# ``python -m stucco_drake.cli`` runs ``main`` (``__main__.py``).

from __future__ import annotations

import argparse
import sys
import time

import numpy as np

from stucco_drake.bor.cli import add_diagram_command, add_run_command
from stucco_drake.bor.log import BOR_SOURCES
from stucco_drake.bor.table_sources import POLICIES, POLICY_SETTINGS, table_scenes
from stucco_drake.cli.estimates import add_estimates_command
from stucco_drake.cli.scenes import add_scenes_command
from stucco_drake.cli.sweep import add_sweep_command
from stucco_drake.core.inputs import InputError, non_negative_int
from stucco_drake.eval.cli_policies import add_policies_command
from stucco_drake.eval.cli_summary import add_summary_command
from stucco_drake.eval.cli_table import add_table_command
from stucco_drake.eval.sources import SYNTHETIC_SOURCES
from stucco_drake.scenes.cli_sim import add_sim_command


def _demo(args: argparse.Namespace) -> int:
    """Track the built-in synthetic key case with STUCCO and with hard clustering; print both."""
    from stucco_drake.core import (
        CylinderSdf,
        GridSdf,
        RobotPenetration,
        SoftTracker,
        SoftTrackingParams,
        contact_error,
        fowlkes_mallows,
    )
    from stucco_drake.core.clustering_tracker import ClusteringTracker, single_linkage
    from stucco_drake.core.synthetic import separation_scenario

    params = SoftTrackingParams.sim()
    grid = GridSdf.build(CylinderSdf(0.02, 0.05), [-0.03, -0.03, -0.06], [0.03, 0.03, 0.06], 0.001)
    trackers = {
        "stucco": SoftTracker(RobotPenetration(grid), params),
        "single-linkage": ClusteringTracker(single_linkage(params.segmentation_radius)),
    }
    print("synthetic planar scene: a 2 cm disc nudges two 10 cm boxes apart from between them")
    for name, tracker in trackers.items():
        world, actions = separation_scenario()
        rng = np.random.default_rng(args.seed)
        truth, n_actions, start = [], 0, time.perf_counter()
        for obs in actions:
            tracker.update(rng, obs.ee_position, obs.contact_points, obs.contact_dx)
            truth.extend(obs.contact_objects)
            n_actions += 1
        elapsed = time.perf_counter() - start
        error = contact_error(tracker.map_points(), world.object_surfaces())
        fmi = fowlkes_mallows(truth, tracker.segment())
        print(
            f"{name:>15}: {n_actions} actions, {len(truth)} contacts, "
            f"CE {error * 100:.2f} cm, FMI {fmi:.3f}, {elapsed:.2f} s"
        )
    return 0


class OneLineErrorParser(argparse.ArgumentParser):
    """An ArgumentParser that reports a bad argument in one line, as :func:`main` reports
    every other bad input (argparse's own report adds the usage block); its subcommands'
    parsers are of this class too."""

    def error(self, message: str):
        self.exit(2, f"{self.prog}: error: {message}\n")


def build_parser() -> argparse.ArgumentParser:
    parser = OneLineErrorParser(prog="stucco-drake", description=__doc__)
    commands = parser.add_subparsers(dest="command", required=True)
    demo = commands.add_parser("demo", help="run the synthetic key-case demo and print metrics")
    demo.add_argument("--seed", type=non_negative_int, default=0,
                      help="seed of the tracker's generator")
    demo.set_defaults(run=_demo)
    add_sim_command(commands)
    add_scenes_command(commands)
    add_estimates_command(commands)
    add_table_command(commands, {**BOR_SOURCES, **SYNTHETIC_SOURCES}, table_scenes, POLICIES,
                      POLICY_SETTINGS)
    add_run_command(commands)
    add_diagram_command(commands)
    add_sweep_command(commands)
    add_summary_command(commands)
    add_policies_command(commands)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Runs one command; exit status 0 done, 1 interrupted (a rerun resumes), 2 bad input.

    Every bad input is reported before any simulation starts, in one line: argparse's checks
    by :class:`OneLineErrorParser` (it exits), the commands' own checks (scene files,
    parameter files, output paths, ...) as an :class:`~stucco_drake.core.inputs.InputError` here.
    """
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return args.run(args)
    except InputError as error:  # one line naming the input, no traceback
        message = " ".join(str(error).split())
        print(f"{parser.prog} {args.command}: error: {message}", file=sys.stderr)
        return 2

