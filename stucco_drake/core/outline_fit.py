"""How well the target's outline explains a segment's contact points, against a circle or a line.

The target-pose estimator's shape test (:func:`shape_excess`) and outline fit (:func:`shape_sse`)
compare two 3-parameter models of planar contact points: the target's outline at a
planar pose, and the best circle or line. Units: metres; points in the world frame W.
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import least_squares

from stucco_drake.core.icp import cross_section_sdf, rotations, to_pose_frames
from stucco_drake.core.shapes import BoxSdf, CylinderSdf


def curve_sse(points_xy) -> tuple[float, float]:
    """Sum of squared distances (m^2) of ``points_xy`` ((n, 2), m) to their best circle or line.

    Returns (sse, radius): the smaller of the geometric circle fit's and the total-least-squares
    line fit's squared residuals, and the circle's radius (m; inf when the line wins). The line
    is the circle's infinite-radius limit, where the circle fit is ill-conditioned, so it is
    fitted on its own. The circle starts at the algebraic (Kasa) fit and is refined by
    Gauss-Newton on the geometric residuals |p - c| - r, which the algebraic fit biases on
    short arcs.
    """
    centred = points_xy - points_xy.mean(axis=0)
    line = float(np.linalg.svd(centred, compute_uv=False)[-1] ** 2)
    if len(centred) < 3:
        return line, np.inf
    design = np.column_stack([centred, np.ones(len(centred))])
    solution = np.linalg.lstsq(design, np.sum(centred**2, axis=1), rcond=None)[0]
    centre = solution[:2] / 2.0
    radius = float(np.sqrt(max(solution[2] + centre @ centre, 0.0)))
    best = (line, np.inf)
    for _ in range(20):
        offset = centred - centre
        distance = np.linalg.norm(offset, axis=1)
        if not np.all(np.isfinite(distance)) or np.any(distance == 0.0):
            break
        residual = distance - radius
        if residual @ residual < best[0]:
            best = (float(residual @ residual), radius)
        jacobian = np.column_stack([-offset / distance[:, None], -np.ones(len(centred))])
        step = np.linalg.lstsq(jacobian, -residual, rcond=None)[0]
        if not np.all(np.isfinite(step)):
            break
        centre, radius = centre + step[:2], abs(radius + step[2])
    return best


def shape_sse(points_xy, poses, shape: BoxSdf | CylinderSdf) -> tuple[float, float]:
    """Squared residuals (m^2) of the points under the target's outline and under a curve.

    Returns (target, curve): the sum of squared exact outline distances |sdf| of
    ``points_xy`` ((n, 2), m) at the best of ``poses`` (B, 3), polished, and
    :func:`curve_sse` of the points (best circle or line). Both models have 3 parameters (a
    planar pose; a circle's centre and radius or a line's 2, so the curve is never the
    simpler model).
    """
    sdf = cross_section_sdf(shape)

    def residuals(pose):
        # Points in the pose's frame O: R^T (p - t), as row vectors.
        return sdf((points_xy - pose[None, :2]) @ rotations(pose[2]))

    local = to_pose_frames(poses, points_xy)
    sse = np.sum(sdf(local.reshape(-1, 2)).reshape(len(poses), -1) ** 2, axis=1)
    # Point-to-point ICP against a sampled outline stops short of the exact optimum (slow
    # sliding, 2 mm samples), which would count against a genuine target; polish the best
    # restart on the exact outline distance.
    polished = least_squares(
        residuals, poses[np.argmin(sse)], x_scale=[0.01, 0.01, 0.1], max_nfev=50
    ).x
    target = min(float(sse.min()), float(np.sum(residuals(polished) ** 2)))
    return target, curve_sse(points_xy)[0]


def pooled_noise_variance(fits, noise: float) -> float:
    """The sensor's noise variance (m^2) pooled over the segments' ``fits``.

    ``fits`` (s, 3) as in :func:`shape_excess`: the median over segments of the better
    model's residual variance (SSE over n - 3 degrees of freedom), floored at ``noise`` (m)
    squared.
    """
    fits = np.asarray(fits, dtype=np.float64).reshape(-1, 3)
    target, curve, count = fits.T
    variance = np.minimum(target, curve) / np.maximum(count - 3.0, 1.0)
    return max(noise**2, float(np.median(variance)))


def shape_excess(fits, noise: float, variance: float | None = None) -> np.ndarray:
    """(s,) how much worse the target's outline explains each segment than a circle or line.

    ``fits`` (s, 3) holds each segment's (target SSE, curve SSE, point count), see
    :func:`shape_sse`. With contact points scattered normally (standard deviation sigma, m)
    about the touched surface, twice the log-likelihood ratio of the two 3-parameter fits is
    their difference in squared residuals over sigma^2; positive values favour the curve.

    sigma is a property of the sensor, shared by all segments: it is the median over segments
    of the better model's residual variance (SSE over n - 3 degrees of freedom), floored at
    ``noise`` (m). Pooling keeps a genuine target seen through heavier noise than ``noise``
    from being rejected (alone, the statistic is then an F-test), while a clutter segment whose
    residuals are large under every model cannot dilute its own evidence. A given
    ``variance`` (m^2) replaces the pooled one (:func:`pooled_noise_variance` of ``fits``).
    """
    fits = np.asarray(fits, dtype=np.float64).reshape(-1, 3)
    if variance is None:
        variance = pooled_noise_variance(fits, noise)
    return (fits[:, 0] - fits[:, 1]) / variance
