"""Scene files: the typed schema of ``diagrams/<name>.yaml`` and its loader.

A scene file describes one simulated rummaging scene: the objects (Drake model directives, plus
inline primitive boxes and cylinders), the retrieval target, where the robot stands, where the
gripper starts, the prescribed planar action sequence, the plant configuration, the joint-level
control gains and the tracker parameters. It is read with pydrake's ``yaml_load_typed`` into
:class:`SceneFile`; every error is re-raised as one :class:`SceneFileError` line naming the file
and the offending key (its path: :func:`~stucco_drake.scenes.bad_yaml_key.locate_bad_key`).

Units: metres, radians, seconds, kilograms. Poses are in the world frame (z up, the table top at
z = 0).
"""

# No "from __future__ import annotations": yaml_load_typed reads the fields' real types.
import dataclasses
import math
from pathlib import Path

import numpy as np
from pydrake.common.yaml import yaml_load_typed
from pydrake.multibody.parsing import ModelDirective
from pydrake.multibody.plant import MultibodyPlantConfig

from stucco_drake.core import SoftTrackingParams
from stucco_drake.core.inputs import InputError
from stucco_drake.robot.models import resolve_model_url
from stucco_drake.scenes.bad_yaml_key import locate_bad_key


def _find_diagrams_dir() -> Path:
    """The repository's ``diagrams/`` folder, else its copy shipped in the wheel."""
    package = Path(__file__).resolve().parents[1]
    source_tree = package.parent / "diagrams"
    if (source_tree / "FB.yaml").is_file():
        return source_tree
    return package / "_diagrams"


#: Folder of the shipped scene files, one ``<name>.yaml`` per scene.
DIAGRAMS_DIR = _find_diagrams_dir()


_CONTACT_MODELS = ("hydroelastic_with_fallback", "hydroelastic", "point")
_APPROXIMATIONS = ("sap", "lagged", "similar", "tamsi")
_SURFACES = ("polygon", "triangle")


class SceneFileError(InputError):
    """A scene file could not be read; the message is one line: ``<file>: <key>: <reason>``."""


@dataclasses.dataclass
class Primitive:
    """A box or cylinder written inline in the scene file (training scenes, odd-sized walls).

    Attributes:
        name: model instance name (unique in the scene).
        shape: "box" or "cylinder" (the cylinder's axis is along the body's z).
        size: box: full extents [x, y, z]; cylinder: [radius, length] (m).
        xyz: position of the body's centre in the world frame (m).
        rpy: roll, pitch, yaw of the body in the world frame (rad).
        mass: kg; ignored when ``welded``.
        welded: weld to the world (an immovable wall) instead of a free body.
        friction: Coulomb friction coefficient (static = dynamic).
        rgba: colour of the visual.
    """

    name: str = ""
    shape: str = "box"
    size: list[float] = dataclasses.field(default_factory=list)
    xyz: list[float] = dataclasses.field(default_factory=lambda: [0.0, 0.0, 0.0])
    rpy: list[float] = dataclasses.field(default_factory=lambda: [0.0, 0.0, 0.0])
    mass: float = 1.0
    welded: bool = False
    friction: float = 0.5
    rgba: list[float] = dataclasses.field(default_factory=lambda: [0.5, 0.6, 0.8, 1.0])


@dataclasses.dataclass
class GripperStart:
    """Where the gripper starts and the height/orientation it holds throughout.

    Attributes:
        xy: planar position of the gripper frame (the grasp centre) in the world frame (m).
        height: z of the gripper frame above the table top (m), held during every action.
        yaw: angle from world x to the gripper's closing axis, about world z (rad); the
            gripper points straight down.
        finger_position: each finger joint's position, held throughout (m).
    """

    xy: list[float] = dataclasses.field(default_factory=lambda: [0.0, 0.0])
    height: float = 0.1
    yaw: float = 0.5 * math.pi
    finger_position: float = 0.0


