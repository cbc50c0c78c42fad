"""Parameter sweeps on a training set (paper Sec. V-B, "Training Set for Tuning"), resumably.

Each trial (scene, seed) is simulated once by its scene's
:class:`~stucco_drake.eval.sources.EpisodeSource` into ``OUT/logs/<scene>_<seed>.npz`` (the
layout of ``stucco-drake table``); trials marked discarded (``info["discarded"]``) are
skipped. Every parameter combination of the grid is replayed on every kept trial; each
finished replay is appended to ``OUT/sweep.csv`` (a runs file, see
:class:`~stucco_drake.eval.results.RunResults`, whose ``method`` column is the combination's
label, e.g. ``stucco[length=0.02]``), so a rerun skips what is done. The tuned combination
maximises the median FMI over all kept trials and, among equal medians, minimises the median
CE; it is written to ``OUT/tuned_<method>.yaml`` (``tuned_<method>_<dx_model>.yaml`` under a
contact motion other than the paper's) with both medians overall and on the ambiguous trials
(ambiguity >= :data:`AMBIGUOUS`). ``OUT/fmi_ce.png`` and ``OUT/tuned.md`` then compare the
tuned combinations of every sweep done in ``OUT`` (the paper's Fig. 4).
"""

from __future__ import annotations

import concurrent.futures as cf
import dataclasses
import functools
import itertools
import math
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np
import yaml

from stucco_drake.core.baselines import (
    TRACKER_NAMES,
    BirchParams,
    DbscanParams,
    GmPhdParams,
    KMeansParams,
)
from stucco_drake.core.contact_motion import DX_MODELS
from stucco_drake.core.metrics import paired_median_gap
from stucco_drake.core.params import SoftTrackingParams
from stucco_drake.eval.cli_table import (
    check_names,
    episode_path,
    load_cached_log,
    replay_penetration,
    simulate_missing,
)
from stucco_drake.eval.episode_log import EpisodeLog
from stucco_drake.eval.replay import replay
from stucco_drake.eval.results import RunResults
from stucco_drake.eval.runner import run_table
from stucco_drake.eval.sources import SYNTHETIC_SOURCES, EpisodeSource
from stucco_drake.eval.table import AMBIGUOUS_RUN, METHOD_LABELS, plot_fmi_ce

#: A trial is ambiguous when its ambiguity is at least this (paper Sec. V-B, Fig. 4 bottom;
#: the same threshold as the test table's plot).
AMBIGUOUS = AMBIGUOUS_RUN
#: Each method's parameter dataclass (its fields are what a grid may sweep).
PARAMS_CLASSES = {
    "stucco": SoftTrackingParams,
    "birch": BirchParams,
    "dbscan": DbscanParams,
    "kmeans": KMeansParams,
    "gmphd": GmPhdParams,
}
#: The grid swept when none is given: each method's primary parameter around its paper value
#: (STUCCO's characteristic length l in m^2; BIRCH's threshold and DBSCAN's eps in m).
DEFAULT_GRIDS = {
    "stucco": {"length": (0.006, 0.01, 0.02, 0.04)},
    "birch": {"threshold": (0.04, 0.06, 0.08, 0.1, 0.12)},
    "dbscan": {"eps": (0.03, 0.05, 0.07, 0.1)},
    "kmeans": {"inertia_ratio": (0.1, 0.2, 0.3, 0.5)},
    "gmphd": {"detection": (0.1, 0.3, 0.5)},
}
assert set(PARAMS_CLASSES) == set(TRACKER_NAMES) == set(DEFAULT_GRIDS)
#: Seed of the bootstrap behind each combination's median-CE gap to the tuned one: fixed, so
#: the same ``sweep.csv`` always gives the same tuned file.
GAP_SEED = 0

Sources = Mapping[str, EpisodeSource]
Grid = dict[str, tuple]


# ------------------------------------------------------------------------------------ grids
def _parse_value(text: str, kind: type, where: str):
    """One grid value of a field whose default is of type ``kind`` (``NoneType``: an
    optional number, off by default, whose value may be ``none`` or a number)."""
    text = text.strip()
    if kind is type(None):
        if text.lower() == "none":
            return None
        kind = float
    if kind is bool:
        if text.lower() in ("true", "1", "yes"):
            return True
        if text.lower() in ("false", "0", "no"):
            return False
        raise ValueError(f"{where}: {text!r} is not true or false")
    try:
        if kind is int:
            value = float(text)
            if not value.is_integer():
                raise ValueError
            return int(value)
        value = float(text)
    except ValueError:
        raise ValueError(f"{where}: {text!r} is not {'an integer' if kind is int else 'a number'}"
                         ) from None
    if not math.isfinite(value):
        raise ValueError(f"{where}: {text!r} is not finite")
    return value


