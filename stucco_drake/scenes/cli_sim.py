"""The ``stucco-drake sim`` subcommand: play a scene's action sequence, optionally in Meshcat."""

from __future__ import annotations

import argparse

import numpy as np

from stucco_drake.core.inputs import positive_int, prepare_output_file


def add_sim_command(commands) -> None:
    """Adds ``sim`` to the CLI's subparsers."""
    sim = commands.add_parser("sim", help="play a scene's prescribed actions in simulation")
    sim.add_argument("--scene", required=True,
                     help="scene name (diagrams/<name>.yaml, e.g. FB) or a path to a scene file")
    sim.add_argument("--actions", type=positive_int, default=None,
                     help="play only the first N actions (default: all)")
    sim.add_argument("--meshcat", action="store_true", help="show the run live in Meshcat")
    sim.add_argument("--record", metavar="OUT.html",
                     help="save a standalone Meshcat HTML recording of the run")
    sim.set_defaults(run=run_sim)


def run_sim(args: argparse.Namespace) -> int:
    from stucco_drake.scenes import build_scene, load_scene
    from stucco_drake.scenes.meshcat_session import save_recording, start_meshcat
    from stucco_drake.scenes.playback import play

    # Bad inputs raise InputError, which the CLI's main reports, before any simulation; the
    # output is prepared last, so that nothing is created for a command that fails.
    scene = load_scene(args.scene)
    record = prepare_output_file("--record", args.record)
    meshcat = start_meshcat(args.meshcat, record)
    built = build_scene(scene, meshcat=meshcat)

    def progress(rec):
        xy_error = np.linalg.norm(rec.gripper_xyz[:2] - rec.goal_xy) * 1000
        print(f"action {rec.index + 1:3d}: gripper ({rec.gripper_xyz[0]:+.3f}, "
              f"{rec.gripper_xyz[1]:+.3f}) m, {xy_error:5.1f} mm from its goal", flush=True)

    records, wall = play(built, args.actions, on_action=progress)
    simulated = records[-1].time
    print(f"scene {scene.name}: {len(records) - 1} actions, {simulated:.1f} s simulated in "
          f"{wall:.1f} s (real-time factor {simulated / max(wall, 1e-9):.2f})")
    for name, start in records[0].objects.items():
        moved = np.linalg.norm(records[-1].objects[name][:2] - start[:2]) * 1000
        print(f"  {name}: moved {moved:.1f} mm")
    if record:
        save_recording(meshcat, record)
    return 0
