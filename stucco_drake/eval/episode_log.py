"""A versioned ``.npz`` log of one episode (scene, seed), replayed by every tracking method.

Layout (format version 2; T actions, N contacts, k objects; metres, radians, world frame):

- ``ee_position`` (T, 3) and ``ee_rotation`` (T, 3, 3): the EE pose after each action.
- ``contact_points``, ``contact_dx`` (N, 3): every action's detected contacts, flat; those of
  action t are rows ``contact_offsets[t]:contact_offsets[t + 1]`` (``contact_offsets`` (T + 1,)).
- ``contact_object`` (N,): index of the object each contact truly touched, -1 if none/unknown.
- ``object_poses`` (T + 1, k, 3): planar poses (x, y, yaw) of every object (walls included),
  row 0 before the first action, row t + 1 after action t. Planar, because the tasks are
  planar and the paper scores CE on objects extruded in z; the Drake producer projects its
  7-vector poses to (x, y, yaw about z).
- ``object_shapes`` (m, 7): the objects' primitives, each in its object's pose frame (see
  :func:`box_spec` and :func:`cylinder_spec`), and ``shape_object`` (m,) the object each
  belongs to (an object may be made of several); ``object_names`` (k,).
- ``robot_object_distance`` (T, k): distance from the robot to each object after each action
  (m, 0 in contact), or (0, k) when the producer did not log it.
- ``robot_shape`` (7,) the EE as a primitive (for pxpen), or (0,) when the replayer must be
  given the robot's penetration.
- ``action_peak_force`` (T,): the largest estimated external force on the EE while in contact
  in each action (N, NaN where not measured), or (0,) in logs made before it was recorded.
- ``final_state``: opaque float array (e.g. the final plant state), for the grasp attempt.
- metadata: ``scene``, ``seed``, ``action_noise`` (m, half-width of the uniform noise added
  to every action axis), ``format_version``, ``info`` (JSON object, free-form).
"""

from __future__ import annotations

import dataclasses
import json
import zipfile
from pathlib import Path

import numpy as np

from stucco_drake.core.npz import save_npz_atomically
from stucco_drake.core.shapes import BoxSdf, CylinderSdf

FORMAT_VERSION = 2
SHAPE_BOX, SHAPE_CYLINDER = 0, 1
#: Half height (m) of the objects when scoring CE: extruded, as in the paper, so only xy counts.
_EXTRUDED_HALF_HEIGHT = 1.0


def box_spec(half_x, half_y, half_z, offset=(0.0, 0.0), yaw: float = 0.0) -> np.ndarray:
    """Shape row of a box with half extents (m), centred at ``offset`` (m) in the pose frame
    and turned by ``yaw`` (rad) about z relative to it."""
    return np.array([SHAPE_BOX, half_x, half_y, half_z, *offset, yaw], dtype=np.float64)


def cylinder_spec(radius, half_height, offset=(0.0, 0.0)) -> np.ndarray:
    """Shape row of a vertical cylinder (m), its axis at ``offset`` (m) in the pose frame."""
    return np.array([SHAPE_CYLINDER, radius, 0.0, half_height, *offset, 0.0], dtype=np.float64)


def shape_sdf(spec, extruded: bool = False):
    """The :class:`BoxSdf`/:class:`CylinderSdf` of a shape row, centred in its own frame."""
    kind, a, b, half_z = (float(v) for v in spec[:4])
    half_z = _EXTRUDED_HALF_HEIGHT if extruded else half_z
    if kind == SHAPE_BOX:
        return BoxSdf(half_extents=(a, b, half_z))
    if kind == SHAPE_CYLINDER:
        return CylinderSdf(radius=a, half_height=half_z)
    raise ValueError(f"unknown shape kind {kind:g} (0 = box, 1 = cylinder)")


