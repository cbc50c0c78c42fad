"""Meshcat for the command line: a live viewer and/or a standalone HTML recording, and the view
a scene opens with."""

from __future__ import annotations

from pathlib import Path

import numpy as np

#: Where the camera opens, in the robot base's frame (m): behind the base, to its right and
#: high above its shoulder. From there it looks into the cupboard over its walls, which are far
#: lower, at the face of the clutter the robot works on; the arm reaches in from the left of
#: the view, and only the forearm, coming down to the gripper, crosses the clutter.
CAMERA_IN_BASE = (-0.25, -0.85, 0.9)
#: The camera's vertical field of view (deg): narrower than Meshcat's default 75, so that the
#: clutter fills the view from that distance.
CAMERA_FOV = 30.0
#: Height (m) above the table the camera looks at, over the middle of the free objects.
CAMERA_TARGET_HEIGHT = 0.08


def show_over_the_shoulder(meshcat, built) -> None:
    """Points Meshcat's camera from over the robot's shoulder (:data:`CAMERA_IN_BASE`) at the
    middle of the scene's free objects (their default poses; without any, over the robot's
    base), :data:`CAMERA_TARGET_HEIGHT` above the table.

    ``built`` is a :class:`~stucco_drake.scenes.builder.BuiltScene`. A recording opens with
    this view; the viewer can still turn the camera.
    """
    from pydrake.geometry import Meshcat

    from stucco_drake.scenes.builder import robot_base_pose

    context = built.plant.CreateDefaultContext()
    objects = [body.EvalPoseInWorld(context).translation() for body in built.free_bodies.values()]
    X_WB = robot_base_pose(built.scene)
    middle = np.mean(objects, axis=0) if objects else X_WB.translation()
    target = np.array([middle[0], middle[1], CAMERA_TARGET_HEIGHT])
    meshcat.SetCamera(Meshcat.PerspectiveCamera(fov=CAMERA_FOV))
    meshcat.SetCameraPose(X_WB @ np.asarray(CAMERA_IN_BASE), target)


def start_meshcat(show: bool, record: str | None):
    """A Meshcat bound to this machine when showing or recording (else None); prints its URL
    when showing and starts recording when ``record`` names an output file."""
    if not (show or record):
        return None
    from pydrake.geometry import Meshcat, MeshcatParams

    # Bound to this machine only; a recording alone needs no viewer.
    meshcat = Meshcat(MeshcatParams(host="localhost"))
    if show:
        print(f"meshcat: {meshcat.web_url()}", flush=True)
    if record:
        meshcat.StartRecording(set_visualizations_while_recording=bool(show))
    return meshcat


def save_recording(meshcat, path: str | Path) -> None:
    """Stops the recording and writes it as a standalone HTML file (opens with no server)."""
    meshcat.StopRecording()
    meshcat.PublishRecording()
    Path(path).write_text(meshcat.StaticHtml())
    print(f"recording: {path}")
