"""Replay one logged episode through one tracking method and score it (one row of Table II).

Every method sees the same log (same actions, contacts and noise) and the same generator
rule: ``numpy.random.default_rng(seed)`` with the episode's seed, as the authors reseed before
each run, so rows of different methods differ only by the method.
"""

from __future__ import annotations

import functools
import time
from collections.abc import Callable

import numpy as np

from stucco_drake.core.baselines import TRACKER_NAMES, make_tracker
from stucco_drake.core.contact_motion import DX_MODELS, contact_motion
from stucco_drake.core.metrics import ambiguity, contact_error, fowlkes_mallows
from stucco_drake.core.penetration import RobotPenetration
from stucco_drake.core.sdf import GridSdf
from stucco_drake.core.tracker import Tracker
from stucco_drake.eval.episode_log import EpisodeLog, shape_sdf

#: The fields of a row, in the order of the results file.
ROW_FIELDS = (
    "scene", "seed", "method", "grasp_success", "ce_cm", "fmi", "ambiguity", "n_contacts",
    "wall_time_s",
)
#: Resolution (m) and margin (m) of the pxpen grid built from a primitive robot shape.
_PXPEN_RESOLUTION = 1e-3
_PXPEN_MARGIN = 0.01

GraspCheck = Callable[[EpisodeLog, Tracker], "bool | None"]


@functools.lru_cache(maxsize=8)
def _primitive_penetration(spec: tuple) -> RobotPenetration:
    """pxpen of a primitive robot (cached per process: the grid takes ~0.1 s to build)."""
    sdf = shape_sdf(np.asarray(spec))
    lower, upper = sdf.bounds(_PXPEN_MARGIN)
    return RobotPenetration(GridSdf.build(sdf, lower, upper, _PXPEN_RESOLUTION))


def log_penetration(log: EpisodeLog) -> RobotPenetration:
    """The robot's pxpen from the log's primitive ``robot_shape``; ValueError if it has none."""
    if log.robot_shape.size == 0:
        raise ValueError(
            f"episode {log.scene}/{log.seed} logs no primitive robot shape; pass penetration="
        )
    return _primitive_penetration(tuple(float(v) for v in log.robot_shape))


def _with_singletons(labels: np.ndarray) -> np.ndarray:
    """Noise labels (-1) become one cluster each, as the authors score DBSCAN's noise."""
    labels = np.asarray(labels, dtype=np.int64).copy()
    noise = labels < 0
    labels[noise] = labels.max(initial=0) + 1 + np.arange(noise.sum())
    return labels


def run_ambiguity(log: EpisodeLog) -> float:
    """The paper's ambiguity of the episode, NaN when robot-object distances were not logged.

    Over the objects truly touched during the episode, per action; averaged over the actions
    that touched an object (see :func:`stucco_drake.core.metrics.ambiguity`).
    """
    if log.robot_object_distance.shape[0] == 0:
        return float("nan")
    touched = np.unique(log.contact_object[log.contact_object >= 0])
    in_contact = np.array(
        [np.any(log.contacts(t)[2] >= 0) for t in range(log.n_actions)], dtype=bool
    )
    return ambiguity(log.robot_object_distance[:, touched], in_contact)


def observed_dx(log: EpisodeLog, dx_model: str, penetration: RobotPenetration | None) -> np.ndarray:
    """(N, 3) every contact's motion (m, world frame) under ``dx_model`` (see
    :mod:`stucco_drake.core.contact_motion`): the logged ``contact_dx`` for ``"ee"``; for
    ``"normal"`` its signed projection onto the robot's outward normal at the contact, for
    ``"cone"`` it clipped to the friction cone about that normal, the robot posed where it was
    logged after that contact's action."""
    if dx_model == "ee":
        return log.contact_dx.copy()
    if dx_model not in DX_MODELS:
        raise ValueError(f"dx_model: expected one of {DX_MODELS}, got {dx_model!r}")
    if penetration is None:
        raise ValueError(f"dx_model {dx_model!r} needs the robot's geometry: pass penetration=")
    dx = np.empty_like(log.contact_dx)
    for t in range(log.n_actions):  # per action: each has its own end-effector pose
        lo, hi = log.contact_offsets[t], log.contact_offsets[t + 1]
        dx[lo:hi] = contact_motion(
            dx_model, log.contact_dx[lo:hi], log.contact_points[lo:hi], penetration.robot_sdf,
            log.ee_position[t], log.ee_rotation[t],
        )  # fmt: skip
    return dx


