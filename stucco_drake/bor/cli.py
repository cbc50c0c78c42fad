"""The ``stucco-drake run`` and ``stucco-drake diagram`` subcommands (Blind Object Retrieval).

``run`` plays a scene through the BOR Diagram and prints one result line; ``diagram`` writes the
Diagram's wiring as Graphviz source (and an SVG when Graphviz's ``dot`` is installed).
"""

from __future__ import annotations

import argparse
import re
import shutil
import sys
from pathlib import Path

import numpy as np

from stucco_drake.core.inputs import (
    InputError,
    hypothesis_settings_of,
    non_negative_int,
    policy_settings_of,
    positive_int,
    prepare_output_file,
    read_stucco_params,
)

#: Nesting depth of the wiring picture: the scene Diagram stays one box.
DIAGRAM_DEPTH = 1


# ------------------------------------------------------------------------------------- run
def add_run_command(subparsers) -> None:
    """Adds ``run`` to the CLI's subparsers."""
    from stucco_drake.core.baselines import TRACKER_NAMES
    from stucco_drake.core.contact_motion import DX_MODELS, DX_MODELS_SUMMARY

    run = subparsers.add_parser("run", help="rummage a scene blind, track contacts, estimate "
                                            "the target's pose; print GS, CE, FMI")  # fmt: skip
    run.add_argument("--scene", required=True,
                     help="scene name (diagrams/<name>.yaml, e.g. FB), a scene file path, or a "
                          "folder of scene files (runs each)")
    run.add_argument("--method", default="stucco", choices=TRACKER_NAMES)
    run.add_argument("--seed", type=non_negative_int, default=0,
                     help="seed of every random stream")
    run.add_argument("--actions", type=positive_int, default=None,
                     help="play only the first N actions (default: all)")
    run.add_argument("--dx-model", choices=DX_MODELS, default="ee",
                     help=f"how tracked contacts move ({DX_MODELS_SUMMARY})")
    run.add_argument("--stucco-params", metavar="PARAMS.yaml", default=None,
                     help="STUCCO's parameters (YAML, fields of SoftTrackingParams over Table "
                          "I's sim preset; default: the scene's)")
    run.add_argument("--policy", choices=("prescribed", "probe", "belief", "sweep"),
                     default="prescribed",
                     help="what chooses the actions: the scene's prescribed list (default); "
                          "'probe': after it, guarded touches of the target where the live "
                          "pose hypotheses put it; 'belief': rummaging chosen from the belief, "
                          "stopping once the target is known; 'sweep': a coverage raster")
    run.add_argument("--policy-params", metavar="SETTINGS.yaml", default=None,
                     help="the policy's settings as YAML overrides of its defaults (nested "
                          "mappings for nested settings)")
    run.add_argument("--target-estimator", choices=("rules", "hypotheses"), default="hypotheses",
                     help="where the grasp is made: the grasp chosen across the weighted pose "
                          "hypotheses (default), or Table II's segment-selection estimate")
    run.add_argument("--hypothesis-params", metavar="SETTINGS.yaml", default=None,
                     help="the target pose estimator's HypothesisParams as YAML overrides of "
                          "its defaults (the live hypotheses, a policy's choices and stop, the "
                          "grasp across them), e.g. confidence_temperature: 3.0")
    run.add_argument("--meshcat", action="store_true", help="show the run live in Meshcat")
    run.add_argument("--record", metavar="OUT.html",
                     help="save a standalone Meshcat HTML recording of the run")
    run.add_argument("--no-grasp", action="store_true",
                     help="skip the final grasp (GS prints n/a)")
    run.add_argument("--plot", metavar="OUT.png",
                     help="plot the tracked points by segment over the true object outlines")
    run.set_defaults(run=run_bor)  # fmt: skip


def _grasp_hook(enabled: bool, estimator: str = "hypotheses"):
    """The grasp hook of ``estimator`` when grasping is asked for and the grasp module is
    present, else None (GS prints n/a)."""
    if not enabled:
        return None
    try:
        import stucco_drake.bor.grasp  # noqa: F401
    except ImportError:
        print("grasp: stucco_drake.bor.grasp is not available, GS is n/a", file=sys.stderr)
        return None
    from stucco_drake.bor.episode import GRASP_HOOKS

    return GRASP_HOOKS[estimator]


