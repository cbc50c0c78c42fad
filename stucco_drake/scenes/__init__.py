"""Scenes: typed scene files (``diagrams/*.yaml``), their Diagram builder and playback."""

from stucco_drake.scenes.builder import BuiltScene, build_scene
from stucco_drake.scenes.scene_file import (
    DIAGRAMS_DIR,
    SceneFile,
    SceneFileError,
    load_scene,
    load_scene_text,
    resolve_scene_path,
    scene_paths,
)

__all__ = [
    "DIAGRAMS_DIR",
    "BuiltScene",
    "SceneFile",
    "SceneFileError",
    "build_scene",
    "load_scene",
    "load_scene_text",
    "resolve_scene_path",
    "scene_paths",
]