def replay(
    log: EpisodeLog,
    method: str,
    seed: int | None = None,
    params=None,
    *,
    penetration: RobotPenetration | None = None,
    grasp: GraspCheck | None = None,
    dx_model: str = "ee",
) -> dict:
    """Feed ``log`` to a fresh ``method`` tracker action by action and score the result.

    Args:
        log: the episode.
        method: a tracker name of :func:`~stucco_drake.core.baselines.make_tracker`.
        seed: seed of the tracker's generator (default: the episode's seed).
        params: the method's parameters (see ``make_tracker``; None = paper defaults).
        penetration: the robot's pxpen for STUCCO (default: built from ``log.robot_shape``).
        grasp: ``grasp(log, tracker) -> bool | None`` run after the last action; None leaves
            the row's ``grasp_success`` empty.
        dx_model: how far each contact point moves, for every method alike: ``"ee"`` (the
            paper: the end-effector's displacement while in contact), ``"normal"`` (its
            signed component along the robot's outward normal at the contact) or ``"cone"``
            (it clipped to the friction cone about that normal; see :func:`observed_dx`;
            both deviate from the paper). They use ``penetration``'s robot geometry, built
            from the log as for STUCCO when omitted.

    Returns:
        A row with :data:`ROW_FIELDS`: ``ce_cm`` mean distance (cm) of the tracked points to
        the final (extruded) object surfaces, ``fmi`` over contacts whose true object is known,
        ``ambiguity`` (:func:`run_ambiguity`), ``n_contacts``, ``wall_time_s`` of the tracking
        alone (s). CE and FMI are NaN when the tracker holds no contact.
    """
    if method not in TRACKER_NAMES:
        raise ValueError(f"unknown method {method!r} (known: {', '.join(TRACKER_NAMES)})")
    if dx_model not in DX_MODELS:
        raise ValueError(f"dx_model: expected one of {DX_MODELS}, got {dx_model!r}")
    if (method == "stucco" or dx_model != "ee") and penetration is None:
        penetration = log_penetration(log)
    dx_all = observed_dx(log, dx_model, penetration)
    tracker = make_tracker(method, params, penetration)
    rng = np.random.default_rng(log.seed if seed is None else seed)
    start = time.perf_counter()
    for t in range(log.n_actions):
        points, _, _ = log.contacts(t)
        dx = dx_all[log.contact_offsets[t] : log.contact_offsets[t + 1]]
        tracker.update(rng, log.ee_position[t], points, dx, log.ee_rotation[t])
    wall = time.perf_counter() - start
    if tracker.n_contacts != log.n_contacts:
        raise RuntimeError(
            f"{method} kept {tracker.n_contacts} of the log's {log.n_contacts} contacts"
        )
    ce = fmi = float("nan")
    if tracker.n_contacts:
        ce = 100.0 * contact_error(tracker.map_points(), log.final_surfaces())
        known = log.contact_object >= 0
        if known.any():
            fmi = fowlkes_mallows(
                log.contact_object[known], _with_singletons(tracker.segment())[known]
            )
    success = grasp(log, tracker) if grasp is not None else None
    return {
        "scene": log.scene,
        "seed": int(log.seed),
        "method": method,
        "grasp_success": None if success is None else bool(success),
        "ce_cm": float(ce),
        "fmi": float(fmi),
        "ambiguity": run_ambiguity(log),
        "n_contacts": int(tracker.n_contacts),
        "wall_time_s": float(wall),
    }
