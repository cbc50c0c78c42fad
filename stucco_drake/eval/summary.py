"""Table folders read together, with their spread: grasp success with its 95 % interval,
every method paired run by run with a reference one, the reference's calibration, and its
grasp success against another set of layouts (the paper's).

Each folder is a ``stucco-drake table`` output (``runs.csv``, ``table_config.yaml``, and for
the calibration ``estimates_<method>.csv`` from ``stucco-drake estimates``). Folders are pooled
only when their ``table_config.yaml`` records the same settings and no run (scene, seed,
method) is in two of them. A layout's runs are grouped under its family, the scene it was
randomized from (``FB-L9020`` under ``FB``); a scene that is no layout is its own family.
"""

from __future__ import annotations

import csv
import math
import re
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import yaml
from scipy import stats

from stucco_drake.core.inputs import InputError
from stucco_drake.eval.results import RunResults, row_key
from stucco_drake.eval.sets import CONFIDENT_FROM
from stucco_drake.eval.table import METHOD_LABELS

#: The two-sided 95 % quantile of the standard normal.
Z95 = float(stats.norm.ppf(0.975))
_LAYOUT = re.compile(r"^(?P<base>.+)-L(?P<seed>\d+)$")


def layout_family(scene: str) -> str:
    """The scene a layout named by :func:`stucco_drake.scenes.randomize.layout_name` was
    randomized from (``"FB-L9020"`` -> ``"FB"``); any other name is its own family."""
    match = _LAYOUT.match(scene)
    return match["base"] if match else scene


def wilson_interval(successes: int, runs: int, z: float = Z95) -> tuple[float, float]:
    """Wilson's score interval (no continuity correction) of a proportion of ``successes``
    in ``runs`` (both counts; (nan, nan) for no runs)."""
    if runs == 0:
        return math.nan, math.nan
    p, z2 = successes / runs, z * z
    centre = (p + z2 / (2 * runs)) / (1 + z2 / runs)
    half = z / (1 + z2 / runs) * math.sqrt(p * (1 - p) / runs + z2 / (4 * runs * runs))
    return max(0.0, centre - half), min(1.0, centre + half)


def paired_p(wins: int, losses: int) -> float:
    """Two-sided exact p of McNemar's test on paired runs: ``wins`` discordant pairs one
    way, ``losses`` the other, each way equally likely under no difference (1.0 for none)."""
    if wins + losses == 0:
        return 1.0
    return float(stats.binomtest(wins, wins + losses, 0.5).pvalue)


def fisher_p(successes_a: int, runs_a: int, successes_b: int, runs_b: int) -> float:
    """Two-sided p of Fisher's exact test that two proportions are the same."""
    table = [[successes_a, runs_a - successes_a], [successes_b, runs_b - successes_b]]
    return float(stats.fisher_exact(table)[1])


def _config(folder: Path) -> dict:
    """The settings ``folder``'s rows were made with (:func:`complete_config`)."""
    from stucco_drake.eval.cli_table import TABLE_CONFIG, complete_config

    try:
        config = yaml.safe_load((folder / TABLE_CONFIG).read_text(encoding="utf-8"))
    except (OSError, yaml.YAMLError) as error:
        raise InputError(f"{folder}: no readable {TABLE_CONFIG} ({error})") from None
    if not isinstance(config, dict) or not {"dx_model", "stucco_params"} <= set(config):
        raise InputError(f"{folder / TABLE_CONFIG}: not a table config")
    return complete_config(config)


def load_runs(folders: Sequence[str | Path]) -> list[dict]:
    """The runs of every folder, each with its ``family``; InputError (one line) when a
    folder has no runs, its settings differ from the first folder's, or a run is in two."""
    rows, seen, first = [], {}, None
    for folder in map(Path, folders):
        if not (folder / "runs.csv").is_file():
            raise InputError(f"{folder}: no runs.csv (not a table folder)")
        config = _config(folder)
        if first is None:
            first = (folder, config)
        elif config != first[1]:
            key = next(k for k in sorted(set(config) | set(first[1]))
                       if config.get(k) != first[1].get(k))  # fmt: skip
            raise InputError(f"{folder}: made with other settings than {first[0]} "
                             f"({key} differs); only tables of one setting are pooled")
        try:
            folder_rows = RunResults(folder / "runs.csv").rows()
        except ValueError as error:
            raise InputError(str(error)) from None
        for row in folder_rows:
            key = row_key(row)
            if key in seen:
                raise InputError(f"{folder}: run {key} is in {seen[key]} too")
            seen[key] = folder
            rows.append({**row, "family": layout_family(row["scene"])})
    return rows


def load_estimates(folders: Sequence[str | Path], method: str) -> list[dict] | None:
    """The rows of every folder's ``estimates_<method>.csv`` (confidence, grasp_success,
    target_contacts, with ``family``), or None when a folder has none."""
    rows = []
    for folder in map(Path, folders):
        path = folder / f"estimates_{method}.csv"
        if not path.is_file():
            return None
        with path.open(newline="", encoding="utf-8") as file:
            for row in csv.DictReader(file):
                grasp = row["grasp_success"]
                rows.append({"scene": row["scene"], "family": layout_family(row["scene"]),
                             "confidence": float(row["confidence"]),
                             "target_contacts": int(row["target_contacts"]),
                             "grasp_success": None if grasp in ("", "None") else grasp == "True"})
    return rows