@dataclasses.dataclass(frozen=True)
class PlanarSurface:
    """Signed distance (m) to an extruded object at planar pose (x, y, yaw); picklable."""

    spec: tuple
    pose: tuple

    def __call__(self, points) -> np.ndarray:
        points = np.asarray(points, dtype=np.float64)
        x, y, yaw = self.pose
        c, s = np.cos(yaw), np.sin(yaw)
        dx, dy = points[..., 0] - x, points[..., 1] - y
        # World -> object frame (R(yaw)^T), then -> shape frame (minus its offset, turned
        # back by its yaw); z = 0 because the shape is extruded.
        ox, oy = c * dx + s * dy - self.spec[4], -s * dx + c * dy - self.spec[5]
        cs, ss = np.cos(self.spec[6]), np.sin(self.spec[6])
        local = np.stack([cs * ox + ss * oy, -ss * ox + cs * oy, 0.0 * dx], axis=-1)
        return shape_sdf(self.spec, extruded=True)(local)


_ARRAYS = {  # array field -> dtype; shapes are checked in EpisodeLog.validate()
    "ee_position": np.float64,
    "ee_rotation": np.float64,
    "contact_offsets": np.int64,
    "contact_points": np.float64,
    "contact_dx": np.float64,
    "contact_object": np.int64,
    "object_poses": np.float64,
    "object_shapes": np.float64,
    "shape_object": np.int64,
    "robot_object_distance": np.float64,
    "robot_shape": np.float64,
    "action_peak_force": np.float64,
    "final_state": np.float64,
}
#: Arrays a log of this format version may lack (written later): read as empty.
_OPTIONAL = ("action_peak_force",)


