"""The tracking training set (paper Sec. V-B): closed-loop trials in Drake in the SELECT
scenes (``trials``; the module documents the trial and what is adapted from the authors').

Above ``bor/`` (a trial drives the BOR Diagram) and ``eval/`` (it logs an ``EpisodeLog``; the
scene names come from ``eval.sets``); the ``sweep`` command uses it.
"""

from stucco_drake.training.trials import (
    CLEARANCE,
    DIST_FOR_DONE,
    MAX_ACTIONS,
    MAX_OBJECT_STEP,
    MIN_CONTACT_FRACTION,
    MIN_SEPARATION,
    TRAINING_SCENES,
    TRAINING_SOURCES,
    WALK_LENGTH,
    ClearanceCheck,
    GreedyRandomWalkPolicy,
    TrialPlan,
    contact_fraction,
    discard_reason,
    is_discarded,
    plan_trial,
    record_trial,
    with_target,
)

__all__ = [
    "CLEARANCE",
    "DIST_FOR_DONE",
    "MAX_ACTIONS",
    "MAX_OBJECT_STEP",
    "MIN_CONTACT_FRACTION",
    "MIN_SEPARATION",
    "TRAINING_SCENES",
    "TRAINING_SOURCES",
    "WALK_LENGTH",
    "ClearanceCheck",
    "GreedyRandomWalkPolicy",
    "TrialPlan",
    "contact_fraction",
    "discard_reason",
    "is_discarded",
    "plan_trial",
    "record_trial",
    "with_target",
]