def make_params(method: str, combination: Mapping):
    """The full parameters of ``method`` with ``combination``'s overrides (STUCCO: on the sim
    preset, as :func:`~stucco_drake.core.baselines.make_tracker` does with a mapping)."""
    return PARAMS_CLASSES[method].from_mapping(dict(combination))


def parse_grid(method: str, entries: Sequence[str] | None) -> Grid:
    """The grid of ``--grid name=v1,v2,...`` entries (default :data:`DEFAULT_GRIDS`).

    Values take the type of the field's default (number, integer, true/false; ``none`` or a
    number for an optional field that is off by default, e.g. STUCCO's
    ``touched_side_margin``). Raises a
    one-line ValueError naming the bad entry: no ``=``, an unknown or repeated parameter, an
    empty or malformed value, or a value the method's parameters reject.
    """
    if method not in PARAMS_CLASSES:
        raise ValueError(f"unknown method {method!r} (known: {', '.join(TRACKER_NAMES)})")
    if not entries:
        return {name: tuple(values) for name, values in DEFAULT_GRIDS[method].items()}
    cls = PARAMS_CLASSES[method]
    defaults = {f.name: getattr(cls(), f.name) for f in dataclasses.fields(cls)}
    sweepable = [n for n, v in defaults.items() if v is None or isinstance(v, bool | int | float)]
    grid: Grid = {}
    for entry in entries:
        where = f"--grid {entry!r}"
        name, sep, values = entry.partition("=")
        name = name.strip()
        if not sep or not name:
            raise ValueError(f"{where}: expected name=v1,v2,...")
        if name not in sweepable:
            raise ValueError(
                f"{where}: {method} has no sweepable parameter {name!r} "
                f"(known: {', '.join(sweepable)})"
            )
        if name in grid:
            raise ValueError(f"{where}: {name} is given twice")
        texts = [v for v in values.split(",") if v.strip()]
        if not texts:
            raise ValueError(f"{where}: no values")
        parsed = [_parse_value(v, type(defaults[name]), where) for v in texts]
        for value in parsed:
            try:
                make_params(method, {name: value})
            except (ValueError, TypeError) as error:
                raise ValueError(f"{where}: {str(error).splitlines()[0]}") from None
        grid[name] = tuple(dict.fromkeys(parsed))  # repeated values count once
    return grid


def combinations(grid: Grid) -> list[dict]:
    """Every combination of the grid's values (parameters in sorted order; {} for no grid)."""
    names = sorted(grid)
    return [dict(zip(names, values, strict=True))
            for values in itertools.product(*(grid[n] for n in names))]  # fmt: skip


def combination_label(method: str, combination: Mapping, dx_model: str = "ee") -> str:
    """The combination's key in ``sweep.csv``, e.g. ``dbscan[eps=0.05 min_samples=1]``; a
    contact-motion model other than the paper's is named after the method, e.g.
    ``stucco@normal[length=0.02]``, so runs of the two models never stand for each other."""
    inner = " ".join(f"{name}={combination[name]!r}" for name in sorted(combination))
    model = "" if dx_model == "ee" else f"@{dx_model}"
    return f"{method}{model}[{inner}]"


def tuned_path(out: Path, method: str, dx_model: str = "ee") -> Path:
    """``OUT/tuned_<method>.yaml``, or ``OUT/tuned_<method>_<dx_model>.yaml`` off the paper's
    contact motion."""
    return Path(out) / (f"tuned_{method}.yaml" if dx_model == "ee"
                        else f"tuned_{method}_{dx_model}.yaml")  # fmt: skip


# ---------------------------------------------------------------------------------- running
def kept_trials(out: Path, trials: Sequence[tuple[str, int]]) -> list[tuple[str, int]]:
    """The cached trials not marked discarded."""
    kept = []
    for scene, seed in trials:
        log = EpisodeLog.load(episode_path(out, scene, seed))
        if not log.info.get("discarded", False):
            kept.append((scene, seed))
    return kept


def replay_combination(task: tuple[str, int, str], out: str, method: str,
                       combos: Mapping[str, dict], sources: Sources,
                       dx_model: str = "ee") -> dict:  # fmt: skip
    """One sweep run (scene, seed, combination label) replayed from its cached log, with the
    scene source's pxpen (runs in a worker); its row's ``method`` is the label."""
    scene, seed, label = task
    log, source = load_cached_log(out, scene, seed), sources[scene]
    row = replay(log, method, params=combos[label],
                 penetration=replay_penetration(source, log, method, dx_model),
                 dx_model=dx_model)
    return {**row, "method": label}


