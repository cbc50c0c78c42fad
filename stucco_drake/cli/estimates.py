"""``stucco-drake estimates``: both target-pose estimators on a table's logged episodes.

Replays a method on every log of a ``table`` output folder, at that folder's recorded settings
(the target pose estimator's among them, unless ``--hypothesis-params`` overrides them, and
STUCCO's tracker's, unless ``--stucco-params`` changes some), and
scores the segment-selection rules and the weighted hypotheses against the target's final
pose (:func:`~stucco_drake.eval.target_estimates.score_estimates`), without simulating a grasp.
Each row joins the table's own grasp outcome for the method (made with the rules' estimate).
Writes ``OUT/estimates_<method>.csv`` and prints a summary per base scene. With
``--after-actions``, each log is cut after each of the given action counts
(:meth:`~stucco_drake.eval.episode_log.EpisodeLog.first`) and scored against the target's pose
there: would a policy stopping at that count have grasped? (Each cut is replayed from the start
with the table's filter stream, so it is the grasp's estimate at that point.) With
``--grasp-truth``, each episode's target is also grasped in simulation at its true final pose
(``true_pose_grasped``): what the episode's end allows a perfect estimate, so a failed grasp
can be told apart from a wrong estimate. With ``--regrasp``, the hypotheses' grasp is made
again from the logged final state with other settings (``regrasped``): a change to the grasp
alone, measured on the same episodes.
"""

from __future__ import annotations

import argparse
import csv
import functools
import math
from pathlib import Path

import numpy as np
import yaml

from stucco_drake.core.inputs import (
    InputError,
    hypothesis_settings_of,
    positive_int,
    probability,
    read_settings,
)

#: Outline error (m) under which an estimate is counted as near the truth in the summary.
NEAR = 0.02


def add_estimates_command(subparsers) -> None:
    """Adds ``estimates`` to the CLI's subparsers."""
    from stucco_drake.core.baselines import TRACKER_NAMES

    command = subparsers.add_parser(
        "estimates", help="score both target-pose estimators on a table folder's logs")
    command.add_argument("--table", required=True, help="a `stucco-drake table` output folder")
    command.add_argument("--method", default="stucco", choices=TRACKER_NAMES)
    command.add_argument("--motion-scales", nargs="+", type=float, default=None, metavar="S",
                         help="the motion scales the hypotheses search, each in [0, 1] (default: "
                              "the estimator's; 0: the points where sensed, 1: where tracked); "
                              "other scales write estimates_<method>_scales_<S>...csv")
    command.add_argument("--hypothesis-params", default=None, metavar="SETTINGS.yaml",
                         help="a YAML mapping of HypothesisParams fields to replay the "
                              "hypotheses with, e.g. confidence_temperature: 3.0, instead of "
                              "the table's recorded ones; writes "
                              "estimates_<method>_<file's stem>.csv")
    command.add_argument("--stucco-params", default=None, metavar="SETTINGS.yaml",
                         help="a YAML mapping of SoftTrackingParams fields to replay STUCCO "
                              "with on top of the table's recorded ones, e.g. replace_bad: "
                              "false; writes estimates_stucco_<file's stem>.csv")
    command.add_argument("--confident-from", type=probability, default=None, metavar="P",
                         help="the confidence from which the summary counts a run as "
                              "confident (default: the project's threshold, "
                              "stucco_drake.eval.sets.CONFIDENT_FROM; a tempered confidence "
                              "needs its own, chosen on development layouts)")
    command.add_argument("--after-actions", nargs="+", type=positive_int, default=None,
                         metavar="K",
                         help="score each log cut after each K actions (a log with fewer is "
                              "left out at that K) against the target's pose there, instead "
                              "of the whole episode; writes estimates_<method>_after_<K...>.csv")
    command.add_argument("--grasp-truth", action="store_true",
                         help="also grasp each episode's target at its true final pose, from "
                              "the logged final state (simulated, about 30 s a log): a column "
                              "true_pose_grasped; writes estimates_<method>..._grasp_truth.csv; "
                              "not with --after-actions (a log holds the plant's state only at "
                              "its end)")
    command.add_argument("--regrasp", action="store_true",
                         help="also grasp again at the hypotheses' chosen pose, from the "
                              "logged final state, with --hypothesis-params's settings (or "
                              "the table's), e.g. box_approach: end: a column regrasped; "
                              "writes estimates_<method>..._regrasp.csv; not with "
                              "--after-actions")
    command.add_argument("--scenes", nargs="+", default=None, metavar="SCENE",
                         help="with --grasp-truth or --regrasp: the scene files, or folders "
                              "of them, of the logs' layouts (the paper's scenes are found by "
                              "name)")
    command.add_argument("--workers", type=positive_int, default=1,
                         help="logs scored in parallel processes (default 1); the rows keep "
                              "the logs' order")
    command.set_defaults(run=run_estimates)


