"""Randomized layouts of a scene: every movable object shifted and turned a little.

A layout keeps everything of its base scene (actions, target, robot, walls, control, tracker)
but the poses of its movable (free) objects. Each object's origin moves in the table plane by
a distance uniform in :attr:`LayoutParams.shift` along a uniform direction, and the object
turns about the vertical through its origin by an angle uniform in
±:attr:`LayoutParams.max_yaw`; heights, roll and pitch are kept, so it still stands on the
table. Layout seed ``s`` draws from ``numpy.random.default_rng(s)``: per draw of a whole
layout, for each movable object in the built plant's order, the direction, the distance and
the turn. A draw is rejected while any movable object is closer than
:attr:`LayoutParams.clearance` to anything but :attr:`LayoutParams.support` (the other
objects, the walls, the robot and gripper at their start posture), by Drake's
``ComputeSignedDistancePairwiseClosestPoints`` on the base scene built once; after
:attr:`LayoutParams.max_draws` rejected draws it gives up with one line (:class:`LayoutError`).

The layout is named ``<base>-L<seed>`` (:func:`layout_name`) and records ``base`` and
``layout_seed`` (see :class:`~stucco_drake.scenes.scene_file.SceneFile`). Units: m, rad.
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
from pydrake.common import schema
from pydrake.common.yaml import yaml_dump_typed
from pydrake.math import RigidTransform, RollPitchYaw, RotationMatrix

from stucco_drake.scenes.builder import BuiltScene, build_scene
from stucco_drake.scenes.scene_file import SceneFile, load_scene_text


class LayoutError(ValueError):
    """No layout could be drawn, or the parameters are invalid (a one-line message)."""


@dataclasses.dataclass
class LayoutParams:
    """How a layout is drawn from its base scene (see the module docstring).

    Attributes:
        shift: [least, most] distance each movable object's origin moves in the table plane (m).
        max_yaw: largest turn of an object about the vertical through its origin (rad).
        clearance: least signed distance from a movable object to anything but ``support`` (m).
        support: model the objects stand on, exempt from ``clearance``.
        max_draws: draws of a whole layout before giving up.
    """

    shift: tuple[float, float] = (0.01, 0.02)
    max_yaw: float = math.radians(8.0)
    clearance: float = 0.002
    support: str = "table"
    max_draws: int = 1000

    def check(self) -> None:
        """LayoutError naming the first invalid field."""
        low, high = self.shift
        for ok, reason in (
            (0 <= low <= high, f"shift: expected 0 <= least <= most, got {list(self.shift)}"),
            (0 <= self.max_yaw <= math.pi, f"max_yaw: expected 0..pi rad, got {self.max_yaw}"),
            (self.clearance >= 0, f"clearance: must be >= 0, got {self.clearance}"),
            (self.max_draws >= 1, f"max_draws: must be >= 1, got {self.max_draws}"),
        ):
            if not ok:
                raise LayoutError(reason)


def layout_name(base: str, seed: int) -> str:
    """The name of layout ``seed`` of scene ``base``."""
    return f"{base}-L{seed}"


class LayoutClearance:
    """Drake's signed distances between the movable objects of a built scene and the rest.

    The scene is built once; :meth:`closest` moves the movable bodies in one context and asks
    the scene graph for every pair within the clearance.
    """

    def __init__(self, built: BuiltScene, params: LayoutParams):
        self.built, self.params = built, params
        plant = built.plant
        self._context = built.diagram.CreateDefaultContext()
        self._plant_context = plant.GetMyMutableContextFromRoot(self._context)
        self._port = built.diagram.GetOutputPort("query_object")
        self.bodies = list(built.free_bodies.values())
        #: Each movable body's pose in the base scene.
        self.start = [plant.EvalBodyPoseInWorld(self._plant_context, b) for b in self.bodies]
        self._movable = {g for b in self.bodies for g in plant.GetCollisionGeometriesForBody(b)}
        self._support = set()
        if plant.HasModelInstanceNamed(params.support):
            instance = plant.GetModelInstanceByName(params.support)
            for index in plant.GetBodyIndices(instance):
                self._support.update(plant.GetCollisionGeometriesForBody(plant.get_body(index)))

    def closest(self, poses: list[RigidTransform]) -> tuple[float, str]:
        """(distance, "a and b"): the least signed distance (m) between a movable object at
        ``poses`` (in the order of :attr:`bodies`) and anything but the support, if below
        the clearance; (inf, "") when every pair keeps it."""
        for body, X_WB in zip(self.bodies, poses, strict=True):
            self.built.plant.SetFreeBodyPose(self._plant_context, body, X_WB)
        query = self._port.Eval(self._context)
        inspector = query.inspector()
        least, names = math.inf, ""
        for pair in query.ComputeSignedDistancePairwiseClosestPoints(self.params.clearance):
            ids = {pair.id_A, pair.id_B}
            if not ids & self._movable or ids & self._support or pair.distance >= least:
                continue
            if pair.distance < self.params.clearance:
                least = pair.distance
                names = " and ".join(inspector.GetName(inspector.GetFrameId(g))
                                     for g in (pair.id_A, pair.id_B))  # fmt: skip
        return least, names


def draw_poses(rng: np.random.Generator, start: list[RigidTransform],
               params: LayoutParams) -> list[RigidTransform]:  # fmt: skip
    """One draw of every movable body's pose from its ``start`` pose (see the module doc)."""
    u = rng.random((len(start), 3))
    heading = 2.0 * math.pi * u[:, 0]
    low, high = params.shift
    distance = low + (high - low) * u[:, 1]
    turn = params.max_yaw * (2.0 * u[:, 2] - 1.0)
    poses = []
    for X, h, d, t in zip(start, heading, distance, turn, strict=True):
        p = X.translation() + np.array([d * math.cos(h), d * math.sin(h), 0.0])
        poses.append(RigidTransform(RotationMatrix.MakeZRotation(t) @ X.rotation(), p))
    return poses


