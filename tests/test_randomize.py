"""Randomized layouts (``stucco-drake scenes randomize``), scene files in the table and run, and
the evaluation's disjoint sets.

Truth for a written layout is Drake itself: the layout's file is loaded by the scene loader,
built, and every movable object's signed distance to everything but the table (the other
objects, the walls, the robot and gripper at their start) is asked of the scene graph here,
apart from the generator's own check; it must be >= 2 mm (Drake's distances are exact for
these boxes, cylinders and ellipsoids, to about 1e-9 m). Each object's displacement from the
base scene, from the two built plants, must lie in the shift range and its turn within the
yaw range (to 1e-9 m and rad), about the vertical only. Units: m, rad.
"""

from __future__ import annotations

import dataclasses
import math
import pickle
import shutil

import numpy as np
import pytest
from pydrake.common.yaml import yaml_dump_typed

from stucco_drake.bor.log import BOR_SOURCES
from stucco_drake.bor.table_sources import record_scene_file, table_scenes
from stucco_drake.eval.cli_table import check_names
from stucco_drake.eval.sets import (
    DEVELOPMENT_SEEDS,
    PAPER_SCENES,
    REPORT_SEEDS,
    TRAINING_SCENES,
    describe_sets,
    scene_set,
)
from stucco_drake.scenes import (
    SceneFileError,
    build_scene,
    load_scene,
    load_scene_text,
    scene_paths,
)
from stucco_drake.scenes.randomize import (
    LayoutClearance,
    LayoutError,
    LayoutParams,
    layout_name,
    randomize_scene,
    write_layouts,
)

SEEDS = list(DEVELOPMENT_SEEDS[:3])
CLEARANCE = 0.002
TOL = 1e-9


def _poses(built) -> dict[str, object]:
    """Every object's body pose (free and welded) in the built scene's default context."""
    context = built.plant.CreateDefaultContext()
    bodies = {**built.free_bodies, **built.welded_bodies}
    return {name: body.EvalPoseInWorld(context) for name, body in bodies.items()}


def _movable_clearance(built) -> tuple[float, str]:
    """Least signed distance from a free body's geometry to any geometry not of the table,
    by Drake's pairwise query on the built scene as loaded."""
    context = built.diagram.CreateDefaultContext()
    query = built.diagram.GetOutputPort("query_object").Eval(context)
    inspector = query.inspector()
    free = {f"{name}::{body.name()}" for name, body in built.free_bodies.items()}
    least = (math.inf, "")
    for pair in query.ComputeSignedDistancePairwiseClosestPoints(0.05):
        names = [inspector.GetName(inspector.GetFrameId(g)) for g in (pair.id_A, pair.id_B)]
        if set(names) & free and not any(n.startswith("table::") for n in names):
            least = min(least, (pair.distance, " / ".join(names)))
    return least


@pytest.fixture(scope="module")
def bases():
    return {name: build_scene(load_scene(name)) for name in ("FB", "TC")}


@pytest.fixture(scope="module")
def written(tmp_path_factory):
    """Three development layouts of FB and of TC, written with the default parameters."""
    out = tmp_path_factory.mktemp("layouts")
    return out, {name: write_layouts(load_scene(name), SEEDS, out) for name in ("FB", "TC")}


def _check_layout(path, base_built, params: LayoutParams):
    layout = load_scene(path)  # the normal loader
    base = base_built.scene
    assert (layout.base, layout.name) == (base.name, layout_name(base.name, layout.layout_seed))
    assert layout.actions == base.actions and layout.target == base.target
    built = build_scene(layout)
    distance, names = _movable_clearance(built)
    assert distance >= params.clearance, f"{path.name}: {names} {distance * 1000:.2f} mm apart"
    before, after = _poses(base_built), _poses(built)
    assert before.keys() == after.keys()
    low, high = params.shift
    for name, X in after.items():
        X0 = before[name]
        shift = X.translation() - X0.translation()
        R = (X.rotation() @ X0.rotation().inverse()).matrix()
        if name not in built.free_bodies:  # walls, pedestal: untouched
            np.testing.assert_allclose(X.GetAsMatrix4(), X0.GetAsMatrix4(), atol=TOL)
            continue
        assert abs(shift[2]) < TOL, name
        assert low - TOL <= np.linalg.norm(shift[:2]) <= high + TOL, (name, shift)
        np.testing.assert_allclose(R[:, 2], [0, 0, 1], atol=TOL)  # a turn about the vertical
        assert abs(math.atan2(R[1, 0], R[0, 0])) <= params.max_yaw + TOL, name


@pytest.mark.parametrize("name", ["FB", "TC"])
def test_written_layouts_keep_clear_and_within_their_ranges(written, bases, name):
    _, layouts = written
    assert [p.name for p, _, _ in layouts[name]] == [f"{name}-L{s}.yaml" for s in SEEDS]
    for path, _, draws in layouts[name]:
        assert 1 <= draws <= LayoutParams().max_draws
        _check_layout(path, bases[name], LayoutParams())


def test_the_clearance_check_sees_a_gap_below_2_mm():
    # The check above is not vacuous: BC as published has its target 1.8 mm from the can.
    distance, names = _movable_clearance(build_scene(load_scene("BC")))
    assert 0 < distance < CLEARANCE and "target" in names and "tomato_can" in names


def test_other_ranges_are_kept(tmp_path, bases):
    params = LayoutParams(shift=(0.03, 0.035), max_yaw=math.radians(2.0), clearance=0.004)
    ((path, _, _),) = write_layouts(load_scene("FB"), [REPORT_SEEDS[0]], tmp_path, params)
    _check_layout(path, bases["FB"], params)