def _table_settings(out: Path):
    """(dx_model, STUCCO's parameters, filter stream, the target pose estimator's
    HypothesisParams or None for the defaults) the table folder ``out`` recorded."""
    from stucco_drake.core.hypothesis_params import HypothesisParams
    from stucco_drake.core.params import SoftTrackingParams
    from stucco_drake.core.settings import settings_with
    from stucco_drake.eval.cli_table import TABLE_CONFIG

    try:
        config = yaml.safe_load((out / TABLE_CONFIG).read_text(encoding="utf-8"))
        params = SoftTrackingParams.from_mapping(config["stucco_params"])
        # A folder recorded without the key, or with no changes, used the defaults.
        changes = config.get("hypothesis_params") or {}
        hypotheses = (settings_with(HypothesisParams(), changes, "hypothesis_params.")
                      if changes else None)  # fmt: skip
        return config["dx_model"], params, int(config.get("filter_stream", 0)), hypotheses
    except (OSError, yaml.YAMLError, KeyError, TypeError, ValueError, AttributeError) as error:
        raise InputError(f"--table {out}: no readable {TABLE_CONFIG} ({error})") from None


def _summary(rows: list[dict], confident_from: float | None = None) -> str:
    lines = ["base  n   rules near/median cm/closes   hypotheses near/median cm/closes   "
             "confidence   grasped"
             + ("   at the true pose" if "true_pose_grasped" in rows[0] else "")
             + ("   regrasped" if "regrasped" in rows[0] else "")]
    for base in sorted({row["base"] for row in rows}):
        group = [row for row in rows if row["base"] == base]
        parts = [f"{base:<4} {len(group):>2}"]
        for name in ("rules", "hypotheses"):
            error = np.array([row[f"{name}_outline_m"] for row in group])
            near = int(np.sum(error < NEAR))
            closes = sum(bool(row[f"{name}_closes"]) for row in group)
            parts.append(f"{near:>2}/{len(group)} {np.nanmedian(error) * 100:6.1f} {closes:>2}")
        confident = np.mean([row["confidence"] for row in group])
        grasped = [row["grasp_success"] for row in group if row["grasp_success"] is not None]
        parts.append(f"mean {confident:.2f}")
        parts.append(f"{sum(grasped)}/{len(grasped)}")
        for column in ("true_pose_grasped", "regrasped"):
            if column in group[0]:
                parts.append(f"{sum(row[column] for row in group)}/{len(group)}")
        lines.append("   ".join(parts))
    from stucco_drake.eval.sets import CONFIDENT_FROM
    from stucco_drake.eval.summary import calibration_lines

    threshold = CONFIDENT_FROM if confident_from is None else confident_from
    by_family = [{**row, "family": row["base"]} for row in rows]
    families = sorted({row["base"] for row in rows})
    return "\n".join([*lines, "", *calibration_lines(by_family, families, threshold)])


def _action_counts(given, paths) -> tuple[int, ...]:
    """The action counts to cut the logs after, in increasing order (() for none);
    InputError when no log of ``paths`` reaches the smallest."""
    if not given:
        return ()
    from stucco_drake.eval.episode_log import EpisodeLog

    after = tuple(sorted(set(given)))
    longest = max(EpisodeLog.load(path).n_actions for path in paths)
    if after[0] > longest:
        raise InputError(f"--after-actions: no log reaches {after[0]} actions (the longest "
                         f"has {longest})")
    return after


