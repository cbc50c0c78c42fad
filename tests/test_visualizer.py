"""ContactTrackingVisualizer: the Meshcat paths and poses it sets, what a recording keeps, and a
recording of a simulated scene rendered in headless Chromium."""

from __future__ import annotations

import base64
import os
import re
import shutil
import subprocess

import msgpack
import numpy as np
import pytest
from PIL import Image
from pydrake.common.value import AbstractValue
from pydrake.math import RigidTransform, RotationMatrix
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder, LeafSystem

from stucco_drake.core.observation import ActionContacts
from stucco_drake.core.shapes import BoxSdf, CylinderSdf
from stucco_drake.scenes import build_scene, load_scene
from stucco_drake.systems.contact_tracking_visualizer import (
    ContactTrackingVisualizer,
    shape_outline,
)

BOX = BoxSdf((0.08, 0.105, 0.03))  # about the FB cracker box, lying flat (m)
X_WO = RigidTransform(RotationMatrix.MakeZRotation(0.3), [0.15, 0.05, 0.10])


def unpack(raw: bytes):
    return msgpack.unpackb(raw, strict_map_key=False) if raw else None


def translation_at(meshcat, path: str) -> np.ndarray:
    """The translation (m) Meshcat holds for ``path`` (its 4x4 matrix is column-major)."""
    matrix = unpack(meshcat._GetPackedTransform(path))["matrix"]
    return np.asarray(matrix, dtype=float).reshape(4, 4).T[:3, 3]


def visible(meshcat, path: str):
    message = unpack(meshcat._GetPackedProperty(path, "visible"))
    return None if message is None else message["value"]


def fix_inputs(visualizer, context, points, labels, contacts, pose) -> None:
    visualizer.GetInputPort("map_points").FixValue(context, np.asarray(points, dtype=float))
    visualizer.GetInputPort("segment_labels").FixValue(context, np.asarray(labels))
    visualizer.GetInputPort("action_contacts").FixValue(context, contacts)
    visualizer.GetInputPort("target_pose").FixValue(context, pose)


POINTS = np.array([[0.10, 0.00, 0.12], [0.20, 0.05, 0.12], [0.25, 0.10, 0.11], [0.0, 0.0, 0.1]])
LABELS = np.array([0, 1, 1, -1])


def test_draws_points_by_segment_contacts_and_outline(meshcat):
    visualizer = ContactTrackingVisualizer(meshcat, BOX, publish_period=0.1)
    context = visualizer.CreateDefaultContext()
    contacts = ActionContacts(4, POINTS[1:3], np.zeros((2, 3)))
    fix_inputs(visualizer, context, POINTS, LABELS, contacts, X_WO)
    visualizer.ForcedPublish(context)

    # Palette colour 0 holds point 0, colour 1 points 1 and 2; label -1 is unlabelled.
    expected = {"/stucco/map/0/0": POINTS[0], "/stucco/map/1/0": POINTS[1],
                "/stucco/map/1/1": POINTS[2], "/stucco/map/unlabelled/0": POINTS[3],
                "/stucco/contacts/0": POINTS[1], "/stucco/contacts/1": POINTS[2]}
    for path, point in expected.items():
        assert meshcat.HasPath(path), path
        np.testing.assert_allclose(translation_at(meshcat, path), point, atol=1e-12)
        assert visible(meshcat, path) is True, path
    assert not meshcat.HasPath("/stucco/map/1/2")
    assert not meshcat.HasPath("/stucco/map/2/0")
    assert meshcat.HasPath("/stucco/target/outline")
    assert visible(meshcat, "/stucco/target") is True
    matrix = unpack(meshcat._GetPackedTransform("/stucco/target"))["matrix"]
    np.testing.assert_allclose(np.reshape(matrix, (4, 4)).T, X_WO.GetAsMatrix4(), atol=1e-12)

    # Fewer points and contacts later: the spare spheres hide, the rest move.
    context.SetTime(0.1)
    fix_inputs(visualizer, context, POINTS[:2], [1, 1], ActionContacts(5), X_WO)
    visualizer.ForcedPublish(context)
    assert visible(meshcat, "/stucco/map/0/0") is False
    np.testing.assert_allclose(translation_at(meshcat, "/stucco/map/1/0"), POINTS[0])
    np.testing.assert_allclose(translation_at(meshcat, "/stucco/map/1/1"), POINTS[1])
    assert visible(meshcat, "/stucco/contacts/0") is False


