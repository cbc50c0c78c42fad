"""The ``stucco-drake table`` subcommand: Table II and its FMI/CE figure, resumably.

Each episode (scene, seed) is simulated once by its scene's
:class:`~stucco_drake.eval.sources.EpisodeSource` into ``OUT/logs/<scene>_<seed>.npz`` and
replayed by every method; every finished run is appended to ``OUT/runs.csv``; ``OUT/table.md``
and ``OUT/fmi_ce.png`` are written from all recorded runs of the requested table. Rerunning
the same command skips what is done.
"""

from __future__ import annotations

import argparse
import concurrent.futures as cf
import functools
import sys
from collections.abc import Mapping, Sequence
from pathlib import Path

import yaml

from stucco_drake.core.baselines import TRACKER_NAMES
from stucco_drake.core.contact_motion import DX_MODELS, DX_MODELS_SUMMARY
from stucco_drake.core.inputs import (
    InputError,
    hypothesis_settings_of,
    non_negative_int,
    policy_settings_of,
    positive_int,
    prepare_output_folder,
    read_stucco_params,
)
from stucco_drake.core.params import SoftTrackingParams
from stucco_drake.eval.episode_log import EpisodeLog
from stucco_drake.eval.replay import replay
from stucco_drake.eval.results import RunResults, row_key
from stucco_drake.eval.runner import Progress, RunInterrupted, make_executor, run_table
from stucco_drake.eval.sets import describe_sets
from stucco_drake.eval.sources import SYNTHETIC_SOURCES, EpisodeSource
from stucco_drake.eval.table import plot_fmi_ce, write_table

Sources = Mapping[str, EpisodeSource]


def check_names(scenes: Sequence[str], methods: Sequence[str],
                sources: Sources = SYNTHETIC_SOURCES) -> None:
    """ValueError naming every unknown scene (not in ``sources``) and method."""
    problems = []
    bad_scenes = [s for s in scenes if s not in sources]
    bad_methods = [m for m in methods if m not in TRACKER_NAMES]
    if bad_scenes:
        problems.append(f"unknown scene(s) {', '.join(map(repr, bad_scenes))} "
                        f"(known: {', '.join(sources)})")
    if bad_methods:
        problems.append(f"unknown method(s) {', '.join(map(repr, bad_methods))} "
                        f"(known: {', '.join(TRACKER_NAMES)})")
    if problems:
        raise ValueError("; ".join(problems))


def episode_path(out: Path, scene: str, seed: int) -> Path:
    return Path(out) / "logs" / f"{scene}_{seed}.npz"


def produce_episode(episode: tuple[str, int], out: str, source: EpisodeSource) -> str:
    """Simulate one episode and save its log (runs in a worker); returns its path."""
    scene, seed = episode
    path = episode_path(Path(out), scene, seed)
    source.produce(scene, seed).save(path)
    return str(path)


def load_cached_log(out, scene: str, seed: int) -> EpisodeLog:
    """The cached log of episode (scene, seed) under ``out``; ValueError if it holds another."""
    log = EpisodeLog.load(episode_path(Path(out), scene, seed))
    if (log.scene, log.seed) != (scene, seed):
        raise ValueError(f"log of {scene}_{seed} holds episode {log.scene}_{log.seed}")
    return log


def replay_penetration(source: EpisodeSource, log: EpisodeLog, method: str, dx_model: str):
    """The robot's pxpen a replay of ``method`` on ``log`` needs: the source's for STUCCO, and
    for any method under a contact motion other than ``"ee"``, whose normals come from the
    robot's geometry (None when neither applies)."""
    penetration = source.penetration_for(log, method)
    if dx_model != "ee" and penetration is None and source.penetration is not None:
        penetration = source.penetration(log)
    return penetration


#: Stream K of a table seeds every tracker's generator with the episode's seed + K times this
#: (stream 0, the default, with the episode's seed itself).
STREAM_STRIDE = 1000
#: Where a table's grasps are made (see :func:`~stucco_drake.bor.log.grasp_from_log`).
TARGET_ESTIMATORS = ("rules", "hypotheses")


