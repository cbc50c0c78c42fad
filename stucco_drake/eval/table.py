"""The paper's Table II (GS, FMI, CE per method and scene) and its Fig. 5-style FMI/CE plot."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

METHOD_LABELS = {
    "stucco": "ours (STUCCO)",
    "birch": "BIRCH",
    "dbscan": "DBSCAN",
    "kmeans": "k-means",
    "gmphd": "GMPHD",
}
#: Placeholder of an empty cell (no grasp attempted, or no run with contacts).
_NONE = "n/a"
#: Runs at least this ambiguous form the plot's bottom row, as in the paper's Fig. 5.
AMBIGUOUS_RUN = 0.3


def _values(rows, scene, method, field) -> np.ndarray:
    """Finite values of ``field`` over the runs of (scene, method)."""
    values = [
        r[field] for r in rows if r["scene"] == scene and r["method"] == method
        and r[field] is not None
    ]
    values = np.asarray(values, dtype=np.float64)
    return values[np.isfinite(values)]


def _stats(values: np.ndarray):
    """(mean, standard deviation over runs with ddof 1, or 0 for a single run); None if empty."""
    if values.size == 0:
        return None
    return float(values.mean()), float(values.std(ddof=1)) if values.size > 1 else 0.0


def write_table(rows: Sequence[dict], scenes: Sequence[str], methods: Sequence[str], path_md):
    """Write Table II as Markdown: one row per method, per scene GS %, FMI and CE (cm).

    FMI and CE are "mean (std)" over the scene's runs; GS is the percentage of runs whose
    grasp succeeded, "n/a" when no grasp was attempted. The best value per scene and column is
    bold (highest GS and FMI, lowest CE), as in the paper. Runs with a NaN metric (no contact)
    are left out of that metric and counted in a note. Returns the Markdown text.
    """
    cells: dict[tuple[str, str], list[str]] = {}
    best: dict[tuple[str, int], float] = {}
    numbers: dict[tuple[str, str, int], float] = {}
    for scene in scenes:
        for method in methods:
            gs = _values(rows, scene, method, "grasp_success")
            fmi = _stats(_values(rows, scene, method, "fmi"))
            ce = _stats(_values(rows, scene, method, "ce_cm"))
            gs_pct = 100.0 * gs.mean() if gs.size else None
            cells[scene, method] = [
                _NONE if gs_pct is None else f"{gs_pct:.0f}",
                _NONE if fmi is None else f"{fmi[0]:.2f} ({fmi[1]:.2f})",
                _NONE if ce is None else f"{ce[0]:.2f} ({ce[1]:.2f})",
            ]
            # Sign makes "larger is better" for all three, so one max picks the bold cell.
            for column, value in enumerate((gs_pct, fmi and fmi[0], ce and -ce[0])):
                if value is not None:
                    numbers[scene, method, column] = round(value, 2)
                    best[scene, column] = max(best.get((scene, column), -np.inf), round(value, 2))
    header = ["method"] + [f"{s} {c}" for s in scenes for c in ("GS %", "FMI", "CE cm")]
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    for method in methods:
        row = [METHOD_LABELS.get(method, method)]
        for scene in scenes:
            for column, text in enumerate(cells[scene, method]):
                bold = numbers.get((scene, method, column)) == best.get((scene, column))
                row.append(f"**{text}**" if bold and text != _NONE else text)
        lines.append("| " + " | ".join(row) + " |")
    lines.append("")
    lines.append("GS: grasp success (%); FMI: Fowlkes-Mallows index; CE: contact error (cm); "
                 "mean (standard deviation) over runs.")
    for scene in scenes:
        counts = [sum(r["scene"] == scene and r["method"] == m for r in rows) for m in methods]
        lines.append(f"{scene}: {min(counts)}-{max(counts)} runs per method"
                     if min(counts) != max(counts) else f"{scene}: {counts[0]} runs per method")
        for method in methods:
            dropped = sum(
                r["scene"] == scene and r["method"] == method and not np.isfinite(r["ce_cm"])
                for r in rows
            )
            if dropped:
                lines.append(f"  {method}: {dropped} run(s) without contacts left out of FMI/CE")
    text = "\n".join(lines) + "\n"
    Path(path_md).parent.mkdir(parents=True, exist_ok=True)
    Path(path_md).write_text(text, encoding="utf-8")
    return text


def plot_fmi_ce(rows, path_png, scenes=None, methods=None, min_ambiguity: float = AMBIGUOUS_RUN):
    """FMI against CE (cm) per scene and method, like the paper's Fig. 5.

    Top row: all runs; bottom row: runs with ambiguity >= ``min_ambiguity`` (runs without
    logged ambiguity are left out there). Each method is its median with 20th-80th percentile
    bars on both axes, over its runs drawn faintly. Ideal is the upper left (FMI 1, CE 0).
    Rendered with the Agg canvas, so no display and no global backend change is needed.
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    scenes = list(scenes or dict.fromkeys(r["scene"] for r in rows))
    methods = list(methods or dict.fromkeys(r["method"] for r in rows))
    figure = Figure(figsize=(4.0 * len(scenes), 7.0), layout="constrained")
    FigureCanvasAgg(figure)
    axes = figure.subplots(2, len(scenes), squeeze=False, sharey=True)
    colors = {m: f"C{i}" for i, m in enumerate(methods)}
    for col, scene in enumerate(scenes):
        for row_index, keep in enumerate((None, min_ambiguity)):
            ax = axes[row_index, col]
            subset = [
                r for r in rows if r["scene"] == scene
                and (keep is None or (np.isfinite(r["ambiguity"]) and r["ambiguity"] >= keep))
            ]
            for method in methods:
                ce = np.array([r["ce_cm"] for r in subset if r["method"] == method])
                fmi = np.array([r["fmi"] for r in subset if r["method"] == method])
                ok = np.isfinite(ce) & np.isfinite(fmi)
                ce, fmi = ce[ok], fmi[ok]
                if ce.size == 0:
                    continue
                ax.scatter(ce, fmi, s=8, alpha=0.25, color=colors[method])
                c20, c50, c80 = np.percentile(ce, [20, 50, 80])
                f20, f50, f80 = np.percentile(fmi, [20, 50, 80])
                ax.errorbar(
                    c50, f50, xerr=[[c50 - c20], [c80 - c50]], yerr=[[f50 - f20], [f80 - f50]],
                    fmt="o", capsize=3, color=colors[method],
                    label=METHOD_LABELS.get(method, method),
                )
            title = scene if keep is None else f"{scene}, ambiguity >= {keep:g}"
            ax.set_title(title if subset else f"{title} (no runs)")
            ax.set_xlabel("CE (cm)")
            # At least 0.5 cm wide, so near-zero errors do not get a 1e-8 scale; a small margin
            # left of 0 keeps markers at CE 0 whole.
            right = max(ax.get_xlim()[1], 0.5)
            ax.set_xlim(-0.03 * right, right)
            ax.set_ylim(0.0, 1.05)
            ax.grid(alpha=0.3)
        if axes[0, col].get_legend_handles_labels()[0]:
            axes[0, col].legend(fontsize="small", loc="lower right")
    for row_index in range(2):
        axes[row_index, 0].set_ylabel("FMI")
    Path(path_png).parent.mkdir(parents=True, exist_ok=True)
    figure.savefig(path_png, dpi=120)
