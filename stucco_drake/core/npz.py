"""Atomic ``.npz`` writes: a crash mid-write never leaves a truncated cache or result file, and
processes writing the same file at once (parallel runs filling a shared cache) never collide."""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

import numpy as np


def save_npz_atomically(path: str | Path, *, compressed: bool = False, **arrays) -> None:
    """Write ``arrays`` to ``path`` through a temporary file of its own (a unique name in the
    same folder) renamed into place: the last writer wins, readers see a whole file."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=path.name + ".", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as file:
            (np.savez_compressed if compressed else np.savez)(file, **arrays)
        os.chmod(tmp, 0o644)  # mkstemp's 0600 would hide the cache from other users
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