@dataclasses.dataclass
class EpisodeLog:
    """One simulated episode: observations, ground truth and metadata (see the module doc)."""

    scene: str
    seed: int
    action_noise: float
    ee_position: np.ndarray
    ee_rotation: np.ndarray
    contact_offsets: np.ndarray
    contact_points: np.ndarray
    contact_dx: np.ndarray
    contact_object: np.ndarray
    object_names: list[str]
    object_poses: np.ndarray
    object_shapes: np.ndarray
    robot_object_distance: np.ndarray
    robot_shape: np.ndarray
    final_state: np.ndarray
    shape_object: np.ndarray | None = None  # default: one shape per object, in order
    action_peak_force: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros(0))
    info: dict = dataclasses.field(default_factory=dict)

    def __post_init__(self):
        if self.shape_object is None:
            self.shape_object = np.arange(len(self.object_shapes))
        for name, dtype in _ARRAYS.items():
            setattr(self, name, np.asarray(getattr(self, name), dtype=dtype))
        self.object_names = [str(n) for n in self.object_names]
        self.validate()

    @property
    def n_actions(self) -> int:
        return len(self.ee_position)

    @property
    def n_contacts(self) -> int:
        return len(self.contact_points)

    def contacts(self, t: int):
        """(points (m, 3), dx (m, 3), true objects (m,)) of action ``t``."""
        lo, hi = self.contact_offsets[t], self.contact_offsets[t + 1]
        return self.contact_points[lo:hi], self.contact_dx[lo:hi], self.contact_object[lo:hi]

    def first(self, actions: int) -> EpisodeLog:
        """The episode as it stood after its first ``actions`` actions (1 to ``n_actions``):
        what was sensed until then and the objects' poses at the end of action ``actions``.
        The plant's state there was not logged, so ``final_state`` is empty (a cut cannot be
        grasped again) and ``info["first_actions"]`` says where it was cut."""
        if not 1 <= actions <= self.n_actions:
            raise ValueError(f"actions: expected 1 to {self.n_actions}, got {actions}")
        n = int(self.contact_offsets[actions])
        cut = slice(0, n)
        distances = self.robot_object_distance
        return dataclasses.replace(
            self, ee_position=self.ee_position[:actions], ee_rotation=self.ee_rotation[:actions],
            contact_offsets=self.contact_offsets[:actions + 1],
            contact_points=self.contact_points[cut], contact_dx=self.contact_dx[cut],
            contact_object=self.contact_object[cut], object_poses=self.object_poses[:actions + 1],
            robot_object_distance=distances[:actions] if len(distances) else distances,
            action_peak_force=self.action_peak_force[:actions],
            final_state=np.zeros(0), info={**self.info, "first_actions": int(actions)},
        )  # fmt: skip

    def final_surfaces(self) -> list[PlanarSurface]:
        """Signed distances of every object at its final pose, extruded in z (CE's surfaces)."""
        poses = self.object_poses[-1]
        return [
            PlanarSurface(tuple(spec), tuple(poses[k]))
            for spec, k in zip(self.object_shapes, self.shape_object, strict=True)
        ]

    def validate(self) -> None:
        """Raises ValueError naming the first inconsistent array."""
        t, n, k = self.n_actions, len(self.contact_points), len(self.object_names)
        expected = {
            "ee_position": (t, 3),
            "ee_rotation": (t, 3, 3),
            "contact_offsets": (t + 1,),
            "contact_points": (n, 3),
            "contact_dx": (n, 3),
            "contact_object": (n,),
            "object_poses": (t + 1, k, 3),
            "object_shapes": (len(self.shape_object), 7),
            "shape_object": (len(self.object_shapes),),
        }
        for name, shape in expected.items():
            if getattr(self, name).shape != shape:
                raise ValueError(f"{name}: expected shape {shape}, got {getattr(self, name).shape}")
        offsets = self.contact_offsets
        if offsets[0] != 0 or offsets[-1] != n or np.any(np.diff(offsets) < 0):
            raise ValueError("contact_offsets: must rise from 0 to the number of contacts")
        if self.robot_object_distance.shape not in ((t, k), (0, k)):
            raise ValueError(
                f"robot_object_distance: expected shape ({t}, {k}) or (0, {k}), "
                f"got {self.robot_object_distance.shape}"
            )
        if self.action_peak_force.shape not in ((t,), (0,)):
            raise ValueError(f"action_peak_force: expected shape ({t},) or (0,), "
                             f"got {self.action_peak_force.shape}")
        if self.robot_shape.shape not in ((7,), (0,)):
            raise ValueError(
                f"robot_shape: expected shape (7,) or (0,), got {self.robot_shape.shape}"
            )
        if np.any((self.shape_object < 0) | (self.shape_object >= k)):
            raise ValueError(f"shape_object: indices must lie in [0, {k})")
        if np.any((self.contact_object < -1) | (self.contact_object >= k)):
            raise ValueError(f"contact_object: indices must lie in [-1, {k})")

    # ------------------------------------------------------------------------------------ I/O
    def save(self, path: str | Path) -> None:
        """Write the log atomically (a crash never leaves a partial file)."""
        arrays = {name: getattr(self, name) for name in _ARRAYS}
        save_npz_atomically(
            path,
            compressed=True,
            format_version=np.int64(FORMAT_VERSION),
            scene=np.str_(self.scene),
            seed=np.int64(self.seed),
            action_noise=np.float64(self.action_noise),
            object_names=np.array(self.object_names, dtype=np.str_).reshape(-1),
            info=np.str_(json.dumps(self.info, sort_keys=True)),
            **arrays,
        )

    @classmethod
    def load(cls, path: str | Path) -> EpisodeLog:
        """Read a log; one-line ValueError for a wrong format version or a malformed file."""
        try:
            with np.load(path, allow_pickle=False) as data:
                if "format_version" not in data.files:
                    raise ValueError("no format_version")
                version = int(data["format_version"])
                if version != FORMAT_VERSION:
                    raise _VersionError(
                        f"{path}: episode log format version {version}, this code reads version "
                        f"{FORMAT_VERSION} (re-simulate the episode)"
                    )
                fields = {name: data[name] for name in _ARRAYS
                          if name in data.files or name not in _OPTIONAL}
                return cls(
                    scene=str(data["scene"]),
                    seed=int(data["seed"]),
                    action_noise=float(data["action_noise"]),
                    object_names=list(data["object_names"]),
                    info=json.loads(str(data["info"])),
                    **fields,
                )
        except _VersionError:
            raise
        except (OSError, ValueError, KeyError, TypeError, zipfile.BadZipFile, EOFError) as error:
            reason = str(error).splitlines()[0] if str(error) else type(error).__name__
            raise ValueError(f"{path}: not a valid episode log ({reason})") from None


class _VersionError(ValueError):
    """A well-formed log of another format version."""
