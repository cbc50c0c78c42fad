"""A BOR episode that ends by touching the target last: the prescribed actions, then probes.

The scene's prescribed actions play as in :func:`~stucco_drake.bor.log.record_episode` (the
same perturbed steps, so the same physics up to their end), then the BOR Diagram's
:class:`~stucco_drake.systems.probe_policy.ProbePolicy` touches the faces of the likeliest pose
of the live target-pose hypotheses, each action's step decided at its start from the
detector's verdict on the action before (the tracked points lag one action behind, the
pipeline's delay).
Units: m, rad, s; world frame.
"""

from __future__ import annotations

import dataclasses
import functools

from stucco_drake.bor.diagram import build_bor_diagram
from stucco_drake.bor.episode import make_bor_simulator, run_episode
from stucco_drake.bor.log import ACTION_NOISE, EpisodeRecorder, perturbed_scene
from stucco_drake.core.probing import ProbeParams
from stucco_drake.eval.episode_log import EpisodeLog
from stucco_drake.eval.sources import EpisodeSource
from stucco_drake.runtime import kernels
from stucco_drake.scenes import SceneFile, load_scene


def record_probed_episode(scene: SceneFile | str, seed: int, *, action_noise: float = ACTION_NOISE,
                          method: str = "stucco", tracker_params=None, dx_model: str = "cone",
                          probe: ProbeParams | None = None) -> EpisodeLog:  # fmt: skip
    """Simulates ``scene`` with run ``seed``'s perturbed prescribed actions followed by the
    probes (:class:`~stucco_drake.systems.probe_policy.ProbePolicy` with ``probe``, default
    settings when None), and logs every action. The live Diagram tracks with ``method``
    (``tracker_params``, ``dx_model``), whose pose hypotheses choose the probes. The log's
    ``info`` says how many actions were prescribed, how many probed and how many probes
    touched."""
    base = load_scene(scene) if isinstance(scene, str) else scene
    scene = perturbed_scene(base, seed, action_noise)
    bor = build_bor_diagram(scene, method, seed, tracker_params=tracker_params,
                            dx_model=dx_model, probe=probe or ProbeParams())
    simulator = make_bor_simulator(bor)
    context = simulator.get_mutable_context()
    recorder = EpisodeRecorder(bor, context)
    result = run_episode(scene, method, seed, bor=bor, simulator=simulator,
                         on_action=recorder.on_action)
    probing = bor.policy.probe_state(bor.policy.GetMyContextFromRoot(context)).policy
    return recorder.log(base.name, seed, action_noise, {
        "wall_time_s": float(result.wall_time_s),
        "kernels": kernels.status(),
        "live": {"method": method, "ce_cm": float(result.ce_cm), "fmi": float(result.fmi)},
        "policy": {"name": "probe", "prescribed_actions": len(scene.actions),
                   "probe_actions": probing.actions, "touches": probing.touches,
                   "probes": probing.probes_done, "bumps": probing.bumps},
    })


def record_probed_scene(scene_ref: str, tracker_params, dx_model: str, name: str,
                        seed: int) -> EpisodeLog:  # fmt: skip
    """:func:`record_probed_episode` of the scene ``scene_ref`` (a name or a scene file),
    which must be the scene ``name`` (the table's key for it)."""
    scene = load_scene(scene_ref)
    if scene.name != name:
        raise ValueError(f"{scene_ref} holds scene {scene.name!r}, not {name!r}")
    return record_probed_episode(scene, seed, tracker_params=tracker_params, dx_model=dx_model)


def probe_source(source: EpisodeSource, name: str, stucco_params, dx_model: str) -> EpisodeSource:
    """``source`` with its episodes recorded by :func:`record_probed_episode` (the live
    tracker STUCCO with ``stucco_params``, None: the scene's, under ``dx_model``); ValueError
    for a scene with no target to grasp."""
    if source.grasp is None:
        raise ValueError(f"--policy probe: scene {name} has no target to grasp")
    return dataclasses.replace(source, produce=functools.partial(
        record_probed_scene, source.scene_file or name, stucco_params, dx_model))


#: The closed-loop policies ``stucco-drake table --policy`` offers besides ``prescribed``.
POLICIES = {"probe": probe_source}