def test_a_seed_gives_the_same_file_and_other_seeds_differ(written, tmp_path):
    out, _ = written
    # Alone and in another order: each layout depends on its own seed only.
    write_layouts(load_scene("FB"), SEEDS[::-1][:2], tmp_path)
    for seed in SEEDS[1:]:
        name = f"FB-L{seed}.yaml"
        assert (tmp_path / name).read_bytes() == (out / name).read_bytes()
    # Past the header and name, the files differ in the objects' poses.
    objects = {(out / f"FB-L{s}.yaml").read_text().split("directives:")[1] for s in SEEDS}
    assert len(objects) == len(SEEDS)


def test_an_existing_different_layout_is_not_overwritten(written, tmp_path):
    out, _ = written
    shutil.copy(out / f"FB-L{SEEDS[0]}.yaml", tmp_path)
    with pytest.raises(LayoutError, match="holds another layout"):
        write_layouts(load_scene("FB"), SEEDS[:1], tmp_path, LayoutParams(shift=(0.0, 0.005)))


def test_rejection_sampling_gives_up_in_one_line(bases):
    params = LayoutParams(clearance=0.05, max_draws=5)
    with pytest.raises(LayoutError, match=r"none of 5 draws") as error:
        randomize_scene(bases["FB"].scene, 1000, params, LayoutClearance(bases["FB"], params))
    assert "\n" not in str(error.value)
    with pytest.raises(LayoutError, match="shift"):
        LayoutParams(shift=(0.02, 0.01)).check()


def test_a_layout_is_not_randomized_again(written):
    out, _ = written
    with pytest.raises(LayoutError, match="is a layout of FB"):
        randomize_scene(load_scene(out / f"FB-L{SEEDS[0]}.yaml"), 1)


# ---------------------------------------------------------------- scene files in table and run
def test_table_scenes_take_names_files_and_folders(written, tmp_path):
    out, _ = written
    single = out / f"TC-L{SEEDS[0]}.yaml"
    names, sources = table_scenes(["FB", str(out), str(single), "NOPE"], BOR_SOURCES)
    layouts = [f"{b}-L{s}" for b in ("FB", "TC") for s in SEEDS]
    assert names == ["FB", *layouts, "NOPE"]  # folder sorted by name; a file once
    assert [p.stem for p in scene_paths(out)] == layouts
    assert sources["FB"] is BOR_SOURCES["FB"] and "NOPE" not in sources
    for name in layouts:
        source = sources[name]
        path = str((out / f"{name}.yaml").resolve())
        assert source.produce.args == (path,) and source.grasp.keywords == {"scene": path}
        assert source.scene_set == "development"
        pickle.dumps(source)  # sent to worker processes
    with pytest.raises(ValueError, match=r"unknown scene.*NOPE"):
        check_names(names, ["stucco"], sources)
    with pytest.raises(ValueError, match=r"holds scene 'TC-L1000', not 'FB-L1000'"):
        record_scene_file(str(single), "FB-L1000", 0)  # refused before simulating
    # One name from two files, or a file named like a shipped scene, is refused.
    shutil.copy(single, tmp_path)
    with pytest.raises(ValueError, match="rename one"):
        table_scenes([str(out), str(tmp_path)], BOR_SOURCES)
    renamed = load_scene(single)
    (tmp_path / "TC-L1000.yaml").write_text(
        single.read_text().replace(f"name: {renamed.name}", "name: FB"))
    with pytest.raises(ValueError, match="'FB' is also"):
        table_scenes(["FB", str(tmp_path)], BOR_SOURCES)


def test_run_takes_a_folder(written, capsys):
    from stucco_drake.cli import main

    out, _ = written
    # Parsed and loaded; refused before simulating since a recording takes one scene.
    assert main(["run", "--scene", str(out), "--record", "x.html"]) == 2
    assert "not a folder of 6" in capsys.readouterr().err


# --------------------------------------------------------------------------------- the sets
def test_the_sets_are_disjoint_and_named():
    assert not set(DEVELOPMENT_SEEDS) & set(REPORT_SEEDS)
    assert not set(TRAINING_SCENES) & set(PAPER_SCENES)
    assert scene_set("FB") == "paper" and scene_set("SELECT2") == "training"
    assert scene_set("FB-L1000", "FB", DEVELOPMENT_SEEDS[0]) == "development"
    assert scene_set("TC-L9999", "TC", REPORT_SEEDS[-1]) == "report"
    assert scene_set("x", "FB", REPORT_SEEDS[-1] + 1) == "other"
    assert scene_set("SELECT1-L5", "SELECT1", 5) == "training"
    assert scene_set("SYN2") == "other"
    assert describe_sets({"FB": "paper", "FB-L1000": "development", "SYN2": "other"}) == (
        "development set: FB-L1000\npaper set: FB\nin no set: SYN2")
    from stucco_drake import training

    assert training.TRAINING_SCENES is TRAINING_SCENES  # one definition
    assert {s.scene_set for s in BOR_SOURCES.values()} == {"paper"}


def test_a_layout_names_its_base_and_seed_together():
    scene = load_scene("FB")
    assert (scene.base, scene.layout_seed) == ("", None)
    text = yaml_dump_typed(dataclasses.replace(scene, base="FB"))
    with pytest.raises(SceneFileError, match="layout_seed"):
        load_scene_text(text)