def test_outline_hidden_until_an_estimate(meshcat):
    visualizer = ContactTrackingVisualizer(meshcat, BOX, publish_period=0.1)
    context = visualizer.CreateDefaultContext()
    fix_inputs(visualizer, context, np.zeros((0, 3)), [], ActionContacts(), RigidTransform())
    visualizer.ForcedPublish(context)
    assert meshcat.HasPath("/stucco/target/outline")
    assert visible(meshcat, "/stucco/target") is False


def test_estimate_body_sits_inside_the_outline(meshcat):
    visualizer = ContactTrackingVisualizer(meshcat, CylinderSdf(0.04, 0.06, (0.0, 0.0, 0.06)),
                                           publish_period=0.1)  # fmt: skip
    context = visualizer.CreateDefaultContext()
    fix_inputs(visualizer, context, POINTS, LABELS, ActionContacts(), X_WO)
    visualizer.ForcedPublish(context)
    body = unpack(meshcat._GetPackedObject("/stucco/target/body"))["object"]
    (geometry,), (material,) = body["geometries"], body["materials"]
    assert geometry["type"] == "CylinderGeometry"
    assert geometry["radiusTop"] == pytest.approx(0.04)
    assert geometry["height"] == pytest.approx(0.12)
    assert material["transparent"] and material["opacity"] < 0.5  # the points inside show
    # At the cylinder's centre in the target frame; the frame is the outline's (the estimate).
    np.testing.assert_allclose(translation_at(meshcat, "/stucco/target/body"), [0, 0, 0.06])
    # The spheres are large enough to see from a view of the whole scene (1 cm and more), and
    # the latest contacts translucent around the tracked points drawn at the same places.
    point = unpack(meshcat._GetPackedObject("/stucco/map/0/0"))["object"]
    assert point["geometries"][0]["radius"] >= 0.01
    contact = unpack(meshcat._GetPackedObject("/stucco/contacts/0"))
    assert contact is None or contact["object"]["materials"][0]["transparent"]


def test_a_scene_opens_looking_into_the_cupboard_over_its_walls(meshcat):
    from stucco_drake.bor.diagram import object_surfaces

    built = build_scene(load_scene("FB"), meshcat=meshcat)
    x, z, minus_y = unpack(meshcat._GetPackedProperty("/Cameras/default/rotated/<object>",
                                                      "position"))["value"]  # three.js: y up
    camera = np.array([x, -minus_y, z])
    context = built.plant.CreateDefaultContext()
    surfaces = object_surfaces(built, context)
    fixed = [s for name in built.welded_bodies for s in surfaces.get(name, [])]
    assert fixed, "FB has walls"
    # The straight line from the camera to each object's centre crosses no wall.
    for name, body in built.free_bodies.items():
        centre = body.EvalPoseInWorld(context).translation()
        line = camera + np.linspace(0.0, 1.0, 400)[:, None] * (centre - camera)
        clearance = min(float(np.min(surface(line))) for surface in fixed)
        assert clearance > 0.0, f"a wall hides {name}"
        assert np.linalg.norm(centre - camera) < 2.0, f"{name} is too far to see"
    camera_object = unpack(meshcat._GetPackedObject("/Cameras/default/rotated"))["object"]
    assert camera_object["object"]["fov"] < 75.0  # narrower than Meshcat's default view


def test_outline_edges():
    start, end = shape_outline(BOX)
    assert start.shape == end.shape == (3, 12)
    # Every box edge is as long as one of the box's extents.
    lengths = np.sort(np.linalg.norm(end - start, axis=0))
    np.testing.assert_allclose(lengths, np.repeat([0.06, 0.16, 0.21], 4))
    start, end = shape_outline(CylinderSdf(0.05, 0.1, (0.0, 0.0, 0.1)), sides=8)
    assert start.shape == (3, 2 * 8 + 4)
    np.testing.assert_allclose(np.hypot(start[0], start[1]), 0.05)
    assert start[2].min() == pytest.approx(0.0) and end[2].max() == pytest.approx(0.2)