def replay_cached(task: tuple[str, int, str], out: str, sources: Sources,
                  dx_model: str = "ee", stucco_params: SoftTrackingParams | None = None,
                  filter_stream: int = 0, target_estimator: str = "rules") -> dict:  # fmt: skip
    """One run (scene, seed, method) replayed from its cached log, with the scene source's
    pxpen and grasp, contact motion ``dx_model``, for STUCCO ``stucco_params`` (None: the
    paper's Table I), and the trackers' generator seeded by ``filter_stream`` (see
    :data:`STREAM_STRIDE`); the grasp at ``target_estimator``'s estimate (``"rules"``, Table
    II's, or ``"hypotheses"``; see :func:`~stucco_drake.bor.log.grasp_from_log`) (runs in a
    worker)."""
    scene, seed, method = task
    log, source = load_cached_log(out, scene, seed), sources[scene]
    penetration = replay_penetration(source, log, method, dx_model)
    params = stucco_params if method == "stucco" else None
    grasp = source.grasp
    if grasp is not None and target_estimator != "rules":
        grasp = functools.partial(grasp, estimator=target_estimator)
    return replay(log, method, seed=seed + STREAM_STRIDE * filter_stream, params=params,
                  penetration=penetration, grasp=grasp, dx_model=dx_model)


def simulate_missing(episodes, out: Path, executor: cf.Executor, progress,
                      sources: Sources) -> None:
    """Simulate the episodes whose logs are not cached yet, in parallel."""
    missing = [e for e in episodes if not episode_path(out, *e).exists()]
    if not missing:
        return
    bar = Progress(len(missing), "episodes", stream=progress)
    futures = {executor.submit(produce_episode, e, str(out), sources[e[0]]): e for e in missing}
    errors = []
    try:
        for future in cf.as_completed(futures):
            try:
                future.result()
                bar.advance()
            except Exception as error:  # collect, so every finished log is kept
                errors.append((futures[future], error))
    finally:
        bar.close()
    if errors:
        (scene, seed), error = errors[0]
        raise RunInterrupted(
            f"simulating {scene}_{seed} failed ({type(error).__name__}: "
            f"{str(error).splitlines()[0] if str(error) else ''}); {len(errors)} episode(s) "
            f"missing: rerun the same command to resume"
        ) from error


#: What ``OUT/table_config.yaml`` records: the settings every row of OUT was made with.
TABLE_CONFIG = "table_config.yaml"


def _plain(mapping):
    """``mapping`` as YAML reads it back: lists, plain floats."""
    return yaml.safe_load(yaml.safe_dump(mapping))


def complete_config(recorded: Mapping) -> dict:
    """A table config as read (a mapping with at least ``dx_model`` and ``stucco_params``),
    each setting it lacks, written before that setting existed, at its default then, and
    STUCCO's parameters completed with Table I's: configs of the same settings compare equal."""
    return {**recorded, "filter_stream": recorded.get("filter_stream", 0),
            "target_estimator": recorded.get("target_estimator", "rules"),
            "policy": recorded.get("policy", "prescribed"),
            "policy_params": recorded.get("policy_params") or {},
            "hypothesis_params": recorded.get("hypothesis_params") or {},
            "stucco_params": {**_plain(SoftTrackingParams.sim().to_mapping()),
                              **recorded["stucco_params"]}}  # fmt: skip