def _truth_scenes(args: argparse.Namespace, paths, after) -> dict[str, str] | None:
    """The scene file of each log's scene name, for ``--grasp-truth`` and ``--regrasp``
    (None without either); InputError for a scene file that does not read, a log whose scene
    is neither given nor shipped, or ``--scenes`` / ``--after-actions`` where they do not
    apply."""
    if not (args.grasp_truth or args.regrasp):
        if args.scenes:
            raise InputError("--scenes: only with --grasp-truth or --regrasp")
        return None
    flag = "--grasp-truth" if args.grasp_truth else "--regrasp"
    if after:
        raise InputError(f"{flag}: not with --after-actions (a log holds the plant's state "
                         "only at its end)")
    from stucco_drake.eval.episode_log import EpisodeLog
    from stucco_drake.scenes import SceneFileError, load_scene, resolve_scene_path, scene_paths

    files = {}
    try:
        for arg in args.scenes or []:
            for path in scene_paths(arg):
                files[load_scene(path).name] = str(path.resolve())
    except SceneFileError as error:
        raise InputError(f"--scenes: {error}") from None
    for name in sorted({EpisodeLog.load(path).scene for path in paths}):
        shipped = resolve_scene_path(name)
        if name not in files and not shipped.is_file():
            raise InputError(f"{flag}: no scene file for {name}; give it, or its "
                             "folder, with --scenes")
        files.setdefault(name, str(shipped))
    return files


def _cut_summary(rows: list[dict], confident_from: float | None = None) -> str:
    """Per base scene and action count: the runs cut there, in how many the hypotheses'
    grasp closes on the target's pose there, their mean confidence, and how many were
    confident (at least ``confident_from``, None: the project's threshold) and closed."""
    from stucco_drake.eval.sets import CONFIDENT_FROM

    threshold = CONFIDENT_FROM if confident_from is None else confident_from
    lines = [f"base  after  runs  closes  mean confidence  confident (>= {threshold}), closing"]
    for base in sorted({row["base"] for row in rows}):
        for k in sorted({row["after_actions"] for row in rows if row["base"] == base}):
            group = [r for r in rows if r["base"] == base and r["after_actions"] == k]
            closes = [bool(r["hypotheses_closes"]) for r in group]
            sure = [c for c, r in zip(closes, group, strict=True)
                    if r["confidence"] >= threshold]  # fmt: skip
            lines.append(f"{base:<4} {k:>5} {len(group):>5} {sum(closes):>7}   "
                         f"{np.mean([r['confidence'] for r in group]):14.2f}   "
                         f"{len(sure):>3} {sum(sure):>3}")
    return "\n".join(lines)


def _motion_scales(given) -> tuple[tuple[float, ...] | None, str]:
    """The motion scales to search and the output name's suffix for them (None and "" for
    the estimator's own, each log's as its episode's estimator searched them); InputError for
    a scale outside [0, 1]."""
    from stucco_drake.core.motion_scale import checked_scales

    if given is None:
        return None, ""
    try:
        checked_scales(given)
    except ValueError as error:
        raise InputError(f"--motion-scales: {error}") from None
    return tuple(given), "_scales_" + "_".join(f"{s:g}" for s in given)


def _check_slides_logged(paths, hypothesis_params) -> None:
    """InputError unless every log says what the estimator needs to search its motion scales
    (with ``still_when_unslidable``, the target's mass and friction and the push limit)."""
    from stucco_drake.eval.episode_log import EpisodeLog
    from stucco_drake.eval.target_estimates import log_motion_scales

    if not hypothesis_params.still_when_unslidable:
        return
    for path in paths:
        try:
            log_motion_scales(EpisodeLog.load(path), hypothesis_params)
        except ValueError as error:
            raise InputError(f"--hypothesis-params: {error}") from None


