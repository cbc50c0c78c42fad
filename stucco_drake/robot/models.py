"""Where stucco_drake's model files live, and how a Drake ``Parser`` finds them.

Every model (the iiwa14 arm, the soft-bubble gripper, the YCB objects, the table and the wall) is
in the ``models/`` folder, which ``models/package.xml`` declares as the package
``stucco_drake_models``. Refer to a model by its URL, ``model_url("ycb/003_cracker_box.sdf")``,
and let every ``Parser`` that may meet such a URL go through :func:`configure_parser` first.

Nothing here touches the network: all models use primitive shapes and no ``drake_models`` files.
"""

from __future__ import annotations

from pathlib import Path, PurePosixPath

import numpy as np
from pydrake.math import RigidTransform
from pydrake.multibody.parsing import PackageMap, Parser
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import ModelInstanceIndex

PACKAGE_NAME = "stucco_drake_models"


def _find_models_dir() -> Path:
    """The repository's ``models/`` folder, else its copy shipped in the wheel (``_models``)."""
    package = Path(__file__).resolve().parents[1]  # stucco_drake/
    source_tree = package.parent / "models"
    if (source_tree / "package.xml").is_file():
        return source_tree
    return package / "_models"


MODELS_DIR: Path = _find_models_dir()

#: The grasp centre (frame ``gripper_frame``) lies this far along the flange's z axis [m].
FLANGE_TO_GRIPPER_FRAME_Z = 0.12


def configure_parser(parser: Parser) -> Parser:
    """Registers the ``stucco_drake_models`` package with ``parser`` (idempotent); returns it.

    With :func:`resolve_model_url` it is the one place that adds our ``package.xml`` to a
    package map. Call it on every ``Parser`` (simulation plant, controller plant, observer
    plant) before adding models.

    It also removes Drake's remote ``drake_models`` package from the map, so that a stray
    ``package://drake_models/...`` reference fails at once ("unknown package") instead of
    starting a download. (Setting ``DRAKE_ALLOW_NETWORK`` without ``package_map`` cannot do this
    with the pip wheel of Drake: there, every ``Parser`` construction then raises, because the
    default package map registers ``drake_models`` as a download-only package.)
    """
    _configure_package_map(parser.package_map())
    return parser


def _configure_package_map(package_map: PackageMap) -> PackageMap:
    if package_map.Contains("drake_models"):
        package_map.Remove("drake_models")
    if not package_map.Contains(PACKAGE_NAME):
        package_map.AddPackageXml(str(MODELS_DIR / "package.xml"))
    return package_map


def resolve_model_url(url: str) -> Path:
    """The file a model URL (``package://...``, ``file://...``) names, resolved as a
    :func:`configure_parser`-ed Parser resolves it; one-line ValueError when it names no file,
    so that a scene can be checked before its plant is built."""
    try:
        path = Path(_configure_package_map(PackageMap()).ResolveUrl(url))
    except RuntimeError as error:
        raise ValueError(str(error).removeprefix("error: ")) from None
    if not path.is_file():
        raise ValueError(f"URI '{url}' resolved to '{path}', which is not a file")
    return path


def model_url(relative: str) -> str:
    """``package://stucco_drake_models/<relative>`` for a file under ``models/``.

    Raises ValueError for an absolute path or one leaving ``models/``, and FileNotFoundError when
    the file does not exist, so that a typo fails here rather than deep inside the parser.
    """
    rel = PurePosixPath(relative)
    if rel.is_absolute() or ".." in rel.parts or not rel.parts:
        raise ValueError(f"expected a path relative to the models folder, got {relative!r}")
    if not (MODELS_DIR / rel).is_file():
        raise FileNotFoundError(f"no model file {rel} in package {PACKAGE_NAME}")
    return f"package://{PACKAGE_NAME}/{rel}"