def run_bor(args: argparse.Namespace) -> int:
    from stucco_drake.bor.diagram import build_bor_diagram
    from stucco_drake.bor.episode import run_episode
    from stucco_drake.bor.policies import coverage_scene
    from stucco_drake.bor.table_sources import POLICY_SETTINGS
    from stucco_drake.scenes import load_scene, scene_paths
    from stucco_drake.scenes.meshcat_session import save_recording, start_meshcat

    # Bad inputs raise InputError, which the CLI's main reports, before any simulation; the
    # outputs are prepared last, so that nothing is created for a command that fails.
    if args.stucco_params is not None and args.method != "stucco":
        raise InputError(f"--stucco-params is for --method stucco, not {args.method}")
    params = read_stucco_params(args.stucco_params)
    settings, _ = policy_settings_of(args.policy, args.policy_params, POLICY_SETTINGS)
    hypothesis_params, _ = hypothesis_settings_of(args.hypothesis_params)
    # A folder runs each of its scenes.
    scenes = [load_scene(path) for path in scene_paths(args.scene)]
    if len(scenes) > 1 and (args.record or args.plot):
        raise InputError(f"--record and --plot take one scene, not a folder of {len(scenes)}")
    record = prepare_output_file("--record", args.record)
    plot = prepare_output_file("--plot", args.plot)
    meshcat = start_meshcat(args.meshcat, record)
    for scene in scenes:
        bor = None
        if args.policy == "sweep":
            scene = coverage_scene(scene, settings)
        elif args.policy != "prescribed":
            bor = build_bor_diagram(scene, args.method, args.seed, meshcat=meshcat,
                                    tracker_params=params, dx_model=args.dx_model,
                                    policy=settings, hypothesis_params=hypothesis_params)
        # The hook grasps at the Diagram's own estimate, made with ``hypothesis_params``.
        grasp = _grasp_hook(not args.no_grasp, args.target_estimator)
        result = run_episode(scene, args.method, args.seed, args.actions, bor=bor,
                             meshcat=meshcat, grasp=grasp, dx_model=args.dx_model,
                             tracker_params=params, target_estimator=args.target_estimator,
                             hypothesis_params=hypothesis_params)
        print(result.summary(), flush=True)
    if record:
        save_recording(meshcat, record)
    if plot:
        plot_episode(result, plot)
        print(f"plot: {plot}")
    return 0


def _outline(surface, n: int = 64) -> np.ndarray:
    """(k, 2) top-view outline (m, world) of a posed box or cylinder."""
    from stucco_drake.core.shapes import BoxSdf

    X_WG = np.linalg.inv(surface.X_GW)
    centre = np.asarray(surface.sdf.center, dtype=float)
    if isinstance(surface.sdf, BoxSdf):
        hx, hy, _ = surface.sdf.half_extents
        local = np.array([[-hx, -hy], [hx, -hy], [hx, hy], [-hx, hy], [-hx, -hy]])
    else:
        angle = np.linspace(0.0, 2 * np.pi, n)
        local = surface.sdf.radius * np.c_[np.cos(angle), np.sin(angle)]
    local = np.c_[local, np.zeros(len(local))] + centre
    return (local @ X_WG[:3, :3].T + X_WG[:3, 3])[:, :2]