@dataclasses.dataclass
class ControlParams:
    """Joint-level and end-effector control.

    Attributes:
        kp, kd, ki: gains of the inverse-dynamics controller on the arm's joints (1/s^2, 1/s,
            1/s^3); they multiply the mass matrix, so they act like a unit-mass PID on every
            joint. A planar force on the gripper at the BOR start posture meets an effective
            mass of 1.0-1.6 kg, so kp = 2500 holds it like a spring of 2400-4100 N/m; a lower
            kp gives a compliant arm that presses into what blocks it gradually rather than
            striking it.
        finger_kp, finger_kd, finger_ki: the same gains on the gripper's finger joints, kept
            apart so that a compliant arm still squeezes hard enough to lift the target.
        ik_period: period of the differential-IK update (s).
        ik_gain: pose-error feedback gain of the differential IK (1/s).
        move_fraction: fraction of each action's duration spent moving; the rest settles.
        max_step: per-axis clip of a planar step (m), the paper's 0.03.
        max_push_force: cap on the gripper's planar push (N), None for none; the paper's
            gripper was moved by a constraint of at most 30 N.
        nominal_q: a preferred arm posture (rad); turned about joint 1 to face the gripper's
            start, it seeds the start IK. The IK's null-space pull then holds the arm near its
            start posture.
    """

    kp: float = 2500.0
    kd: float = 100.0
    ki: float = 10.0
    finger_kp: float = 2500.0
    finger_kd: float = 100.0
    finger_ki: float = 10.0
    ik_period: float = 0.01
    ik_gain: float = 20.0
    move_fraction: float = 0.7
    max_step: float = 0.03
    max_push_force: float | None = None
    nominal_q: list[float] = dataclasses.field(
        # The IK solution with the gripper at the middle of the BOR scenes, from the
        # default base pose: a posture with the elbow up and well inside the joint limits.
        default_factory=lambda: [0.13, 1.6, 0.0, -1.53, 0.85, 0.01, 0.85]
    )


@dataclasses.dataclass
class SensorNoise:
    """Zero-mean Gaussian noise on the robot's senses (0: noise-free, the paper's simulation).

    Attributes:
        torque_std: on each measured joint torque (N m), before the momentum observer.
        velocity_std: on each measured joint velocity (rad/s), before the momentum observer.
        bubble_point_std: on each coordinate of a bubble's reported contact point (m).

    Draws come from generators seeded by the episode's seed (see ``docs/sensor_noise.md``
    for the values of a real iiwa with bubbles).
    """

    torque_std: float = 0.0
    velocity_std: float = 0.0
    bubble_point_std: float = 0.0


@dataclasses.dataclass
class SceneFile:
    """One scene (see the module docstring for units and frames).

    Attributes:
        name: the scene's short name (FB, BC, ...).
        description: free text.
        base: for a randomized layout (see :mod:`stucco_drake.scenes.randomize`), the name of
            the scene it was drawn from, whose actions and target it keeps; "" for a scene of
            its own.
        layout_seed: a randomized layout's seed (its generator's), None for a scene of its own.
        robot_base: [x, y, z, yaw] of the iiwa's base link in the world (m, m, m, rad). With
            z > 0 the base stands on a welded pedestal column from the table top up.
        workspace: [x_min, x_max, y_min, y_max] box the gripper may be sent to (m); see
            :meth:`in_workspace`, which also applies ``reach``.
        reach: [r_min, r_max] horizontal distance from the robot base within which the arm can
            hold the gripper's height and orientation (m); it depends on the base height.
        gripper_start: see :class:`GripperStart`.
        target: model instance name of the object to retrieve ("" for none).
        directives: Drake model directives adding the table, walls and objects.
        primitives: inline boxes and cylinders, see :class:`Primitive`.
        actions: normalized planar actions [u_x, u_y], each clipped to [-1, 1] and scaled by
            ``control.max_step`` into a step in metres along world x and y.
        action_duration: simulated time per action (s).
        plant: MultibodyPlant configuration (discrete time step, SAP, contact model).
        control: see :class:`ControlParams`.
        tracker_preset: "sim" or "real", the base of the tracker parameters.
        tracker: overrides of :class:`~stucco_drake.core.SoftTrackingParams` fields.
        friction: model instance name -> Coulomb friction (static = dynamic) given to every
            collision geometry of that model, replacing its file's (e.g. a table that must
            reproduce another simulator's combined object-ground friction).
        sensor_noise: see :class:`SensorNoise`.
    """

    name: str = ""
    description: str = ""
    base: str = ""
    layout_seed: int | None = None
    robot_base: list[float] = dataclasses.field(default_factory=lambda: [-0.22, 0.0, 0.4, 0.0])
    workspace: list[float] = dataclasses.field(default_factory=lambda: [-0.05, 0.42, -0.3, 0.3])
    # Measured by IK for a base 0.4 m up (0.10-0.70 m), less a margin from the stretched arm.
    reach: list[float] = dataclasses.field(default_factory=lambda: [0.15, 0.68])
    gripper_start: GripperStart = dataclasses.field(default_factory=GripperStart)
    target: str = ""
    directives: list[ModelDirective] = dataclasses.field(default_factory=list)
    primitives: list[Primitive] = dataclasses.field(default_factory=list)
    actions: list[list[float]] = dataclasses.field(default_factory=list)
    action_duration: float = 1.0
    plant: MultibodyPlantConfig = dataclasses.field(
        default_factory=lambda: MultibodyPlantConfig(
            time_step=0.002,
            discrete_contact_approximation="sap",
            contact_model="hydroelastic_with_fallback",
            use_sampled_output_ports=False,
        )
    )
    control: ControlParams = dataclasses.field(default_factory=ControlParams)
    tracker_preset: str = "sim"
    tracker: dict[str, float] = dataclasses.field(default_factory=dict)
    friction: dict[str, float] = dataclasses.field(default_factory=dict)
    sensor_noise: SensorNoise = dataclasses.field(default_factory=SensorNoise)

    def tracker_params(self) -> SoftTrackingParams:
        """The tracker parameters: ``tracker`` overrides on top of ``tracker_preset``."""
        return SoftTrackingParams.from_mapping(dict(self.tracker), preset=self.tracker_preset)

    def planar_steps(self) -> np.ndarray:
        """(N, 2) the prescribed actions as planar steps (m, world): each clipped to [-1, 1]
        per axis and scaled by ``control.max_step``."""
        actions = np.asarray(self.actions, dtype=float).reshape(-1, 2)
        return np.clip(actions, -1, 1) * self.control.max_step

    def in_workspace(self, xy) -> bool:
        """Whether planar point ``xy`` (m, world) is inside ``workspace`` and within ``reach``."""
        x, y = float(xy[0]), float(xy[1])
        x_min, x_max, y_min, y_max = self.workspace
        r = math.hypot(x - self.robot_base[0], y - self.robot_base[1])
        return x_min <= x <= x_max and y_min <= y <= y_max and self.reach[0] <= r <= self.reach[1]

    def model_names(self) -> list[str]:
        """Names of the model instances the directives and primitives add."""
        names = [d.add_model.name for d in self.directives if d.add_model is not None]
        return names + [p.name for p in self.primitives]


