"""Meshcat for the command line: a live viewer and/or a standalone HTML recording."""

from __future__ import annotations

from pathlib import Path


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