def plot_episode(result, path: str | Path) -> None:
    """Top view: true object outlines at their final poses (grey; the target black), tracked
    points in their segment's colour (the recording's), and the estimated target outline
    (magenta, dashed, as in the recording); the title gives how far the estimate is off."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from stucco_drake.bor.diagram import PosedSurface
    from stucco_drake.systems.contact_tracking_visualizer import (
        OUTLINE_COLOR,
        SEGMENT_PALETTE,
        UNLABELLED_COLOR,
        segment_color_index,
    )

    fig, ax = plt.subplots(figsize=(6, 6))
    for name, group in result.surfaces.items():
        target = name == result.scene_target
        for surface in group:
            xy = _outline(surface)
            ax.plot(xy[:, 0], xy[:, 1], color="k" if target else "0.6", lw=1.5 if target else 1)
    points, labels = result.map_points, np.asarray(result.labels)
    for label in np.unique(labels):
        index = segment_color_index(label)
        color = (UNLABELLED_COLOR if index < 0 else SEGMENT_PALETTE[index]).rgba[:3]
        mine = points[labels == label]
        ax.scatter(mine[:, 0], mine[:, 1], color=color, marker="o", s=36, edgecolors="k",
                   linewidths=0.5, label=f"segment {label}" if label >= 0 else "unlabelled")
    if result.estimate is not None and result.target_shape is not None:
        x, y, yaw = np.asarray(result.estimate.pose, dtype=float)  # rules' or hypotheses'
        c, s = np.cos(yaw), np.sin(yaw)
        X_WO = np.array([[c, -s, 0, x], [s, c, 0, y], [0, 0, 1, 0], [0, 0, 0, 1.0]])
        xy = _outline(PosedSurface(result.target_shape, np.linalg.inv(X_WO)))
        ax.plot(xy[:, 0], xy[:, 1], "--", color=OUTLINE_COLOR.rgba[:3], lw=1.5,
                label="estimated target")  # fmt: skip
    # Frame the clutter (free objects and tracked points), not the walls around it.
    near = [xy[:2] for xy in result.object_poses.values()] + [p[:2] for p in points]
    low, high = np.min(near, axis=0) - 0.12, np.max(near, axis=0) + 0.12
    ax.set_xlim(low[0], high[0])
    ax.set_ylim(low[1], high[1])
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    grasp = "" if result.grasp_success is None else (
        ", grasped" if result.grasp_success else ", grasp failed")
    ax.set_title(f"{result.scene} {result.method} seed {result.seed}: CE {result.ce_cm:.2f} cm, "
                 f"FMI {result.fmi:.2f}\n{result.estimate_words()}{grasp}")  # fmt: skip
    ax.legend(loc="upper right", fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


# --------------------------------------------------------------------------------- diagram
def add_diagram_command(subparsers) -> None:
    """Adds ``diagram`` to the CLI's subparsers."""
    from stucco_drake.core.baselines import TRACKER_NAMES

    diagram = subparsers.add_parser("diagram", help="write the BOR Diagram's wiring picture")
    diagram.add_argument("--scene", default="FB", help="scene name or scene file path")
    diagram.add_argument("--method", default="stucco", choices=TRACKER_NAMES)
    diagram.add_argument("--out", default="diagrams/bor.svg",
                         help="output .svg (also writes the .dot source next to it) or .dot")
    diagram.set_defaults(run=run_diagram)  # fmt: skip


def normalized_graphviz(text: str) -> str:
    """Graphviz source with Drake's per-process system ids renumbered by first appearance and
    the edges sorted (Drake lists them in hash order), so the same wiring gives the same text."""
    ids: dict[str, str] = {}

    def renumber(match: re.Match) -> str:
        return match.group(1) + ids.setdefault(match.group(2), str(len(ids)))

    lines = re.sub(r"(digraph _|clusters|cluster|\bs)(\d+)", renumber, text).splitlines()
    edges = [i for i, line in enumerate(lines) if " -> " in line]
    for i, line in zip(edges, sorted(lines[i] for i in edges), strict=True):
        lines[i] = line
    return "\n".join(lines) + "\n"


def bor_graphviz(scene="FB", method: str = "stucco") -> str:
    """The normalized Graphviz source of the BOR Diagram of ``scene`` (a SceneFile or a scene
    name)."""
    from stucco_drake.bor.diagram import build_bor_diagram

    diagram = build_bor_diagram(scene, method).diagram
    return normalized_graphviz(diagram.GetGraphvizString(max_depth=DIAGRAM_DEPTH))


def run_diagram(args: argparse.Namespace) -> int:
    from stucco_drake.scenes import load_scene

    scene = load_scene(args.scene)  # a bad scene or output raises InputError for the CLI's main
    out = prepare_output_file("--out", args.out)
    dot_path = prepare_output_file("--out", out.with_suffix(".dot"))
    source = bor_graphviz(scene, args.method)
    dot_path.write_text(source)
    print(f"graphviz source: {dot_path}")
    if out.suffix == ".dot":
        return 0
    if shutil.which("dot") is None:
        print("graphviz 'dot' not found: no SVG written (render the .dot source elsewhere)",
              file=sys.stderr)  # fmt: skip
        return 1
    import pydot

    (graph,) = pydot.graph_from_dot_data(source)
    graph.write_svg(str(out))
    print(f"picture: {out}")
    return 0
