"""Atomic ``.npz`` writes: a crash mid-write never leaves a truncated cache or result file."""

from __future__ import annotations

from pathlib import Path

import numpy as np


def save_npz_atomically(path: str | Path, *, compressed: bool = False, **arrays) -> None:
    """Write ``arrays`` to ``path`` through a temporary file renamed into place."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".tmp.npz")
    (np.savez_compressed if compressed else np.savez)(tmp, **arrays)
    tmp.replace(path)
