"""The sources of ``stucco-drake table`` beyond the paper's scenes: scene files and folders
of them (randomized layouts), and episodes recorded under a closed-loop policy
(:mod:`stucco_drake.bor.policies`) instead of a scene's prescribed actions."""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Mapping, Sequence
from pathlib import Path

from stucco_drake.bor import log as bor_log
from stucco_drake.core.coverage import CoverageParams
from stucco_drake.core.probe_params import ProbeParams
from stucco_drake.core.rummage_params import RummageParams
from stucco_drake.eval.episode_log import EpisodeLog
from stucco_drake.eval.sets import scene_set
from stucco_drake.eval.sources import EpisodeSource
from stucco_drake.scenes import SceneFile, load_scene, resolve_scene_path, scene_paths


def record_scene_file(path: str, name: str, seed: int, **record) -> EpisodeLog:
    """:func:`~stucco_drake.bor.log.record_episode` (with ``record``'s keywords) of the
    scene ``path`` (a scene file or a scene's name), which must be the scene ``name`` (the
    table's key for it)."""
    scene = load_scene(path)
    if scene.name != name:
        raise ValueError(f"{path} holds scene {scene.name!r}, not {name!r}")
    return bor_log.record_episode(scene, seed, **record)


#: The settings of each closed-loop policy ``stucco-drake table --policy`` offers besides
#: ``prescribed`` (see :mod:`stucco_drake.bor.policies`).
POLICY_SETTINGS = {"probe": ProbeParams, "belief": RummageParams, "sweep": CoverageParams}


def policy_source(source: EpisodeSource, name: str, stucco_params, dx_model: str,
                  policy: str, settings=None) -> EpisodeSource:  # fmt: skip
    """``source`` with its episodes recorded under the policy named ``policy`` (a key of
    :data:`POLICY_SETTINGS`) with ``settings`` (an instance of its settings class; None: the
    defaults) (:func:`~stucco_drake.bor.log.record_episode`, the live tracker STUCCO with
    ``stucco_params``, None: the scene's, under ``dx_model``); ValueError for a scene with no
    target to grasp."""
    if source.grasp is None:
        raise ValueError(f"--policy {policy}: scene {name} has no target to grasp")
    settings = POLICY_SETTINGS[policy]() if settings is None else settings
    if not isinstance(settings, POLICY_SETTINGS[policy]):
        raise ValueError(f"--policy {policy} takes {POLICY_SETTINGS[policy].__name__}, "
                         f"not {type(settings).__name__}")
    return dataclasses.replace(source, produce=functools.partial(
        record_scene_file, source.scene_file or name, tracker_params=stucco_params,
        dx_model=dx_model, policy=settings))


#: The closed-loop policies ``stucco-drake table --policy`` offers besides ``prescribed``.
POLICIES = {name: functools.partial(policy_source, policy=name) for name in POLICY_SETTINGS}


def scene_file_source(path: str | Path, scene: SceneFile) -> EpisodeSource:
    """The table's source of ``scene``, read from the file at ``path``: its episodes and
    grasps are that file's (picklable, for worker processes)."""
    path = str(Path(path).resolve())
    return EpisodeSource(
        functools.partial(record_scene_file, path), bor_log.log_penetration,
        functools.partial(bor_log.grasp_success, scene=path),
        scene_set=scene_set(scene.name, scene.base, scene.layout_seed),
        family=scene.base if scene.layout_seed is not None else "", scene_file=path,
    )  # fmt: skip


def table_scenes(args: Sequence[str], sources: Mapping[str, EpisodeSource]):
    """(scene names, sources) of the table's ``--scenes`` arguments: each is a name of
    ``sources``, a scene file or a folder of them (every ``*.yaml`` in it, by name); a file's
    scene is named by its ``name`` field. Other arguments are kept as names, for the table to
    report as unknown. ValueError when two files give one name, or a file a name of
    ``sources`` that is not that file."""
    names, known = [], dict(sources)
    files: dict[str, Path] = {}
    for arg in args:
        if arg in sources or not Path(arg).exists():
            names.append(arg)
            continue
        for path in scene_paths(arg):
            scene, path = load_scene(path), path.resolve()
            taken = files.get(scene.name)
            if taken is None and scene.name in known:
                taken = resolve_scene_path(scene.name).resolve()
            if taken is not None and taken != path:
                raise ValueError(f"{path}: its scene {scene.name!r} is also {taken}; "
                                 "rename one (the table keys its logs by scene name)")
            if scene.name not in known:
                files[scene.name] = path
                known[scene.name] = scene_file_source(path, scene)
            names.append(scene.name)
    return list(dict.fromkeys(names)), known