def check_table_config(out: Path, dx_model: str, stucco_params: SoftTrackingParams | None,
                       filter_stream: int = 0, target_estimator: str = "rules",
                       policy: str = "prescribed", policy_params: Mapping | None = None,
                       hypothesis_params: Mapping | None = None) -> None:  # fmt: skip
    """Records in ``OUT/table_config.yaml`` the contact motion, STUCCO's full parameters
    (Table I when None), the filter stream, the target estimator of the grasps, the
    policy that chose the actions and how its settings differ from their defaults
    (``policy_params``, plain values; None: they do not) and how the target pose
    estimator's differ from theirs (``hypothesis_params``, likewise) the rows of ``out`` are
    made with, or, when the file exists, checks that they are the same: rows are keyed by
    scene, seed and method only, so rows of two settings in one folder would pass for each
    other. A file written before a setting existed counts at that setting's default.
    ValueError naming the first setting that differs."""
    params = stucco_params if stucco_params is not None else SoftTrackingParams.sim()
    config = _plain({"dx_model": dx_model, "stucco_params": params.to_mapping(),
                    "filter_stream": int(filter_stream),
                    "target_estimator": target_estimator, "policy": policy,
                    "policy_params": dict(policy_params or {}),
                    "hypothesis_params": dict(hypothesis_params or {})})  # fmt: skip
    path = Path(out) / TABLE_CONFIG
    if not path.exists():
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text("# the settings every row of runs.csv here was made with\n"
                        + yaml.safe_dump(config, sort_keys=False), encoding="utf-8")
        return
    try:
        recorded = yaml.safe_load(path.read_text(encoding="utf-8"))
    except yaml.YAMLError:
        recorded = None
    if (not isinstance(recorded, dict) or not {"dx_model", "stucco_params"} <= set(recorded)
            or not set(recorded) <= set(config)
            or not isinstance(recorded["stucco_params"], dict)):  # fmt: skip
        raise ValueError(f"{path} is not a table config (expected keys dx_model, stucco_params"
                         f" and optionally filter_stream, target_estimator, policy, "
                         f"policy_params, hypothesis_params)")
    old = complete_config(recorded)
    settings = [("--dx-model ", old["dx_model"], dx_model),
                ("--filter-stream ", old["filter_stream"], config["filter_stream"]),
                ("--target-estimator ", old["target_estimator"], target_estimator),
                ("--policy ", old["policy"], policy),
                ("--policy-params ", old["policy_params"], config["policy_params"]),
                ("--hypothesis-params ", old["hypothesis_params"], config["hypothesis_params"])]
    settings += [(f"STUCCO's {name} = ", repr(old["stucco_params"][name]), repr(value))
                 for name, value in config["stucco_params"].items()]  # fmt: skip
    for label, old, new in settings:
        if old != new:
            raise ValueError(f"{path}: the rows here were made with {label}{old}, not {new}; "
                             f"use another --out")


def make_table(
    scenes: Sequence[str],
    methods: Sequence[str],
    runs: int,
    out,
    executor: cf.Executor,
    progress=None,
    sources: Sources = SYNTHETIC_SOURCES,
    dx_model: str = "ee",
    stucco_params: SoftTrackingParams | None = None,
    filter_stream: int = 0,
    target_estimator: str = "rules",
    policy: str = "prescribed",
    policy_params: Mapping | None = None,
    hypothesis_params: Mapping | None = None,
) -> list[dict]:
    """Simulate, replay and tabulate seeds 0..runs-1 of every scene and method.

    ``sources`` maps each scene name to its :class:`EpisodeSource`; ``dx_model`` is how every
    method moves contact points (see :func:`~stucco_drake.eval.replay.replay`) and
    ``stucco_params`` STUCCO's parameters (None: Table I) and ``filter_stream`` which draws
    the trackers take (0: seeded with the episode's seed, as the paper's tables; K: another
    stream of draws on the same episodes, see :data:`STREAM_STRIDE`); ``target_estimator``
    where the grasps are made (see :func:`replay_cached`); ``policy`` names what chose the
    episodes' actions and ``policy_params`` how its settings differ from their defaults, and
    ``hypothesis_params`` how the target pose estimator's do (both recorded only: ``sources``
    produce and grasp with them). Scenes whose sources share a
    ``family`` (the randomized layouts of one base scene) are tabled as one column group, their
    runs pooled. Rows are keyed by
    scene, seed and method only, so an OUT folder holds one of each: :func:`check_table_config`
    refuses another setting in a folder that holds one. Returns the table's rows (from
    ``OUT/runs.csv``, including runs of earlier calls).
    """
    check_names(scenes, methods, sources)
    if runs < 1:
        raise ValueError(f"runs must be positive, got {runs}")
    if filter_stream < 0:
        raise ValueError(f"filter_stream must be 0 or more, got {filter_stream}")
    out = Path(out)
    if target_estimator not in TARGET_ESTIMATORS:
        raise ValueError(f"target_estimator: expected one of {TARGET_ESTIMATORS}, "
                         f"got {target_estimator!r}")
    check_table_config(out, dx_model, stucco_params, filter_stream, target_estimator, policy,
                       policy_params, hypothesis_params)
    results = RunResults(out / "runs.csv")
    replay_task = functools.partial(replay_cached, out=str(out), sources=dict(sources),
                                    dx_model=dx_model, stucco_params=stucco_params,
                                    filter_stream=filter_stream,
                                    target_estimator=target_estimator)
    wanted = {(scene, seed, method) for seed in range(runs) for scene in scenes
              for method in methods}  # fmt: skip

    # A family's layouts (randomized from one base scene) share one column group.
    family = {scene: sources[scene].family or scene for scene in scenes}
    columns = list(dict.fromkeys(family[scene] for scene in scenes))

    def tabulate() -> list[dict]:
        rows = [row for row in results.rows() if row_key(row) in wanted]
        grouped = [{**row, "scene": family[row["scene"]]} for row in rows]
        write_table(grouped, columns, methods, out / "table.md")
        plot_fmi_ce(grouped, out / "fmi_ce.png", columns, methods)
        return rows

    # Seed by seed: simulate that seed's episodes of every scene, replay them and rewrite the
    # table, so an interrupted table shows complete rows for every seed it reached.
    for seed in range(runs):
        seed_tasks = [(scene, seed, method) for scene in scenes for method in methods]
        if set(seed_tasks) <= results.done():
            continue
        simulate_missing([(scene, seed) for scene in scenes], out, executor, progress, sources)
        run_table(seed_tasks, replay_task, results, executor, progress)
        tabulate()
    return tabulate()