class ScriptedTracking(LeafSystem):
    """Stand-in for the tracker and estimator: a point more per 0.5 s, an estimate from 1 s."""

    def __init__(self, centre: np.ndarray):
        super().__init__()
        self._centre = np.asarray(centre, dtype=float)
        self.DeclareAbstractOutputPort(
            "map_points", lambda: AbstractValue.Make(np.zeros((0, 3))), self._points
        )
        self.DeclareAbstractOutputPort(
            "segment_labels", lambda: AbstractValue.Make(np.zeros(0, dtype=np.int64)),
            self._labels,
        )
        self.DeclareAbstractOutputPort(
            "action_contacts", lambda: AbstractValue.Make(ActionContacts()), self._contacts
        )
        self.DeclareAbstractOutputPort(
            "target_pose", lambda: AbstractValue.Make(RigidTransform()), self._pose
        )

    def all_points(self) -> np.ndarray:
        """A ring of points just above the box (m, world)."""
        angles = np.linspace(0.0, 2 * np.pi, 12, endpoint=False)
        ring = np.column_stack([0.09 * np.cos(angles), 0.11 * np.sin(angles), np.zeros(12)])
        return self._centre + ring + [0.0, 0.0, 0.12]

    def count(self, context) -> int:
        return min(12, 1 + int(context.get_time() / 0.25))

    def _points(self, context, output):
        output.set_value(self.all_points()[: self.count(context)])

    def _labels(self, context, output):
        output.set_value(np.arange(self.count(context), dtype=np.int64) % 3)

    def _contacts(self, context, output):
        n = self.count(context)
        points = self.all_points()[max(0, n - 2):n]
        output.set_value(ActionContacts(n, points, np.zeros_like(points)))

    def _pose(self, context, output):
        if context.get_time() < 1.0:
            output.set_value(RigidTransform())
        else:
            output.set_value(RigidTransform(self._centre))


def add_visualized_tracking(builder, meshcat, centre) -> ContactTrackingVisualizer:
    source = builder.AddSystem(ScriptedTracking(centre))
    visualizer = builder.AddSystem(ContactTrackingVisualizer(meshcat, BOX, publish_period=0.05))
    for name in ("map_points", "segment_labels", "action_contacts", "target_pose"):
        builder.Connect(source.GetOutputPort(name), visualizer.GetInputPort(name))
    return visualizer


def recorded_animation(html: str) -> dict:
    """path -> {track name: [(frame, value), ...]} of the set_animation message in ``html``."""
    for blob in re.findall(r"base64,([A-Za-z0-9+/=]+)", html):
        try:
            message = msgpack.unpackb(base64.b64decode(blob), strict_map_key=False)
        except (ValueError, msgpack.UnpackException):
            continue  # other embedded data (textures, meshes)
        if isinstance(message, dict) and message.get("type") == "set_animation":
            return {
                animation["path"]: {
                    track["name"]: [(key["time"], key["value"]) for key in track["keys"]]
                    for track in animation["clip"]["tracks"]
                }
                for animation in message["animations"]
            }
    raise AssertionError("the HTML holds no animation")


def test_recording_keeps_the_markers(meshcat):
    builder = DiagramBuilder()
    add_visualized_tracking(builder, meshcat, X_WO.translation())
    simulator = Simulator(builder.Build())
    meshcat.StartRecording(frames_per_second=64.0, set_visualizations_while_recording=False)
    simulator.AdvanceTo(2.0)
    meshcat.StopRecording()
    meshcat.PublishRecording()
    tracks = recorded_animation(meshcat.StaticHtml())

    points = ScriptedTracking(X_WO.translation()).all_points()
    # Point 3 (label 0, second of its colour) appears at 0.75 s: hidden before, then in place.
    sphere = tracks["/stucco/map/0/1"]
    assert sphere[".visible"][0] == (0, False)
    assert next(frame for frame, value in sphere[".visible"] if value) == round(0.75 * 64)
    np.testing.assert_allclose(sphere[".position"][-1][1], points[3])
    # The outline appears with the first estimate, at 1 s.
    target = tracks["/stucco/target"][".visible"]
    assert target[0] == (0, False)
    assert next(frame for frame, value in target if value) == 64


