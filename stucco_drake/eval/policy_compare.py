"""Ways of choosing the actions compared on the same layouts: the prescribed scripts, the
coverage sweep, the belief policy, each a set of ``stucco-drake table`` folders (pooled: a set
may join folders made with other settings, e.g. another budget per family, but no run may be
in two of them). Per family, one method's grasp success with its 95 % Wilson interval and the
median number of actions an episode played before the grasp (its log's length), then each set
paired with the first layout by layout (W/L, McNemar's exact p).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from stucco_drake.core.inputs import InputError
from stucco_drake.eval.cli_table import episode_path
from stucco_drake.eval.results import RunResults
from stucco_drake.eval.summary import count_text, layout_family, markdown_lines, paired_p


def load_set(name: str, folders: Sequence[str | Path], method: str) -> dict:
    """{(family, scene, seed): (grasped, actions)} of ``method``'s runs with a grasp outcome
    over ``folders``; InputError (one line) when a folder is no table folder, has no run of
    ``method``, lacks a run's log, or a run is in two folders."""
    runs, seen = {}, {}
    for folder in map(Path, folders):
        if not (folder / "runs.csv").is_file():
            raise InputError(f"{name}: {folder}: no runs.csv (not a table folder)")
        try:
            rows = [r for r in RunResults(folder / "runs.csv").rows() if r["method"] == method]
        except ValueError as error:
            raise InputError(f"{name}: {error}") from None
        if not rows:
            raise InputError(f"{name}: {folder}: no run of method {method}")
        for row in rows:
            key = (layout_family(row["scene"]), row["scene"], int(row["seed"]))
            if key in seen:
                raise InputError(f"{name}: run {key[1:]} is in {seen[key]} and {folder}")
            seen[key] = folder
            if row["grasp_success"] is None:
                continue
            log = episode_path(folder, row["scene"], int(row["seed"]))
            if not log.is_file():
                raise InputError(f"{name}: {log}: the run's log is missing")
            with np.load(log) as data:
                actions = int(data["ee_position"].shape[0])
            runs[key] = (bool(row["grasp_success"]), actions)
    return runs


def grasp_action_lines(sets: dict[str, dict], families: Sequence[str]) -> list[str]:
    """Per set and family: grasped/runs (%, Wilson interval) and the median actions."""
    table = []
    for name, runs in sets.items():
        line = [name]
        for family in families:
            group = [v for k, v in runs.items() if k[0] == family]
            grasped = sum(g for g, _ in group)
            median = f"{np.median([a for _, a in group]):.0f}" if group else "n/a"
            line.append(f"{count_text(grasped, len(group))}; {median}")
        table.append(line)
    return ["Grasp success: grasped/runs (%, 95 % Wilson interval); median actions per "
            "episode.", "", *markdown_lines(["actions chosen by", *families], table)]


def paired_set_lines(sets: dict[str, dict], families: Sequence[str]) -> list[str]:
    """Each set after the first against it, on the layouts both ran: W/L (grasped by the
    first only / by the other only), McNemar's exact two-sided p, and the median ratio of
    the first's actions to the other's."""
    (first, ours), table = next(iter(sets.items())), []
    for name, theirs in list(sets.items())[1:]:
        line = [name]
        for family in families:
            shared = [k for k in ours.keys() & theirs.keys() if k[0] == family]
            if not shared:
                line.append("n/a")
                continue
            wins = sum(ours[k][0] and not theirs[k][0] for k in shared)
            losses = sum(theirs[k][0] and not ours[k][0] for k in shared)
            ratio = np.median([ours[k][1] / theirs[k][1] for k in shared])
            line.append(f"{wins}/{losses}, p {paired_p(wins, losses):.2f}; "
                        f"actions x{ratio:.2f}")
        table.append(line)
    return [f"Paired with {first}, layout by layout: W/L = grasped by {first} only / by the "
            f"other only; p: McNemar's exact test; {first}'s actions over the other's, "
            "median.", "", *markdown_lines(["against", *families], table)]


def compare_text(named_folders: Sequence[tuple[str, Sequence[str]]],
                 method: str = "stucco") -> str:
    """The comparison of :mod:`the module <stucco_drake.eval.policy_compare>` as Markdown;
    InputError (one line) on a repeated name or a folder that cannot be read."""
    names = [name for name, _ in named_folders]
    if len(set(names)) != len(names):
        raise InputError(f"--set: a name is given twice ({', '.join(names)})")
    sets = {name: load_set(name, folders, method) for name, folders in named_folders}
    families = list(dict.fromkeys(k[0] for runs in sets.values() for k in sorted(runs)))
    lines = [f"Method {method}; sets: " + "; ".join(
        f"{name}: {', '.join(map(str, folders))}" for name, folders in named_folders) + ".",
        "", *grasp_action_lines(sets, families), ""]
    if len(sets) > 1:
        lines += [*paired_set_lines(sets, families), ""]
    return "\n".join(lines)