def add_table_command(subparsers, sources: Sources = SYNTHETIC_SOURCES, resolve=None,
                      policies: Mapping | None = None,
                      policy_settings: Mapping | None = None) -> None:  # fmt: skip
    """Adds ``table`` to the CLI's subparsers, over the scenes of ``sources`` and, with
    ``resolve(args, sources) -> (scene names, sources)``, whatever else it resolves (scene
    files). ``policies`` maps each closed-loop policy ``--policy`` offers besides
    ``prescribed`` to ``make(source, scene, stucco_params, dx_model, settings=...) ->
    EpisodeSource``, the source whose episodes that policy drives with those settings
    (ValueError for a scene it cannot); ``policy_settings`` maps it to its settings class
    (``--policy-params`` overrides its defaults)."""
    policies = dict(policies or {})
    table = subparsers.add_parser(
        "table", help="replay every method on logged episodes; write Table II and Fig. 5"
    )
    table.add_argument("--runs", type=positive_int, default=20,
                       help="seeds 0..RUNS-1 per scene")
    table.add_argument("--scenes", nargs="+", required=True,
                       help=f"scene names ({', '.join(sources)})"
                            + (", scene files or folders of them" if resolve else ""))
    table.add_argument("--methods", nargs="+", default=list(TRACKER_NAMES),
                       help=f"tracking methods (default: {' '.join(TRACKER_NAMES)})")
    table.add_argument("--out", required=True, help="output folder (logs, runs.csv, table)")
    table.add_argument("--dx-model", choices=DX_MODELS, default="ee",
                       help=f"how contact points move ({DX_MODELS_SUMMARY})")
    table.add_argument("--stucco-params", metavar="PARAMS.yaml", default=None,
                       help="STUCCO's parameters as YAML overrides of Table I (default: Table I)")
    table.add_argument("--filter-stream", type=non_negative_int, default=0, metavar="K",
                       help="seed the trackers with the episode's seed + K x "
                            f"{STREAM_STRIDE} (default 0: the episode's seed); another K "
                            "replays the same episodes with other draws")
    table.add_argument("--target-estimator", choices=TARGET_ESTIMATORS, default="hypotheses",
                       help="where the grasps are made: 'hypotheses' (default: the grasp "
                            "chosen across weighted pose hypotheses) or 'rules' (the segment "
                            "selection of results/table_ii)")
    table.add_argument("--policy", choices=("prescribed", *policies), default="prescribed",
                       help="what chooses the actions: the scene's prescribed list (default)"
                            + (", or after it 'probe': guarded touches where STUCCO's live "
                               "pose hypotheses disagree, then of the likeliest pose"
                               if "probe" in policies
                               else ""))
    table.add_argument("--policy-params", metavar="SETTINGS.yaml", default=None,
                       help="the policy's settings as YAML overrides of its defaults (nested "
                            "mappings for nested settings); recorded in OUT/table_config.yaml")
    table.add_argument("--hypothesis-params", metavar="SETTINGS.yaml", default=None,
                       help="the target pose estimator's HypothesisParams as YAML overrides of "
                            "its defaults, for the live estimator and the grasps (Drake scenes "
                            "only); the changes are recorded in OUT/table_config.yaml")
    table.add_argument("--workers", type=positive_int, default=None,
                       help="parallel workers (default: one per CPU)")
    table.add_argument("--executor", choices=("process", "dask"), default="process",
                       help="local process pool, or a Dask cluster")
    table.add_argument("--scheduler", default=None,
                       help="Dask scheduler address (default: start a local cluster)")
    table.set_defaults(run=functools.partial(run_table_command, sources=sources,
                                             resolve=resolve, policies=policies,
                                             policy_settings=policy_settings))