def _medians(rows: list[dict]) -> dict:
    """n, median FMI and median CE (cm) of rows, NaN-ignoring (NaN when none)."""
    def median(key):
        values = np.array([row[key] for row in rows], dtype=np.float64)
        values = values[np.isfinite(values)]
        return float(np.median(values)) if len(values) else float("nan")

    return {"n_runs": len(rows), "median_fmi": median("fmi"), "median_ce_cm": median("ce_cm")}


def summarize(rows: Sequence[dict], method: str, combos: Sequence[dict],
              dx_model: str = "ee") -> list[dict]:  # fmt: skip
    """Per combination: its params, medians over all rows and over ambiguous rows."""
    by_label = {}
    for row in rows:
        by_label.setdefault(row["method"], []).append(row)
    summary = []
    for combo in combos:
        mine = by_label.get(combination_label(method, combo, dx_model), [])
        ambiguous = [r for r in mine if np.isfinite(r["ambiguity"]) and r["ambiguity"] >= AMBIGUOUS]
        summary.append({"params": dict(combo), **_medians(mine), "ambiguous": _medians(ambiguous)})
    return summary


def best_combination(summary: Sequence[dict]) -> dict:
    """The summary entry of highest median FMI, then lowest median CE (NaN ranks last)."""
    def key(entry):
        fmi, ce = entry["median_fmi"], entry["median_ce_cm"]
        return (-fmi if math.isfinite(fmi) else math.inf, ce if math.isfinite(ce) else math.inf)

    return min(summary, key=key)  # min keeps the first of equal keys: grid order breaks ties


def add_ce_gaps(summary: Sequence[dict], rows: Sequence[dict], best: dict, method: str,
                dx_model: str = "ee", seed: int = GAP_SEED) -> None:  # fmt: skip
    """Gives every summary entry ``ce_gap_to_tuned``: how much its median CE (cm) lies above
    the tuned combination's, paired by trial, with a bootstrap 95 % interval
    (:func:`~stucco_drake.core.metrics.paired_median_gap`; None without a common trial). The
    medians of neighbouring settings are often within noise of each other: an interval that
    holds 0 says the training set does not rank the two."""
    ce = {}
    for row in rows:
        ce.setdefault(row["method"], {})[(row["scene"], row["seed"])] = row["ce_cm"]
    reference = ce.get(combination_label(method, best["params"], dx_model), {})
    rng = np.random.default_rng(seed)
    for entry in summary:
        mine = ce.get(combination_label(method, entry["params"], dx_model), {})
        trials = sorted(set(mine) & set(reference))
        try:
            entry["ce_gap_to_tuned"] = paired_median_gap(
                [mine[t] for t in trials], [reference[t] for t in trials], rng)
        except ValueError:  # no trial with both finite
            entry["ce_gap_to_tuned"] = None


def _plain(value):
    """YAML-safe copy: tuples as lists, numpy scalars as Python numbers."""
    if isinstance(value, Mapping):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_plain(v) for v in value]
    if isinstance(value, np.generic):
        return value.item()
    return value


def write_tuned(path: Path, method: str, best: dict, summary: Sequence[dict], scenes,
                n_trials: int, n_kept: int, dx_model: str = "ee") -> dict:  # fmt: skip
    """Writes the tuned document to ``path`` and returns it: the method, the contact-motion
    model replayed, its full tuned ``params`` (every field, loadable by its
    ``from_mapping``), the ``swept`` values, their medians (FMI; CE in cm) over all kept
    trials and over the ambiguous ones, the trial counts (over all scenes) and the summary of
    every combination."""
    document = _plain({
        "method": method,
        "dx_model": dx_model,
        "params": dataclasses.asdict(make_params(method, best["params"])),
        "swept": best["params"],
        "selection": "max median FMI, then min median CE (cm), over all kept trials",
        "median_fmi": best["median_fmi"],
        "median_ce_cm": best["median_ce_cm"],
        "n_runs": best["n_runs"],
        "ambiguous": {"threshold": AMBIGUOUS, **best["ambiguous"]},
        "scenes": list(scenes),
        "n_trials": n_trials,
        "n_kept_trials": n_kept,
        "combinations": list(summary),
    })  # fmt: skip
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(".yaml.tmp")
    tmp.write_text(yaml.safe_dump(document, sort_keys=False), encoding="utf-8")
    tmp.replace(path)  # atomic: a reader never sees half a file
    return document


