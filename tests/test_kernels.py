"""Seeded runs are bit-identical across processes and do not depend on the CPU kernels that
numpy and OpenBLAS would pick on another machine (stucco_drake.runtime.kernels pins them)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest

from stucco_drake.eval.episode_log import EpisodeLog
from stucco_drake.runtime import kernels

# What a machine with older vector units would choose by itself: OpenBLAS's kernels without
# fused multiply-add, numpy's loops without AVX2, and two BLAS threads.
OTHER_CPU = {
    "OPENBLAS_CORETYPE": "Sandybridge",
    "NPY_DISABLE_CPU_FEATURES": "X86_V3",
    "OPENBLAS_NUM_THREADS": "2",
}

_EPISODE = textwrap.dedent("""
    import json, sys
    from stucco_drake.runtime import kernels
    from stucco_drake.bor.log import log_penetration, record_episode
    from stucco_drake.eval.replay import replay

    log = record_episode("FB", 5, n_actions=3)
    log.save(sys.argv[1])
    row = replay(log, "stucco", penetration=log_penetration(log), dx_model="cone")
    print(json.dumps({"kernels": kernels.status(), "ce_cm": float(row["ce_cm"]),
                      "fmi": float(row["fmi"])}))
""")

_PRODUCT = textwrap.dedent("""
    import numpy as np
    J = np.random.default_rng(0).standard_normal((6, 7))
    print((J @ J.T).tobytes().hex())
""")


def _python(code: str, *args: str, env: dict | None = None) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-c", code, *args], stdout=subprocess.PIPE,
                            text=True, env={**os.environ, **(env or {})})  # fmt: skip


def _output(process: subprocess.Popen) -> str:
    out, _ = process.communicate(timeout=600)
    assert process.returncode == 0
    return out.strip()


@pytest.mark.skipif(kernels.status() != "pinned", reason=f"kernels {kernels.status()}")
def test_the_other_cpus_kernels_change_the_arithmetic():
    # Without the pin, the emulated machine's BLAS rounds the controller's J J^T differently:
    # the comparison below is between different arithmetic, not a tautology.
    native = {kernels.NATIVE_SWITCH: "1"}
    here = _python(_PRODUCT, env={**native, "OPENBLAS_CORETYPE": "Haswell"})
    other = _python(_PRODUCT, env={**native, **OTHER_CPU})
    assert _output(here) != _output(other)


@pytest.mark.skipif(kernels.status() != "pinned", reason=f"kernels {kernels.status()}")
def test_an_episode_and_its_replay_are_bit_identical_across_processes_and_cpus(tmp_path):
    """FB's first 3 actions (the third touches the target) recorded in two processes
    at once, one as another CPU would run it, then STUCCO replayed on each log."""
    runs = {name: _python(_EPISODE, str(tmp_path / f"{name}.npz"), env=env)
            for name, env in (("here", None), ("other", OTHER_CPU))}  # fmt: skip
    rows = {name: json.loads(_output(process)) for name, process in runs.items()}
    assert rows["here"] == rows["other"]
    assert rows["here"]["kernels"] == "pinned"
    here, other = (EpisodeLog.load(tmp_path / f"{name}.npz") for name in ("here", "other"))
    assert here.n_contacts > 0
    for name in ("ee_position", "ee_rotation", "contact_points", "contact_dx", "contact_object",
                 "object_poses", "robot_object_distance", "final_state"):  # fmt: skip
        np.testing.assert_array_equal(getattr(here, name), getattr(other, name), err_msg=name)