def resolve_scene_path(name_or_path: str | Path) -> Path:
    """``diagrams/<name>.yaml`` for a bare scene name, else the given path."""
    path = Path(name_or_path)
    if path.suffix in (".yaml", ".yml") or path.parent != Path("."):
        return path
    return DIAGRAMS_DIR / f"{name_or_path}.yaml"


def scene_paths(name_or_path: str | Path) -> list[Path]:
    """The scene files a scene argument stands for: a folder's ``*.yaml`` files (sorted by
    name), else the one file :func:`resolve_scene_path` gives. SceneFileError for a folder
    without any."""
    path = Path(name_or_path)
    if not path.is_dir():
        return [resolve_scene_path(name_or_path)]
    files = sorted(p for p in path.iterdir() if p.suffix in (".yaml", ".yml") and p.is_file())
    if not files:
        raise SceneFileError(f"{path}: <folder>: holds no .yaml scene file")
    return files


def load_scene(name_or_path: str | Path) -> SceneFile:
    """Reads and checks a scene file; raises :class:`SceneFileError` (one line) on any fault."""
    path = resolve_scene_path(name_or_path)
    try:
        text = path.read_text()
    except OSError as error:
        raise SceneFileError(f"{path}: <file>: {error.strerror or error}") from None
    return load_scene_text(text, where=str(path))


def load_scene_text(text: str, *, where: str = "<string>") -> SceneFile:
    """Like :func:`load_scene` for YAML text; ``where`` names the source in errors."""
    try:
        scene = yaml_load_typed(schema=SceneFile, data=text)
    except Exception as error:  # yaml_load_typed raises several types without the key path
        key = locate_bad_key(text, SceneFile)
        raise SceneFileError(f"{where}: {key}: {_one_line(error)}") from None
    try:
        _check(scene)
    except _BadValue as error:
        raise SceneFileError(f"{where}: {error.key}: {error.reason}") from None
    return scene


class _BadValue(Exception):
    def __init__(self, key: str, reason: str):
        super().__init__(f"{key}: {reason}")
        self.key, self.reason = key, reason


def _one_line(error: BaseException) -> str:
    text = " ".join(str(error).split()) or type(error).__name__
    return f"{type(error).__name__}: {text}" if isinstance(error, AssertionError) else text