def _grasps(rows, family, method) -> dict[tuple[str, int], bool]:
    """(scene, seed) -> grasped, over the runs of ``method`` in ``family`` whose grasp was
    made (a run with no grasp outcome is left out)."""
    return {(r["scene"], r["seed"]): bool(r["grasp_success"]) for r in rows
            if r["family"] == family and r["method"] == method
            and r["grasp_success"] is not None}  # fmt: skip


def count_text(successes: int, runs: int) -> str:
    """``successes``/``runs`` (%, Wilson 95 % interval), or n/a for no runs."""
    if runs == 0:
        return "n/a"
    low, high = wilson_interval(successes, runs)
    return f"{successes}/{runs} ({100 * successes / runs:.0f} %, {100 * low:.0f}-{100 * high:.0f})"


def markdown_lines(header: Sequence[str], lines: Sequence[Sequence[str]]) -> list[str]:
    """A Markdown table's lines."""
    return ["| " + " | ".join(header) + " |", "|" + "---|" * len(header),
            *("| " + " | ".join(line) + " |" for line in lines)]


def grasp_lines(rows, families, methods) -> list[str]:
    """Each method's grasp success per family: grasped/runs (%, Wilson 95 % interval), and
    its contact error (cm), mean (standard deviation) over the runs with contacts."""
    table = []
    for method in methods:
        line = [METHOD_LABELS.get(method, method)]
        for family in families:
            grasped = _grasps(rows, family, method)
            line.append(count_text(sum(grasped.values()), len(grasped)))
        for family in families:
            ce = np.array([r["ce_cm"] for r in rows
                           if r["family"] == family and r["method"] == method])
            ce = ce[np.isfinite(ce)]
            line.append("n/a" if ce.size == 0 else
                        f"{ce.mean():.2f} ({ce.std(ddof=1) if ce.size > 1 else 0.0:.2f})")
        table.append(line)
    header = ["method", *(f"{f} GS" for f in families), *(f"{f} CE cm" for f in families)]
    return ["Grasp success: grasped/runs (%, 95 % Wilson interval); contact error: mean (sd).",
            "", *markdown_lines(header, table)]


def paired_lines(rows, families, reference, methods) -> list[str]:
    """Each other method against ``reference`` on the runs both have a grasp outcome for:
    W/L (layouts only the reference grasps / only the other), McNemar's exact two-sided p."""
    table = []
    for method in methods:
        if method == reference:
            continue
        line = [METHOD_LABELS.get(method, method)]
        for family in families:
            ours, theirs = _grasps(rows, family, reference), _grasps(rows, family, method)
            shared = ours.keys() & theirs.keys()
            wins = sum(ours[k] and not theirs[k] for k in shared)
            losses = sum(theirs[k] and not ours[k] for k in shared)
            line.append(f"{wins}/{losses}, p {paired_p(wins, losses):.2f}" if shared else "n/a")
        table.append(line)
    name = METHOD_LABELS.get(reference, reference)
    return [f"Paired with {name}, layout by layout: W/L = grasped by {name} only / by the "
            "other only; p: McNemar's exact test.", "",
            *markdown_lines(["method", *families], table)]


def calibration_lines(estimates, families, threshold: float = CONFIDENT_FROM) -> list[str]:
    """Of the runs confident at ``threshold``: how many, how many grasped (Wilson interval);
    of the others: how many, how many touched the target, how many grasped."""
    table = []
    for family in [*families, "all"]:
        group = [e for e in estimates if family in ("all", e["family"])]
        sure = [e for e in group if e["confidence"] >= threshold]
        rest = [e for e in group if e["confidence"] < threshold]
        table.append([family, count_text(sum(bool(e["grasp_success"]) for e in sure), len(sure)),
                      f"{len(rest)}", f"{sum(e['target_contacts'] > 0 for e in rest)}",
                      f"{sum(bool(e['grasp_success']) for e in rest)}"])
    header = ["family", f"confident (>= {threshold:g}): grasped/runs", "others",
              "others, target touched", "others, grasped"]
    return ["Calibration of the target confidence.", "", *markdown_lines(header, table)]


def against_lines(rows, other_rows, families, method) -> list[str]:
    """``method``'s grasp success here and on ``other_rows`` (e.g. the paper's layouts), per
    family: the difference in points and Fisher's exact two-sided p."""
    table = []
    for family in families:
        here, there = _grasps(rows, family, method), _grasps(other_rows, family, method)
        if not here or not there:
            continue
        k1, n1, k2, n2 = sum(here.values()), len(here), sum(there.values()), len(there)
        table.append([family, count_text(k1, n1), count_text(k2, n2),
                      f"{100 * (k1 / n1 - k2 / n2):+.0f}", f"{fisher_p(k1, n1, k2, n2):.2f}"])
    name = METHOD_LABELS.get(method, method)
    return [f"{name} on these layouts and on --against's: the difference in points and "
            "Fisher's exact p.", "",
            *markdown_lines(["family", "here", "--against", "points", "Fisher p"], table)]