def _with_poses(base: SceneFile, built: BuiltScene, bodies, poses) -> SceneFile:
    """A copy of ``base`` whose movable ``bodies`` stand at ``poses``."""
    scene = load_scene_text(yaml_dump_typed(base), where=base.name)  # a deep copy
    plant = built.plant
    primitives = {p.name: p for p in scene.primitives}
    models = {d.add_model.name: d.add_model for d in scene.directives if d.add_model is not None}
    for body, X in zip(bodies, poses, strict=True):
        model = plant.GetModelInstanceName(body.model_instance())
        rpy = RollPitchYaw(X.rotation()).vector() + 0.0  # + 0.0: written 0.0, not -0.0
        if model in primitives:
            primitives[model].xyz = X.translation().tolist()
            primitives[model].rpy = rpy.tolist()
            continue
        add_model = models.get(model)
        pose = add_model.default_free_body_pose.get(body.name()) if add_model else None
        if pose is None or pose.base_frame not in (None, "world"):
            raise LayoutError(f"{base.name}: {model}: a movable object needs a "
                              f"default_free_body_pose in the world frame to be moved")
        pose.translation = X.translation()
        pose.rotation = schema.Rotation()
        pose.rotation.set_rpy_deg(np.degrees(rpy))
        add_model.default_free_body_pose = {**add_model.default_free_body_pose,
                                            body.name(): pose}  # fmt: skip
    return scene


def randomize_scene(base: SceneFile, seed: int, params: LayoutParams | None = None,
                    clearance: LayoutClearance | None = None) -> tuple[SceneFile, int]:  # fmt: skip
    """Layout ``seed`` of ``base`` and the number of draws it took; ``clearance`` is the
    base's :class:`LayoutClearance` (built here when None). LayoutError after
    ``params.max_draws`` rejected draws, or if ``base`` is itself a layout."""
    params = params or LayoutParams()
    params.check()
    if base.base:
        raise LayoutError(f"{base.name} is a layout of {base.base}: randomize {base.base}")
    clearance = clearance or LayoutClearance(build_scene(base), params)
    rng = np.random.default_rng(seed)
    best = (-math.inf, "")  # the rejected draw whose closest pair was farthest apart
    for draw in range(1, params.max_draws + 1):
        poses = draw_poses(rng, clearance.start, params)
        found = clearance.closest(poses)
        if math.isinf(found[0]):
            scene = _with_poses(base, clearance.built, clearance.bodies, poses)
            scene.name, scene.base = layout_name(base.name, seed), base.name
            scene.layout_seed = seed
            scene.description = f"{base.description} (layout {seed} of {base.name})".lstrip()
            return scene, draw
        best = max(best, found)
    raise LayoutError(
        f"{layout_name(base.name, seed)}: none of {params.max_draws} draws kept every movable "
        f"object {params.clearance * 1000:g} mm from everything (best draw: {best[1]} "
        f"{best[0] * 1000:.1f} mm apart); change the shift or lower the clearance"
    )


def layout_text(scene: SceneFile, params: LayoutParams, draws: int) -> str:
    """The scene file of layout ``scene``: a header saying how it was drawn, then the YAML."""
    low, high = (1000 * s for s in params.shift)
    header = (
        f"{scene.name}: layout {scene.layout_seed} of scene {scene.base}, written by "
        f"`stucco-drake scenes randomize`.\n"
        f"Everything is {scene.base}'s but the movable objects' poses: each moved "
        f"{low:g}-{high:g} mm in the table\n"
        f"plane and turned within +-{math.degrees(params.max_yaw):g} deg about its vertical, "
        f"drawn from numpy.random.default_rng({scene.layout_seed})\n"
        f"(draw {draws}), every one at least {params.clearance * 1000:g} mm from everything "
        f"but the {params.support} by Drake's signed distance,\n"
        f"the robot at its start. {scene.base}'s own file lists the scene's deviations from "
        f"the paper."
    )
    return "".join(f"# {line}\n" for line in header.splitlines()) + yaml_dump_typed(scene)


def write_layouts(base: SceneFile, seeds, out: str | Path, params: LayoutParams | None = None
                  ) -> list[tuple[Path, SceneFile, int]]:  # fmt: skip
    """Writes layout ``s`` of ``base`` for every seed ``s`` to ``out/<name>.yaml``; returns
    (path, layout, draws) of each. A file already there is left if identical, else refused
    (LayoutError): logs of the table are keyed by scene name."""
    params = params or LayoutParams()
    params.check()
    clearance = LayoutClearance(build_scene(base), params)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    written = []
    for seed in seeds:
        scene, draws = randomize_scene(base, int(seed), params, clearance)
        path, text = out / f"{scene.name}.yaml", layout_text(scene, params, draws)
        if path.exists() and path.read_text(encoding="utf-8") != text:
            raise LayoutError(f"{path} exists and holds another layout; use another --out")
        path.write_text(text, encoding="utf-8")
        written.append((path, scene, draws))
    return written