def run_table_command(args: argparse.Namespace, sources: Sources = SYNTHETIC_SOURCES,
                      resolve=None, policies: Mapping | None = None,
                      policy_settings: Mapping | None = None) -> int:  # fmt: skip
    """Handler of ``stucco-drake table``: 0 done, 1 interrupted (rerun resumes); a bad input
    raises InputError (the CLI's main reports it) before any simulation. ``resolve``,
    ``policies`` and ``policy_settings`` as :func:`add_table_command`'s; each scene's set is
    printed first."""
    stucco_params = read_stucco_params(args.stucco_params)
    policy = getattr(args, "policy", "prescribed")
    settings, changes = policy_settings_of(policy, getattr(args, "policy_params", None),
                                           policy_settings or {})
    hypothesis_params, hypothesis_changes = hypothesis_settings_of(
        getattr(args, "hypothesis_params", None))
    if args.scheduler is not None and args.executor != "dask":
        raise InputError("--scheduler needs --executor dask")
    try:
        scenes = args.scenes
        if resolve is not None:
            scenes, sources = resolve(args.scenes, sources)
        check_names(scenes, args.methods, sources)
        if policy != "prescribed":
            make = functools.partial((policies or {})[policy], settings=settings)
            sources = {**sources, **{scene: make(sources[scene], scene, stucco_params,
                                                 args.dx_model) for scene in scenes}}
        if hypothesis_params is not None:  # wraps the policy's producer, if any
            sources = {**sources, **{scene: sources[scene].with_hypothesis_params(
                hypothesis_params, scene) for scene in scenes}}
    except ValueError as error:
        raise InputError(str(error)) from None
    out = prepare_output_folder("--out", args.out)
    try:
        # OUT's rows of other settings, or a runs file of another version, are refused now.
        check_table_config(out, args.dx_model, stucco_params, args.filter_stream,
                           args.target_estimator, policy, changes, hypothesis_changes)
        RunResults(out / "runs.csv").rows()
        executor = make_executor(args.executor, args.workers, args.scheduler)
    except (ValueError, RuntimeError) as error:  # RuntimeError: the Dask executor without Dask
        raise InputError(str(error)) from None
    print(describe_sets({scene: sources[scene].scene_set for scene in scenes}))
    try:
        with executor:
            rows = make_table(scenes, args.methods, args.runs, out, executor,
                              sources=sources, dx_model=args.dx_model,
                              stucco_params=stucco_params,
                              filter_stream=args.filter_stream,
                              target_estimator=args.target_estimator, policy=policy,
                              policy_params=changes, hypothesis_params=hypothesis_changes)
    except RunInterrupted as error:
        print(f"stucco-drake table: {error}", file=sys.stderr)
        return 1
    print((out / "table.md").read_text(encoding="utf-8"), end="")
    print(f"{len(rows)} runs in {out / 'runs.csv'}; figure {out / 'fmi_ce.png'}")
    return 0
