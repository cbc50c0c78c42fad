"""Evaluation of the paper's Table II: episode logs, replay by every method, resumable tables.

Pure numpy (no pydrake import): the Drake scenes produce :class:`EpisodeLog` files that this
package replays and scores.
"""

from stucco_drake.eval.episode_log import EpisodeLog, box_spec, cylinder_spec
from stucco_drake.eval.replay import ROW_FIELDS, replay
from stucco_drake.eval.results import RunResults
from stucco_drake.eval.runner import RunInterrupted, make_executor, run_table
from stucco_drake.eval.synthetic_episode import SYNTHETIC_SCENES, synthetic_episode
from stucco_drake.eval.table import plot_fmi_ce, write_table

__all__ = [
    "ROW_FIELDS",
    "SYNTHETIC_SCENES",
    "EpisodeLog",
    "RunInterrupted",
    "RunResults",
    "box_spec",
    "cylinder_spec",
    "make_executor",
    "plot_fmi_ce",
    "replay",
    "run_table",
    "synthetic_episode",
    "write_table",
]
