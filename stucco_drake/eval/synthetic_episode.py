"""Episode logs from the built-in planar pushing world, until Drake episodes exist.

As in the paper's BOR runs, a scene is a fixed world and a fixed scripted action sequence;
the run's seed only perturbs every action by uniform noise of up to ``action_noise`` per
axis (the paper: +-0.5 mm against 30 mm steps). Scenes:

- ``SYN2``: :func:`~stucco_drake.core.synthetic.separation_scenario`, two boxes first
  touched close together, then pushed apart.
- ``SYNC``: eight boxes of :func:`~stucco_drake.core.synthetic.random_clutter` (fixed layout)
  and :data:`SYNC_ACTIONS` actions of :func:`~stucco_drake.core.synthetic.rummage`.
"""

from __future__ import annotations

import copy
import functools
import itertools

import numpy as np

from stucco_drake.core.synthetic import (
    PlanarPushWorld,
    random_clutter,
    rummage,
    separation_scenario,
)
from stucco_drake.eval.episode_log import EpisodeLog, box_spec, cylinder_spec

SYNTHETIC_SCENES = ("SYN2", "SYNC")
#: Half-width (m) of the uniform noise added to each action axis (paper Sec. V-C).
ACTION_NOISE = 5e-4
#: Largest action (m) per axis; noisy actions are clipped to it, as the paper's controller does.
MAX_STEP = 0.03
SYNC_ACTIONS = 60
#: The SYNC layout and script are the scene's, not the run's: the same for every seed.
_SYNC_SCENE_SEED = 0
_EE_RADIUS = 0.02


def _record_deltas(world: PlanarPushWorld, actions, limit: int | None = None) -> np.ndarray:
    """(T, 2) the EE motions (m) a scripted action generator commands on ``world``."""
    deltas = []
    step = world.step

    def recording(delta):
        deltas.append(np.array(delta, dtype=np.float64))
        return step(delta)

    # The generators call world.step on this instance, so shadowing it records each command.
    world.step = recording
    for _ in itertools.islice(actions, limit):
        pass
    return np.array(deltas).reshape(-1, 2)


@functools.cache
def _script(scene: str) -> tuple[PlanarPushWorld, np.ndarray]:
    """The scene's untouched starting world and its nominal actions (T, 2) m; cached."""
    if scene == "SYN2":
        world, actions = separation_scenario()
        deltas = _record_deltas(world, actions)
        return separation_scenario()[0], deltas
    if scene == "SYNC":
        rng = np.random.default_rng(_SYNC_SCENE_SEED)
        start = random_clutter(rng, ee_radius=_EE_RADIUS)
        scratch = copy.deepcopy(start)
        return start, _record_deltas(scratch, rummage(scratch, rng), SYNC_ACTIONS)
    raise ValueError(f"unknown synthetic scene {scene!r} (known: {', '.join(SYNTHETIC_SCENES)})")


def _robot_distances(world: PlanarPushWorld) -> np.ndarray:
    """(k,) distance (m) from the EE disc to each box, 0 in contact."""
    lo = world.box_centers - world.box_half_extents
    hi = world.box_centers + world.box_half_extents
    gap = np.linalg.norm(np.clip(world.ee, lo, hi) - world.ee, axis=1) - world.ee_radius
    return np.maximum(gap, 0.0)


def _poses(world: PlanarPushWorld) -> np.ndarray:
    """(k, 3) planar poses (x, y, yaw); the world's boxes never rotate."""
    return np.column_stack([world.box_centers, np.zeros(len(world.box_centers))])


def synthetic_episode(scene: str, seed: int, action_noise: float = ACTION_NOISE) -> EpisodeLog:
    """Simulate ``scene`` ('SYN2' or 'SYNC') with the actions perturbed by run ``seed``.

    The noise is U(-action_noise, action_noise) (m) per axis per action, drawn from
    ``numpy.random.default_rng(seed)``; the noisy action is clipped to +-3 cm per axis.
    """
    start, deltas = _script(scene)
    world = copy.deepcopy(start)
    rng = np.random.default_rng(seed)
    noisy = np.clip(deltas + rng.uniform(-action_noise, action_noise, deltas.shape), -MAX_STEP,
                    MAX_STEP)
    positions, offsets, points, dx, objects = [], [0], [], [], []
    poses, distances = [_poses(world)], []
    for delta in noisy:
        obs = world.step(delta)
        positions.append(obs.ee_position)
        points.append(obs.contact_points)
        dx.append(obs.contact_dx)
        objects.append(obs.contact_objects)
        offsets.append(offsets[-1] + len(obs.contact_points))
        poses.append(_poses(world))
        distances.append(_robot_distances(world))
    k = len(world.box_centers)
    height = world.height
    robot = world.robot_sdf()
    return EpisodeLog(
        scene=scene,
        seed=int(seed),
        action_noise=float(action_noise),
        ee_position=np.array(positions).reshape(-1, 3),
        ee_rotation=np.broadcast_to(np.eye(3), (len(positions), 3, 3)),
        contact_offsets=np.array(offsets),
        contact_points=np.concatenate(points).reshape(-1, 3),
        contact_dx=np.concatenate(dx).reshape(-1, 3),
        contact_object=np.concatenate(objects).astype(np.int64),
        object_names=[f"box{i}" for i in range(k)],
        object_poses=np.array(poses),
        object_shapes=np.array([box_spec(hx, hy, height) for hx, hy in world.box_half_extents]),
        robot_object_distance=np.array(distances).reshape(-1, k),
        robot_shape=cylinder_spec(robot.radius, robot.half_height),
        final_state=np.concatenate([world.box_centers.ravel(), world.ee]),
        info={"producer": "synthetic", "ee_radius_m": world.ee_radius},
    )