IIWA14_URL = model_url("iiwa14/iiwa14.urdf")
BUBBLE_GRIPPER_URL = model_url("bubble_gripper/bubble_gripper.sdf")
TABLE_URL = model_url("table.sdf")
WALL_URL = model_url("wall.sdf")


def add_iiwa14_with_bubble_gripper(
    parser: Parser, *, iiwa_name: str = "iiwa", gripper_name: str = "bubble_gripper"
) -> tuple[ModelInstanceIndex, ModelInstanceIndex]:
    """Adds the iiwa14 and the bubble gripper welded to its flange; returns both instances.

    The gripper's mounting frame is welded to ``iiwa_link_ee`` with the identity transform, and a
    collision filter group excludes contact between the wrist links 5-7 and every gripper body
    (each model file filters its own parts, but neither file can name the other's bodies). The
    arm's base ``iiwa_link_0`` is left free: weld it where the scene wants it.
    """
    configure_parser(parser)
    a, g = iiwa_name, gripper_name
    members = ", ".join(
        [f"{a}::iiwa_link_{i}" for i in (5, 6, 7)]
        + [f"{g}::{body}" for body in ("body", "left_finger", "right_finger")]
    )
    directives = f"""
directives:
- add_model:
    name: {a}
    file: {IIWA14_URL}
- add_model:
    name: {g}
    file: {BUBBLE_GRIPPER_URL}
- add_weld:
    parent: {a}::iiwa_link_ee
    child: {g}::body
- add_collision_filter_group:
    name: {a}_wrist_and_{g}
    members: [{members}]
    ignored_collision_filter_groups: [{a}_wrist_and_{g}]
"""
    parser.AddModelsFromString(directives, "dmd.yaml")
    plant = parser.plant()
    return plant.GetModelInstanceByName(a), plant.GetModelInstanceByName(g)


#: Generalized coordinates of the iiwa's seven arm joints in :func:`iiwa_robot_plant` (the
#: gripper's two finger joints follow).
IIWA_ARM_JOINTS = tuple(range(7))


def iiwa_robot_plant(X_WB: RigidTransform | None = None) -> MultibodyPlant:
    """A continuous, finalized plant of the iiwa14 + bubble gripper alone, base welded at X_WB.

    The robot model the proprioceptive systems read (no objects). Its arm coordinates come
    first (:data:`IIWA_ARM_JOINTS`), then the two finger joints (m).
    """
    plant = MultibodyPlant(0.0)
    iiwa, _ = add_iiwa14_with_bubble_gripper(configure_parser(Parser(plant)))
    base = plant.GetFrameByName("iiwa_link_0", iiwa)
    plant.WeldFrames(plant.world_frame(), base, X_WB if X_WB is not None else RigidTransform())
    plant.Finalize()
    return plant


def iiwa_observed_robot_arguments(X_WB: RigidTransform | None = None,
                                  finger_positions=None) -> dict:  # fmt: skip
    """Arguments of ``ObservedRobot`` for our iiwa: its robot plant (base at X_WB), the
    ``gripper_frame``, the arm joints observed and the fingers held at ``finger_positions``
    ((2,) m, [right, left]; default the model's)."""
    plant = iiwa_robot_plant(X_WB)
    positions = plant.GetPositions(plant.CreateDefaultContext())
    if finger_positions is not None:
        positions[len(IIWA_ARM_JOINTS):] = np.asarray(finger_positions, dtype=float).reshape(-1)
    return {"plant": plant, "frame": plant.GetFrameByName("gripper_frame"),
            "joints": IIWA_ARM_JOINTS, "positions": positions}  # fmt: skip


def bubble_bodies(plant: MultibodyPlant, gripper_name: str = "bubble_gripper") -> list:
    """The bubble gripper's two fingers in ``plant`` (the bodies carrying its bubbles), left
    then right: the order of the bubble sensor's outputs."""
    instance = plant.GetModelInstanceByName(gripper_name)
    return [plant.GetBodyByName(name, instance) for name in ("left_finger", "right_finger")]
