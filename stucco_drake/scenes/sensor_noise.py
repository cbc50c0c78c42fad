"""Scenes whose robot senses with noise: a copy of a scene with its ``sensor_noise`` set.

The paper simulates noise-free sensing. :data:`REAL_IIWA` is noise of the size a real iiwa with
soft bubbles shows (see ``docs/sensor_noise.md`` for where each figure comes from); the copy
is named ``<scene>-noise`` so the table keeps its logs apart from the noise-free scene's.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

from pydrake.common.yaml import yaml_dump_typed

from stucco_drake.core.inputs import InputError
from stucco_drake.scenes.scene_file import SceneFile, SensorNoise, load_scene_text

#: Joint-torque noise matching the free-space wrench noise the authors measured on their real
#: KUKA arm (2 N, 0.8 N m), and bubble contact points a few pixels' centroid shift off.
REAL_IIWA = SensorNoise(torque_std=2.0, velocity_std=0.0, bubble_point_std=0.002)


def noisy_name(name: str) -> str:
    """The name of ``name``'s noisy copy."""
    return f"{name}-noise"


def with_sensor_noise(scene: SceneFile, noise: SensorNoise = REAL_IIWA) -> SceneFile:
    """A copy of ``scene`` named :func:`noisy_name` whose senses have ``noise``, checked as a
    scene file is (SceneFileError, e.g. for a negative noise)."""
    copy = dataclasses.replace(scene, name=noisy_name(scene.name), sensor_noise=noise,
                               description=f"{scene.description} (noisy sensing)".lstrip())
    return load_scene_text(yaml_dump_typed(copy), where=copy.name)  # a deep, checked copy


def write_noisy_scene(scene: SceneFile, out: str | Path,
                      noise: SensorNoise = REAL_IIWA) -> Path:  # fmt: skip
    """Writes :func:`with_sensor_noise` of ``scene`` to ``out/<name>.yaml`` (a header saying
    what it is, then the YAML); returns the path. An existing different file is refused
    (InputError): the table keys its logs by scene name."""
    noisy = with_sensor_noise(scene, noise)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    header = (f"# {noisy.name}: scene {scene.name} with noisy sensing, written by "
              f"`stucco-drake scenes noise`.\n# Everything is {scene.name}'s but "
              f"sensor_noise; docs/sensor_noise.md gives the figures' sources.\n")
    path, text = out / f"{noisy.name}.yaml", header + yaml_dump_typed(noisy)
    if path.exists() and path.read_text(encoding="utf-8") != text:
        raise InputError(f"{path} exists and holds another scene; use another --out")
    path.write_text(text, encoding="utf-8")
    return path