def score_log(path: Path, method: str, params, dx_model: str, stream: int, scales,
              hypothesis_params=None, after=None, truth_scenes=None,
              grasp_truth: bool = False, regrasp: bool = False) -> list[dict]:  # fmt: skip
    """The rows of :func:`~stucco_drake.eval.target_estimates.score_estimates` for ``method``
    replayed at the table's settings on one log (runs in a worker): one for the whole
    episode, or with ``after`` one per action count in it that the log reaches, each scoring
    the log cut there (``after_actions``). With ``truth_scenes`` (scene name -> file), the
    whole episode's row also says whether a grasp at the target's true pose lifts it
    (``grasp_truth``) and whether one at the hypotheses' chosen pose does (``regrasp``), a
    box gone down on as the hypotheses' settings say (``box_approach``)."""
    from stucco_drake.bor import log as bor_log
    from stucco_drake.core.hypothesis_params import HypothesisParams
    from stucco_drake.eval.episode_log import EpisodeLog
    from stucco_drake.eval.replay import replay
    from stucco_drake.eval.summary import layout_family
    from stucco_drake.eval.target_estimates import log_motion_scales, score_estimates

    log = EpisodeLog.load(path)
    penetration = bor_log.log_penetration(log)
    base = layout_family(log.scene)
    cuts = [k for k in after if k <= log.n_actions] if after else [None]
    scored = []

    if scales is None:
        scales = log_motion_scales(log, hypothesis_params)

    def score(replayed, tracker):
        scored.append(score_estimates(replayed, tracker, penetration, hypothesis_params,
                                      scales=scales))  # fmt: skip
        if regrasp:  # the whole episode only (refused with --after-actions)
            result = bor_log.grasp_from_log(log, tracker, truth_scenes[log.scene],
                                            "hypotheses", hypothesis_params)  # fmt: skip
            scored[-1]["regrasped"] = bool(result is not None and result.success)

    for k in cuts:
        replay(log if k is None else log.first(k), method, log.seed + 1000 * stream,
               params if method == "stucco" else None, penetration=penetration,
               dx_model=dx_model, grasp=score)  # fmt: skip
    if truth_scenes is not None and grasp_truth:
        grasp = hypothesis_params or HypothesisParams()
        result = bor_log.grasp_true_pose(log, truth_scenes[log.scene],
                                         box_approach=grasp.box_approach,
                                         withdraw_when_blocked=grasp.withdraw_when_blocked)
        scored[0]["true_pose_grasped"] = bool(result.success)
    return [{"base": base, **({} if k is None else {"after_actions": k}), **row}
            for k, row in zip(cuts, scored, strict=True)]


def run_estimates(args: argparse.Namespace) -> int:
    """Handler of ``stucco-drake estimates``."""
    from stucco_drake.eval.results import RunResults
    from stucco_drake.eval.runner import make_executor

    out = Path(args.table)
    scales, suffix = _motion_scales(args.motion_scales)
    hypothesis_params, _ = hypothesis_settings_of(args.hypothesis_params)
    if args.stucco_params is not None:  # a bad file is refused before the table is read
        if args.method != "stucco":
            raise InputError(f"--stucco-params: only with --method stucco, not {args.method}")
        from stucco_drake.core.params import SoftTrackingParams

        read_settings("--stucco-params", args.stucco_params, SoftTrackingParams.sim())
    dx_model, params, stream, recorded = _table_settings(out)
    if args.stucco_params is not None:  # on top of the table's recorded parameters
        params = read_settings("--stucco-params", args.stucco_params, params)
        suffix = "_" + Path(args.stucco_params).stem + suffix
    if hypothesis_params is None:  # the table's own, as its grasps were made with
        hypothesis_params = recorded
    else:
        suffix += "_" + Path(args.hypothesis_params).stem
    paths = sorted((out / "logs").glob("*.npz"))
    if not paths:
        raise InputError(f"--table {out}: no episode logs in {out / 'logs'}")
    if scales is None and hypothesis_params is not None:
        _check_slides_logged(paths, hypothesis_params)
    after = _action_counts(args.after_actions, paths)
    if after:
        suffix += "_after_" + "_".join(str(k) for k in after)
    truth_scenes = _truth_scenes(args, paths, after)
    suffix += "_grasp_truth" if args.grasp_truth else ""
    suffix += "_regrasp" if args.regrasp else ""
    grasped = {(row["scene"], row["seed"]): row["grasp_success"]
               for row in RunResults(out / "runs.csv").rows()
               if row["method"] == args.method}  # fmt: skip
    task = functools.partial(score_log, method=args.method, params=params, dx_model=dx_model,
                             stream=stream, scales=scales,
                             hypothesis_params=hypothesis_params, after=after,
                             truth_scenes=truth_scenes, grasp_truth=args.grasp_truth,
                             regrasp=args.regrasp)
    rows = []
    # A cut's row keeps the whole episode's grasp under another name: it is not the cut's.
    joined = "episode_grasped" if after else "grasp_success"
    with make_executor("process", args.workers) as executor:
        for scored in executor.map(task, paths):
            for row in scored:
                row[joined] = grasped.get((row["scene"], row["seed"]))
                rows.append(row)
                print(" ".join(f"{k}={v:.4g}" if isinstance(v, float) and not math.isnan(v)
                               else f"{k}={v}" for k, v in row.items()), flush=True)  # fmt: skip
    target = out / f"estimates_{args.method}{suffix}.csv"
    with target.open("w", newline="", encoding="utf-8") as file:
        writer = csv.DictWriter(file, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    print(_cut_summary(rows, args.confident_from) if after
          else _summary(rows, args.confident_from))
    print(f"{len(rows)} rows of {len(paths)} logs in {target}")
    return 0
