"""ContactTrackingVisualizer: draws the tracker's MAP points, the latest contacts and the
estimated target outline in Meshcat, live and in Meshcat recordings.

Why pools of spheres rather than a point cloud: a Meshcat animation records only transforms and
properties (``SetTransform``/``SetProperty`` with ``time_in_recording``); ``SetObject`` is sent
once and never animated. So every marker is a sphere object created once (lazily, the first
time it is needed) and then moved and shown or hidden; a recording replays those changes.
Colours are fixed per sphere, one pool per palette colour: a point that changes segment moves to
a sphere of its new colour, because only transform and visibility key frames are sure to replay.
"""

from __future__ import annotations

import dataclasses
import itertools

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.geometry import Box, Cylinder, Rgba, Sphere
from pydrake.math import RigidTransform
from pydrake.systems.framework import LeafSystem

from stucco_drake.core.observation import ActionContacts
from stucco_drake.core.shapes import BoxSdf, CylinderSdf

#: Segment colours (Okabe-Ito, without black: distinguishable with colour-vision deficiency).
SEGMENT_PALETTE = (
    Rgba(0.90, 0.62, 0.00),  # orange
    Rgba(0.34, 0.71, 0.91),  # sky blue
    Rgba(0.00, 0.62, 0.45),  # bluish green
    Rgba(0.94, 0.89, 0.26),  # yellow
    Rgba(0.00, 0.45, 0.70),  # blue
    Rgba(0.84, 0.37, 0.00),  # vermillion
    Rgba(0.80, 0.47, 0.65),  # reddish purple
)
#: Points with a negative label (unsegmented or noise).
UNLABELLED_COLOR = Rgba(0.55, 0.55, 0.55)
#: The latest contacts: a dark, translucent shell, so the segment colour of a point drawn at the
#: same place still shows through it.
CONTACT_COLOR = Rgba(0.05, 0.05, 0.05, 0.35)
OUTLINE_COLOR = Rgba(1.0, 0.0, 1.0)
#: The estimated target's body inside its outline: translucent, so what it covers shows; a
#: line is a pixel wide in a browser, and the body keeps the estimate visible from afar.
ESTIMATE_BODY_COLOR = Rgba(1.0, 0.0, 1.0, 0.3)


def segment_color_index(label: int) -> int:
    """Index into :data:`SEGMENT_PALETTE` of a segment label; -1 for negative labels."""
    return -1 if label < 0 else int(label) % len(SEGMENT_PALETTE)


