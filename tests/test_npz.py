"""Atomic .npz writes from processes racing on one file (parallel runs filling a shared cache:
the table once lost a run to two workers renaming the same temporary file)."""

from __future__ import annotations

import multiprocessing

import numpy as np
import pytest

from stucco_drake.core.npz import save_npz_atomically


def _write_many(path: str, value: float, times: int) -> None:
    for _ in range(times):
        save_npz_atomically(path, data=np.full(20_000, value))


def test_processes_writing_one_file_at_once_neither_fail_nor_leave_temporaries(tmp_path):
    path = tmp_path / "cache" / "shared.npz"
    context = multiprocessing.get_context("spawn")
    writers = [context.Process(target=_write_many, args=(str(path), v, 40)) for v in (1.0, 2.0)]
    for writer in writers:
        writer.start()
    for writer in writers:
        writer.join(timeout=120)
    # Each writer exits 0 (a collision raised FileNotFoundError in one of them).
    assert [w.exitcode for w in writers] == [0, 0]
    data = np.load(path)["data"]
    # The file is one writer's whole array (last writer wins), never a mixture.
    assert data.shape == (20_000,) and np.unique(data).size == 1 and data[0] in (1.0, 2.0)
    assert sorted(p.name for p in path.parent.iterdir()) == ["shared.npz"]


def test_a_failed_write_leaves_the_old_file_and_no_temporary(tmp_path):
    path = tmp_path / "old.npz"
    save_npz_atomically(path, data=np.arange(3.0))

    class Unsaveable:
        def __array__(self, *args, **kwargs):
            raise RuntimeError("cannot be saved")

    with pytest.raises(RuntimeError, match="cannot be saved"):
        save_npz_atomically(path, data=Unsaveable())
    np.testing.assert_array_equal(np.load(path)["data"], np.arange(3.0))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["old.npz"]