def training_summary(out) -> list[dict]:
    """The paper's Fig. 4 from every sweep done in ``out``: each ``tuned_*.yaml``'s tuned
    combination, its runs (from ``sweep.csv``, on that sweep's trials) plotted as FMI against
    CE (cm) into ``OUT/fmi_ce.png`` (all runs; runs of ambiguity >= :data:`AMBIGUOUS`) and
    its medians listed in ``OUT/tuned.md``. Returns one entry per tuned file: ``name`` (the
    method, with ``@<dx_model>`` off the paper's contact motion), ``doc`` and ``rows``."""
    out = Path(out)
    results = RunResults(out / "sweep.csv").rows() if (out / "sweep.csv").exists() else []
    entries = []
    for path in sorted(out.glob("tuned_*.yaml")):
        doc = yaml.safe_load(path.read_text(encoding="utf-8"))
        dx_model = doc.get("dx_model", "ee")
        label = combination_label(doc["method"], doc["swept"], dx_model)
        per_scene = doc["n_trials"] // max(len(doc["scenes"]), 1)
        rows = [r for r in results if r["method"] == label and r["scene"] in doc["scenes"]
                and r["seed"] < per_scene]  # fmt: skip
        name = label.split("[")[0]
        entries.append({"name": name, "doc": doc, "rows": rows})
    if not entries:
        return entries
    plot_fmi_ce([{**r, "method": e["name"], "scene": "training set"}
                 for e in entries for r in e["rows"]], out / "fmi_ce.png",
                min_ambiguity=AMBIGUOUS)  # fmt: skip
    lines = [
        "| method | contact motion | tuned | runs | median FMI | median CE (cm) "
        f"| runs, ambiguity >= {AMBIGUOUS:g} | median FMI | median CE (cm) |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for e in entries:
        doc, amb = e["doc"], e["doc"]["ambiguous"]
        swept = ", ".join(f"{k} = {v}" for k, v in doc["swept"].items())
        lines.append(
            f"| {METHOD_LABELS.get(doc['method'], doc['method'])} | {doc.get('dx_model', 'ee')} "
            f"| {swept} | {doc['n_runs']} | {doc['median_fmi']:.3f} | {doc['median_ce_cm']:.2f} "
            f"| {amb['n_runs']} | {amb['median_fmi']:.3f} | {amb['median_ce_cm']:.2f} |"
        )
    (out / "tuned.md").write_text("\n".join(lines) + "\n", encoding="utf-8")
    return entries


def run_sweep(
    method: str,
    scenes: Sequence[str],
    trials: int,
    out,
    executor: cf.Executor,
    grid: Grid | None = None,
    sources: Sources = SYNTHETIC_SOURCES,
    progress=None,
    dx_model: str = "ee",
) -> dict:
    """Simulate trials 0..trials-1 of every scene (cached), replay every combination of
    ``grid`` (default :data:`DEFAULT_GRIDS`) on each kept trial with the contact motion
    ``dx_model`` (see :func:`~stucco_drake.eval.replay.replay`), pick and write the tuned
    parameters to :func:`tuned_path`, and redraw :func:`training_summary` over every sweep
    done in ``out``. Returns the tuned document (see :func:`write_tuned`).

    Raises:
        ValueError: unknown scene or method, trials < 1, no kept trial.
        RunInterrupted: a simulation or replay failed; what finished is kept (rerun resumes).
    """
    check_names(scenes, [method], sources)
    if dx_model not in DX_MODELS:
        raise ValueError(f"dx_model: expected one of {DX_MODELS}, got {dx_model!r}")
    if trials < 1:
        raise ValueError(f"trials must be positive, got {trials}")
    grid = parse_grid(method, None) if grid is None else grid
    out = Path(out)
    wanted = [(scene, seed) for scene in scenes for seed in range(trials)]
    simulate_missing(wanted, out, executor, progress, sources)
    kept = kept_trials(out, wanted)
    if not kept:
        raise ValueError(f"all {len(wanted)} trials are discarded: nothing to tune on")
    combos = combinations(grid)
    labels = {combination_label(method, c, dx_model): c for c in combos}
    results = RunResults(out / "sweep.csv")
    task = functools.partial(replay_combination, out=str(out), method=method, combos=labels,
                             sources=dict(sources), dx_model=dx_model)
    run_table([(scene, seed, label) for label in labels for scene, seed in kept], task, results,
              executor, progress)
    keys = {(scene, seed, label) for label in labels for scene, seed in kept}
    rows = [r for r in results.rows() if (r["scene"], r["seed"], r["method"]) in keys]
    summary = summarize(rows, method, combos, dx_model)
    best = best_combination(summary)
    add_ce_gaps(summary, rows, best, method, dx_model)
    tuned = write_tuned(tuned_path(out, method, dx_model), method, best, summary, scenes,
                        len(wanted), len(kept), dx_model)  # fmt: skip
    training_summary(out)
    return tuned