def chromium_command() -> list[str]:
    """Chromium's headless screenshot command, or a failure saying how to install it."""
    for name in ("chromium", "chromium-browser"):
        path = shutil.which(name)
        if path:
            break
    else:
        pytest.fail("Chromium is needed to render the Meshcat recording: on Debian, as root, "
                    "`apt-get update && apt-get install -y chromium` (`make test` does it).")
    command = [path, "--headless", "--hide-scrollbars", "--mute-audio",
               # Software WebGL: CI machines have no GPU.
               "--use-angle=swiftshader", "--enable-unsafe-swiftshader"]
    if os.geteuid() == 0:
        command.append("--no-sandbox")  # Chromium's sandbox refuses to run as root
    return command


def test_recording_renders_in_chromium(meshcat, tmp_path):
    scene = load_scene("FB")
    builder = DiagramBuilder()
    built = build_scene(scene, meshcat=meshcat)
    builder.AddSystem(built.diagram)
    target = built.free_bodies[scene.target]
    centre = target.EvalPoseInWorld(built.plant.CreateDefaultContext()).translation()
    add_visualized_tracking(builder, meshcat, centre)
    simulator = Simulator(builder.Build())
    # No camera set here: the view the scene opens with (over the robot's shoulder) must show
    # the markers at their default size.
    meshcat.StartRecording(set_visualizations_while_recording=False)
    simulator.AdvanceTo(2 * scene.action_duration)  # two actions
    meshcat.StopRecording()
    meshcat.PublishRecording()
    html = tmp_path / "recording.html"
    html.write_text(meshcat.StaticHtml())

    shot = tmp_path / "shot.png"
    # Virtual time lets the page load and play the 2 s animation to its (clamped) end.
    command = [
        *chromium_command(), f"--user-data-dir={tmp_path / 'profile'}", "--window-size=640,480",
        "--virtual-time-budget=6000", f"--screenshot={shot}", html.as_uri(),
    ]
    run = subprocess.run(command, capture_output=True, text=True, timeout=90, check=False)
    assert shot.exists(), f"no screenshot; Chromium said:\n{run.stderr[-2000:]}"

    rgb = np.asarray(Image.open(shot).convert("RGB"), dtype=int)
    r, g, b = rgb[..., 0], rgb[..., 1], rgb[..., 2]
    # Meshcat's background is a grey gradient: a blank (or failed WebGL) page has almost no
    # saturated pixels. The scene's robot and objects are coloured.
    saturation = rgb.max(axis=2) - rgb.min(axis=2)
    colourful = np.count_nonzero(saturation > 60) / saturation.size
    distinct = len(np.unique(rgb.reshape(-1, 3) // 16, axis=0))
    # The outline is unlit magenta, a colour nothing else in the scene has; it is hidden until
    # 1 s, so it shows only if the recorded animation played.
    magenta = np.count_nonzero((r > 180) & (b > 180) & (g < 90))
    # Bluish-green spheres (palette colour 2, every third point; far more blue than red): the
    # scene itself has nearly none of that hue (1 pixel without the visualizer, about 100 with
    # it, in the scene's opening view).
    green = np.count_nonzero((g > r + 50) & (g > b + 20) & (b > r + 40))
    assert rgb.std() > 20, "the screenshot is flat"
    assert colourful > 0.03, f"only {colourful:.1%} saturated pixels"
    assert distinct > 40, f"only {distinct} distinct colours"
    assert magenta > 50, f"only {magenta} magenta (target outline) pixels"
    assert green > 50, f"only {green} bluish-green (segment 2 point) pixels"
