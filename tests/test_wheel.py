"""The built wheel installs into a fresh virtualenv and runs an episode from any folder.

The wheel is built from this checkout (no build isolation: no download) and installed, without
dependencies, into a new virtualenv that sees this environment's packages (drake, numpy, ...)
through a ``.pth`` line but not the checkout: the episode then finds its models and scene files
inside the installed package. Truth: the checkout's own file tree (what must ship) and the same
command run from the checkout (what it must print).
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
import sysconfig
import venv
import zipfile
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
COMMAND = ["run", "--scene", "FB", "--actions", "4", "--no-grasp"]


def _result_line(stdout: str) -> str:
    """The run's result line without its wall time (the only part that may differ)."""
    lines = [line for line in stdout.splitlines() if line.startswith("FB stucco seed 0:")]
    assert len(lines) == 1, stdout
    return re.sub(r", wall [0-9.]+ s", "", lines[0])


@pytest.fixture(scope="module")
def wheel(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("wheel")
    # Built from a copy of the checkout: setuptools' build folder stays out of it, and no stale
    # build output of an earlier layout can slip into the wheel.
    source = out / "source"
    shutil.copytree(REPO, source, ignore=shutil.ignore_patterns(
        ".git", ".venv", "build", "out", "*.egg-info", "__pycache__", ".cache"))  # fmt: skip
    subprocess.run(
        [sys.executable, "-m", "pip", "wheel", "--quiet", "--no-deps", "--no-build-isolation",
         "--wheel-dir", str(out), str(source)],
        check=True, capture_output=True, text=True,
    )  # fmt: skip
    (path,) = out.glob("stucco_drake-*.whl")
    return path


def test_wheel_ships_every_package_model_and_scene(wheel):
    names = set(zipfile.ZipFile(wheel).namelist())
    for init in (REPO / "stucco_drake").rglob("__init__.py"):
        assert init.relative_to(REPO).as_posix() in names
    for model in (REPO / "models").rglob("*"):
        if model.is_file():
            assert f"stucco_drake/_models/{model.relative_to(REPO / 'models').as_posix()}" in names
    for scene in (REPO / "diagrams").glob("*.yaml"):
        assert f"stucco_drake/_diagrams/{scene.name}" in names


def test_installed_wheel_runs_an_episode_from_another_folder(wheel, tmp_path):
    # Nothing of the checkout on the path, for pip and the runs alike.
    env = {**os.environ, "STUCCO_DRAKE_CACHE": str(tmp_path / "cache")}
    env.pop("PYTHONPATH", None)
    env_dir = tmp_path / "venv"
    venv.create(env_dir, with_pip=True)
    python = env_dir / "bin" / "python"
    purelib = subprocess.run(
        [str(python), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
        check=True, capture_output=True, text=True,
    ).stdout.strip()  # fmt: skip
    # This environment's third-party packages, reused (no download); the checkout is not on it.
    Path(purelib, "_reused_packages.pth").write_text(sysconfig.get_paths()["purelib"] + "\n")
    subprocess.run(
        [str(python), "-m", "pip", "install", "--quiet", "--no-deps", "--no-index", str(wheel)],
        env=env, check=True, capture_output=True, text=True,
    )  # fmt: skip
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    located = subprocess.run(
        [str(python), "-c", "import stucco_drake.robot.models as m; print(m.MODELS_DIR)"],
        cwd=elsewhere, env=env, capture_output=True, text=True,
    )  # fmt: skip
    assert located.returncode == 0, located.stderr[-2000:]
    assert Path(located.stdout.strip()).is_relative_to(env_dir), located.stdout
    installed = subprocess.run(
        [str(env_dir / "bin" / "stucco-drake"), *COMMAND],
        cwd=elsewhere, env=env, capture_output=True, text=True,
    )  # fmt: skip
    assert installed.returncode == 0, installed.stderr[-2000:]
    in_tree = subprocess.run(
        [str(Path(sys.executable).parent / "stucco-drake"), *COMMAND],
        cwd=REPO, env=env, check=True, capture_output=True, text=True,
    )  # fmt: skip
    assert _result_line(installed.stdout) == _result_line(in_tree.stdout)
    assert " 0 contacts" not in _result_line(installed.stdout)  # the pushes touched something