def shape_outline(shape: BoxSdf | CylinderSdf, sides: int = 24) -> tuple[np.ndarray, np.ndarray]:
    """Wireframe edges of ``shape`` in its own frame: (start, end), each (3, k) in m."""
    center = np.asarray(shape.center, dtype=float)
    if isinstance(shape, BoxSdf):
        half = np.asarray(shape.half_extents, dtype=float)
        corners = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)])
        # Corners differing in exactly one coordinate share an edge (12 edges).
        pairs = [(i, j) for i in range(8) for j in range(i + 1, 8)
                 if np.count_nonzero(corners[i] != corners[j]) == 1]
        start = np.array([corners[i] for i, _ in pairs]) * half + center
        end = np.array([corners[j] for _, j in pairs]) * half + center
        return start.T, end.T
    if isinstance(shape, CylinderSdf):
        angles = np.linspace(0.0, 2 * np.pi, sides + 1)
        ring = np.stack([np.cos(angles), np.sin(angles)], axis=1) * shape.radius
        segments = []
        for z in (-shape.half_height, shape.half_height):
            points = np.column_stack([ring, np.full(len(ring), z)])
            segments += list(itertools.pairwise(points))
        # Four vertical edges so the cylinder's height reads in any view.
        for k in range(0, sides, sides // 4):
            x, y = ring[k]
            segments.append(([x, y, -shape.half_height], [x, y, shape.half_height]))
        start = np.array([s for s, _ in segments]) + center
        end = np.array([e for _, e in segments]) + center
        return start.T, end.T
    raise ValueError(f"target_shape: {type(shape).__name__} is neither BoxSdf nor CylinderSdf")


def shape_geometry(shape: BoxSdf | CylinderSdf) -> tuple[Box | Cylinder, RigidTransform]:
    """The Drake geometry of ``shape`` and its pose in the shape's frame (m)."""
    if isinstance(shape, BoxSdf):
        geometry = Box(*(2.0 * np.asarray(shape.half_extents, dtype=float)))
    elif isinstance(shape, CylinderSdf):
        geometry = Cylinder(shape.radius, 2.0 * shape.half_height)
    else:
        raise ValueError(f"target_shape: {type(shape).__name__} is neither BoxSdf nor CylinderSdf")
    return geometry, RigidTransform(np.asarray(shape.center, dtype=float))


@dataclasses.dataclass
class _Marker:
    """What was last sent for one sphere: shown or not, at which point (m), at what time (s)."""

    path: str
    visible: bool = False
    position: np.ndarray | None = None
    time: float = 0.0


class _SpherePool:
    """Spheres of one colour under ``path``, created on demand and reused across publishes."""

    def __init__(self, meshcat, path: str, radius: float, color: Rgba):
        self._meshcat, self._path, self._radius, self._color = meshcat, path, radius, color
        self.markers: list[_Marker] = []

    def reset(self):
        self.markers = []

    def show(self, points: np.ndarray, time: float, previous_time: float) -> None:
        """Shows one sphere at each row of ``points`` (m, world) and hides the rest."""
        while len(self.markers) < len(points):
            marker = _Marker(f"{self._path}/{len(self.markers)}")
            self._meshcat.SetObject(marker.path, Sphere(self._radius), self._color)
            # Hidden from the recording's start: before its first key frame an animated object
            # would otherwise hold its first recorded (visible) state.
            self._meshcat.SetProperty(marker.path, "visible", False, 0.0)
            self._meshcat.SetProperty(marker.path, "visible", False, time)
            marker.time = time
            self.markers.append(marker)
        for k, marker in enumerate(self.markers):
            position = points[k] if k < len(points) else None
            self._update(marker, position, time, previous_time)

    def _update(self, marker: _Marker, position, time: float, previous_time: float) -> None:
        visible = position is not None
        moved = visible and (marker.position is None
                             or not np.array_equal(marker.position, position))
        if visible == marker.visible and not moved:
            return
        # Key frames interpolate linearly: pin the old state at the previous publish so a
        # reused sphere jumps within one publish period instead of sliding from its last change.
        if marker.time < previous_time:
            self._send(marker, marker.visible, marker.position, previous_time)
        self._send(marker, visible, position if visible else marker.position, time)

    def _send(self, marker: _Marker, visible: bool, position, time: float) -> None:
        if position is not None:
            # A copy: the row may be a view into an input value its owner later reuses.
            position = np.array(position, dtype=float)
            self._meshcat.SetTransform(marker.path, RigidTransform(position), time)
        self._meshcat.SetProperty(marker.path, "visible", visible, time)
        marker.visible, marker.position, marker.time = visible, position, time


class ContactTrackingVisualizer(LeafSystem):
    """Draws contact tracking in Meshcat under ``prefix`` (default ``/stucco``).

    Paths: ``{prefix}/map/{c}/{k}`` MAP points as spheres coloured by segment (``c`` the
    palette index, or ``unlabelled``); ``{prefix}/contacts/{k}`` the latest action's contact
    points, larger, dark and translucent; ``{prefix}/target`` the estimated target frame with
    the shape's wireframe at ``{prefix}/target/outline`` and its translucent body at
    ``{prefix}/target/body``. All positions are in the world frame (m).

    Input ports (each optional: an unconnected port is not drawn):
        map_points: (n, 3) numpy array of MAP contact points (m, world).
        segment_labels: (n,) numpy int array, a segment label per point (negative: none).
        action_contacts: :class:`ActionContacts` of the latest completed action.
        target_pose: RigidTransform X_WO of the estimated target (m, world); the identity
            means "no estimate yet" (the TargetPoseEstimator's convention) and hides the outline.

    Drawing happens in a periodic publish event (every ``publish_period`` s) and on forced
    publish, with ``time_in_recording`` = the context time, so a Meshcat recording
    (``Meshcat.StartRecording``) replays it. An initialization event clears ``prefix``.

    The sphere bookkeeping lives in this object (Meshcat is external state, as for Drake's
    MeshcatVisualizer): use one instance per simulated context.

    Args:
        meshcat: the Meshcat instance to draw to.
        target_shape: the target's geometry in its own frame (BoxSdf or CylinderSdf).
        publish_period: seconds between draws (> 0).
        point_radius: radius of the MAP point spheres (m).
        contact_radius: radius of the latest-contact spheres (m).
        prefix: the Meshcat path everything is drawn under.
    """

    def __init__(self, meshcat, target_shape: BoxSdf | CylinderSdf, publish_period: float, *,
                 point_radius: float = 0.01, contact_radius: float = 0.014,
                 prefix: str = "/stucco"):
        super().__init__()
        if not publish_period > 0:
            raise ValueError(f"publish_period: must be > 0 s, got {publish_period!r}")
        self._meshcat = meshcat
        self._prefix = prefix.rstrip("/")
        self._outline = shape_outline(target_shape)
        self._body = shape_geometry(target_shape)
        self._points = self.DeclareAbstractInputPort(
            "map_points", AbstractValue.Make(np.zeros((0, 3)))
        )
        self._labels = self.DeclareAbstractInputPort(
            "segment_labels", AbstractValue.Make(np.zeros(0, dtype=np.int64))
        )
        self._contacts = self.DeclareAbstractInputPort(
            "action_contacts", AbstractValue.Make(ActionContacts())
        )
        self._pose = self.DeclareAbstractInputPort(
            "target_pose", AbstractValue.Make(RigidTransform())
        )
        colors = [*SEGMENT_PALETTE, UNLABELLED_COLOR]
        names = [str(c) for c in range(len(SEGMENT_PALETTE))] + ["unlabelled"]
        self._map_pools = [
            _SpherePool(meshcat, f"{self._prefix}/map/{name}", point_radius, color)
            for name, color in zip(names, colors, strict=True)
        ]
        self._contact_pool = _SpherePool(
            meshcat, f"{self._prefix}/contacts", contact_radius, CONTACT_COLOR
        )
        self._previous_time = 0.0
        self._target_shown: bool | None = None
        self.DeclareInitializationPublishEvent(self._on_initialize)
        self.DeclarePeriodicPublishEvent(publish_period, 0.0, self._draw)
        self.DeclareForcedPublishEvent(self._draw)

    @property
    def prefix(self) -> str:
        """The Meshcat path everything is drawn under (no trailing slash)."""
        return self._prefix

    def _on_initialize(self, context):
        # A fresh simulation starts from a clean slate (objects of an earlier run would linger).
        self._meshcat.Delete(self._prefix)
        for pool in [*self._map_pools, self._contact_pool]:
            pool.reset()
        self._target_shown = None
        self._previous_time = context.get_time()
        return self._draw(context)

    def _draw(self, context):
        time = context.get_time()
        self._draw_map(context, time)
        if self._contacts.HasValue(context):
            points = self._contacts.Eval(context).points
            self._contact_pool.show(points, time, self._previous_time)
        if self._pose.HasValue(context):
            self._draw_target(self._pose.Eval(context), time)
        self._previous_time = time
        return None

    def _draw_map(self, context, time: float) -> None:
        if not self._points.HasValue(context):
            return
        points = np.asarray(self._points.Eval(context), dtype=float).reshape(-1, 3)
        if self._labels.HasValue(context):
            labels = np.asarray(self._labels.Eval(context), dtype=np.int64).reshape(-1)
        else:
            labels = np.full(len(points), -1)
        if len(labels) != len(points):
            raise ValueError(
                f"segment_labels: {len(labels)} labels for {len(points)} map points"
            )
        colors = np.array([segment_color_index(label) for label in labels], dtype=int)
        for c, pool in enumerate(self._map_pools):
            index = -1 if c == len(SEGMENT_PALETTE) else c
            pool.show(points[colors == index], time, self._previous_time)

    def _draw_target(self, X_WO: RigidTransform, time: float) -> None:
        target = f"{self._prefix}/target"
        if self._target_shown is None:
            start, end = self._outline
            self._meshcat.SetLineSegments(f"{target}/outline", start, end, 2.0, OUTLINE_COLOR)
            geometry, X_OG = self._body
            self._meshcat.SetObject(f"{target}/body", geometry, ESTIMATE_BODY_COLOR)
            self._meshcat.SetTransform(f"{target}/body", X_OG)
            # Hidden from the recording's start until an estimate exists (see the pools).
            self._meshcat.SetProperty(target, "visible", False, 0.0)
            self._target_shown = False
        shown = not X_WO.IsExactlyIdentity()
        if shown:
            self._meshcat.SetTransform(target, X_WO, time)
        if shown != self._target_shown:
            self._meshcat.SetProperty(target, "visible", shown, time)
            self._target_shown = shown
