"""The ``stucco-drake scenes`` subcommand: ``scenes randomize`` writes randomized layouts,
``scenes noise`` copies of scenes with noisy sensing.

See :mod:`stucco_drake.scenes.randomize` for how a layout is drawn and
:mod:`stucco_drake.eval.sets` for the development and report ranges of layout seeds.
"""

from __future__ import annotations

import argparse
import math
import sys
import time

from stucco_drake.eval.sets import DEVELOPMENT_SEEDS, REPORT_SEEDS, describe_sets, scene_set


def add_scenes_command(subparsers) -> None:
    """Adds ``scenes`` (with ``randomize``) to the CLI's subparsers."""
    from stucco_drake.scenes.randomize import LayoutParams

    defaults = LayoutParams()
    scenes = subparsers.add_parser(
        "scenes", help="work with scene files: randomized layouts, noisy sensing")
    commands = scenes.add_subparsers(dest="scenes_command", required=True)
    randomize = commands.add_parser(
        "randomize", help="write randomized layouts of a scene: every movable object shifted "
                          "and turned, none closer than the clearance to anything")  # fmt: skip
    randomize.add_argument("--scene", required=True, help="base scene name or scene file")
    randomize.add_argument("--count", type=int, default=1, help="number of layouts (default 1)")
    randomize.add_argument(
        "--seed", type=int, required=True,
        help=f"first layout seed; layouts take SEED..SEED+COUNT-1 (development "
             f"{_span(DEVELOPMENT_SEEDS)}, report {_span(REPORT_SEEDS)})")  # fmt: skip
    randomize.add_argument("--out", required=True, help="output folder (<scene>-L<seed>.yaml)")
    randomize.add_argument("--shift", type=float, nargs=2, default=list(defaults.shift),
                           metavar=("MIN", "MAX"),
                           help="range of each object's planar shift, m (default %(default)s)")
    randomize.add_argument("--yaw", type=float, default=math.degrees(defaults.max_yaw),
                           metavar="DEG", help="largest turn, deg (default %(default)g)")
    randomize.add_argument("--clearance", type=float, default=defaults.clearance,
                           help="least distance of a moved object to anything but the "
                                f"{defaults.support}, m (default %(default)g)")
    randomize.add_argument("--max-draws", type=int, default=defaults.max_draws,
                           help="draws per layout before giving up (default %(default)d)")
    randomize.set_defaults(run=run_randomize)

    from stucco_drake.scenes.sensor_noise import REAL_IIWA

    noise = commands.add_parser(
        "noise", help="write copies of scenes whose robot senses with noise (<scene>-noise.yaml; "
                      "defaults: a real iiwa with bubbles, docs/sensor_noise.md)")  # fmt: skip
    noise.add_argument("--scenes", nargs="+", required=True, help="scene names or scene files")
    noise.add_argument("--out", required=True, help="output folder")
    noise.add_argument("--torque-std", type=float, default=REAL_IIWA.torque_std,
                       help="joint torque noise, N m (default %(default)g)")
    noise.add_argument("--velocity-std", type=float, default=REAL_IIWA.velocity_std,
                       help="joint velocity noise, rad/s (default %(default)g)")
    noise.add_argument("--bubble-std", type=float, default=REAL_IIWA.bubble_point_std,
                       help="bubble contact point noise per coordinate, m (default %(default)g)")
    noise.set_defaults(run=run_noise)


def run_noise(args: argparse.Namespace) -> int:
    """Handler of ``stucco-drake scenes noise``: 0 written; a bad input raises InputError (the
    CLI's main reports it), before anything is written."""
    from stucco_drake.scenes import load_scene
    from stucco_drake.scenes.scene_file import SensorNoise
    from stucco_drake.scenes.sensor_noise import with_sensor_noise, write_noisy_scene

    noise = SensorNoise(args.torque_std, args.velocity_std, args.bubble_std)
    scenes = [load_scene(name) for name in args.scenes]
    for scene in scenes:  # every copy is checked before any is written
        with_sensor_noise(scene, noise)
    for scene in scenes:
        print(write_noisy_scene(scene, args.out, noise))
    return 0


def _span(seeds: range) -> str:
    return f"{seeds.start}-{seeds.stop - 1}"


def run_randomize(args: argparse.Namespace) -> int:
    """Handler of ``stucco-drake scenes randomize``: 0 written, 2 bad input or no layout."""
    from stucco_drake.scenes import load_scene
    from stucco_drake.scenes.randomize import LayoutError, LayoutParams, write_layouts

    start = time.perf_counter()
    base = load_scene(args.scene)  # a bad scene file is reported by the CLI's main
    params = LayoutParams(shift=tuple(args.shift), max_yaw=math.radians(args.yaw),
                          clearance=args.clearance, max_draws=args.max_draws)  # fmt: skip
    try:
        if args.count < 1 or args.seed < 0:
            raise LayoutError(f"--count must be positive and --seed >= 0, got {args.count} "
                              f"and {args.seed}")
        seeds = range(args.seed, args.seed + args.count)
        written = write_layouts(base, seeds, args.out, params)
    except LayoutError as error:
        print(f"stucco-drake scenes randomize: error: {error}", file=sys.stderr)
        return 2
    for path, _, draws in written:
        print(f"{path} ({draws} draw{'s' if draws > 1 else ''})")
    print(describe_sets({s.name: scene_set(s.name, s.base, s.layout_seed) for _, s, _ in written}))
    print(f"{len(written)} layouts of {base.name} in {time.perf_counter() - start:.1f} s")
    return 0