def _check(scene: SceneFile) -> None:
    """Checks what the schema's types cannot express."""

    def need(ok: bool, key: str, reason: str):
        if not ok:
            raise _BadValue(key, reason)

    need(bool(scene.name), "name", "must be a non-empty string")
    need((scene.layout_seed is None) == (not scene.base), "layout_seed",
         "a randomized layout names both its base scene and its layout_seed")
    need(len(scene.robot_base) == 4, "robot_base", "expected [x, y, z, yaw]")
    need(len(scene.workspace) == 4, "workspace", "expected [x_min, x_max, y_min, y_max]")
    need(len(scene.reach) == 2 and 0 <= scene.reach[0] < scene.reach[1], "reach",
         "expected [r_min, r_max] with 0 <= r_min < r_max")
    need(scene.in_workspace(scene.gripper_start.xy), "gripper_start.xy",
         "outside the workspace or the arm's reach")
    need(len(scene.gripper_start.xy) == 2, "gripper_start.xy", "expected [x, y]")
    need(scene.gripper_start.height > 0, "gripper_start.height", "must be > 0")
    for i, action in enumerate(scene.actions):
        ok = len(action) == 2 and all(math.isfinite(a) for a in action)
        need(ok, f"actions[{i}]", f"expected two finite numbers, got {action}")
    need(scene.action_duration > 0, "action_duration", "must be > 0")
    for name, mu in scene.friction.items():
        need(math.isfinite(mu) and mu >= 0, f"friction.{name}", f"must be >= 0, got {mu}")
    for key, std in dataclasses.asdict(scene.sensor_noise).items():
        need(math.isfinite(std) and std >= 0, f"sensor_noise.{key}", f"must be >= 0, got {std}")
    plant = scene.plant
    need(plant.time_step > 0, "plant.time_step", "the plant must be discrete (> 0)")
    # Drake checks these only when the plant is built; a scene file should fail on loading.
    for key, value, known in (
        ("contact_model", plant.contact_model, _CONTACT_MODELS),
        ("discrete_contact_approximation", plant.discrete_contact_approximation, _APPROXIMATIONS),
        ("contact_surface_representation", plant.contact_surface_representation, _SURFACES),
    ):
        need(value in known, f"plant.{key}", f"unknown value {value!r} (known: {', '.join(known)})")
    c = scene.control
    need(0 < c.move_fraction <= 1, "control.move_fraction", "must lie in (0, 1]")
    need(c.max_step > 0, "control.max_step", "must be > 0")
    for key in ("kp", "kd", "finger_kp", "finger_kd"):
        need(getattr(c, key) > 0, f"control.{key}", "must be > 0")
    for key in ("ki", "finger_ki"):
        need(getattr(c, key) >= 0, f"control.{key}", "must be >= 0")
    need(c.max_push_force is None or c.max_push_force > 0, "control.max_push_force",
         "must be > 0 (or omitted)")
    need(c.ik_period >= scene.plant.time_step, "control.ik_period", "must be >= plant.time_step")
    need(len(c.nominal_q) == 7, "control.nominal_q", "expected 7 joint angles")
    for i, p in enumerate(scene.primitives):
        key = f"primitives[{i}]"
        need(bool(p.name), f"{key}.name", "must be a non-empty string")
        need(p.shape in ("box", "cylinder"), f"{key}.shape", f"unknown shape {p.shape!r}")
        n_size = 3 if p.shape == "box" else 2
        need(len(p.size) == n_size and min(p.size) > 0, f"{key}.size",
             f"expected {n_size} positive numbers")
        need(len(p.xyz) == 3 and len(p.rpy) == 3, f"{key}.xyz", "xyz and rpy need 3 numbers")
        need(p.welded or p.mass > 0, f"{key}.mass", "a free body needs mass > 0")
        need(len(p.rgba) == 4, f"{key}.rgba", "expected 4 numbers")
    names = scene.model_names()
    duplicates = sorted({n for n in names if names.count(n) > 1})
    need(not duplicates, "directives", f"duplicate model names {duplicates}")
    need(not scene.target or scene.target in names, "target",
         f"{scene.target!r} is not a model the scene adds")
    try:
        scene.tracker_params()
    except ValueError as error:
        raise _BadValue("tracker", _one_line(error)) from None
    _check_model_files(scene)


def _check_model_files(scene: SceneFile) -> None:
    """Every file the directives name exists (Drake finds out only when it builds the plant)."""
    for i, directive in enumerate(scene.directives):
        for kind in ("add_model", "add_directives"):
            entry = getattr(directive, kind)
            if entry is None:
                continue
            try:
                resolve_model_url(entry.file)
            except ValueError as error:
                raise _BadValue(f"directives[{i}].{kind}.file", str(error)) from None
