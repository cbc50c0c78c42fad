"""The evaluation's disjoint sets of scenes, and which one a scene belongs to.

- **training**: the training scenes SELECT1-4 (and any layout drawn from them). Parameters are
  chosen on these only (``stucco-drake sweep``), as the paper does.
- **development**: randomized layouts of the paper's scenes (``stucco-drake scenes
  randomize``) with a layout seed in :data:`DEVELOPMENT_SEEDS`; look at them as much as you
  like.
- **report**: layouts of the paper's scenes with a seed in :data:`REPORT_SEEDS`, run once per
  change of method and never used to choose anything.
- **paper**: FB, BC, IB and TC as published: Table II, the comparison with the paper.

Anything else (another seed, a scene file of one's own, the synthetic scenes) is **other**.
Nothing is refused on these grounds: the table prints each scene's set so that it is visible.
"""

from __future__ import annotations

from stucco_drake.core.rummage_params import RummageParams

#: The paper's training scenes.
TRAINING_SCENES = ("SELECT1", "SELECT2", "SELECT3", "SELECT4")
#: The paper's four Blind Object Retrieval scenes.
PAPER_SCENES = ("FB", "BC", "IB", "TC")
#: Layout seeds of the development layouts.
DEVELOPMENT_SEEDS = range(1000, 2000)
#: Layout seeds of the report layouts.
REPORT_SEEDS = range(9000, 10000)

SETS = ("training", "development", "report", "paper", "other")

#: The target confidence (the hypotheses' posterior probability that the grasp closes with margin)
#: from which a run counts as confident, and at which the belief policy stops. Chosen on the
#: development layouts' probed episodes (IB, FB, TC-L1000-1009): the highest precision with at
#: least 9 of 30 runs passing, 8 of those 9 grasped; 0.9 gave 16 of 21 and 0.99 10 of 13.
CONFIDENT_FROM = RummageParams.stop_confidence


def scene_set(name: str, base: str = "", layout_seed: int | None = None) -> str:
    """The set (one of :data:`SETS`) of scene ``name``, a layout of ``base`` drawn with
    ``layout_seed`` when ``base`` is not empty."""
    if not base:
        if name in TRAINING_SCENES:
            return "training"
        return "paper" if name in PAPER_SCENES else "other"
    if base in TRAINING_SCENES:
        return "training"
    if base in PAPER_SCENES and layout_seed is not None:
        if layout_seed in DEVELOPMENT_SEEDS:
            return "development"
        if layout_seed in REPORT_SEEDS:
            return "report"
    return "other"


def describe_sets(scene_sets: dict[str, str]) -> str:
    """One line per set present, ``<set> set: <scene names>`` (``in no set: ...`` for
    other), from scene name -> set."""
    lines = []
    for which in SETS:
        names = [name for name, s in scene_sets.items() if s == which]
        if names:
            label = "in no set" if which == "other" else f"{which} set"
            lines.append(f"{label}: {' '.join(names)}")
    return "\n".join(lines)
