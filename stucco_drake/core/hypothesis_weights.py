"""Weights of scored target poses: from their costs, over distinct poses, and the confidence
formed at a temperature of its own (:mod:`~stucco_drake.core.pose_hypotheses`). Poses are
(x, y, yaw) in the world frame W (m, rad); costs are negative log-likelihoods."""

from __future__ import annotations

import numpy as np

from stucco_drake.core.grasp_choice import grasp_closes
from stucco_drake.core.hypothesis_params import HypothesisParams
from stucco_drake.core.shapes import BoxSdf, CylinderSdf


def cost_weights(costs, temperature: float) -> np.ndarray:
    """(k,) weights ``exp(-(cost - min cost) / temperature)`` of ``costs`` (k,), normalised."""
    costs = np.asarray(costs, dtype=np.float64)
    weights = np.exp(-(costs - costs.min()) / temperature)
    return weights / weights.sum()


def distinct_rivals(poses, costs, count: int | None = None, distance: float = 0.02,
                    angle: float = np.radians(15.0)) -> np.ndarray:  # fmt: skip
    """Indices of up to ``count`` (None: any number of) hypotheses, cheapest first, each at
    least ``distance`` (m) or ``angle`` (rad, modulo a half turn; ``np.inf`` for a cylinder,
    whose turn shows nothing) from every cheaper one taken: variants of one pose tell nothing
    apart."""
    poses = np.asarray(poses, dtype=np.float64)
    taken: list[int] = []
    for k in np.argsort(np.asarray(costs), kind="stable"):
        turn = np.abs((poses[taken, 2] - poses[k, 2] + np.pi / 2) % np.pi - np.pi / 2)
        near = (np.hypot(*(poses[taken, :2] - poses[k, :2]).T) < distance) & (turn < angle)
        if not near.any():
            taken.append(int(k))
            if len(taken) == count:
                break
    return np.array(taken, dtype=int)


def tempered_confidence(grasp, poses, costs, shape: BoxSdf | CylinderSdf,
                        params: HypothesisParams) -> float:  # fmt: skip
    """Weight, at ``params.confidence_temperature``, of the scored ``poses`` (k, 3) with
    ``costs`` (k,) under which ``grasp`` (x, y, closing yaw) closes on the target with the grasp
    margins to spare, one pose per mode (:func:`distinct_rivals`): the scored poses include
    many variants of each, whose summed weight would count one rival many times."""
    turn = np.inf if isinstance(shape, CylinderSdf) else np.radians(15.0)
    modes = distinct_rivals(poses, costs, angle=turn)
    poses, costs = np.asarray(poses)[modes], np.asarray(costs)[modes]
    weights = cost_weights(costs, params.confidence_temperature)
    closes = grasp_closes(np.asarray(grasp)[None], poses, shape, params.grasp_margin,
                          params.grasp_angle_margin)[0]  # fmt: skip
    return float(np.round(closes.astype(np.float64) @ weights, 12))


__all__ = ["cost_weights", "distinct_rivals", "tempered_confidence"]
