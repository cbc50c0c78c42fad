"""Every bad input to the command line is one ``stucco-drake <command>: error: ...`` line on
stderr and exit status 2, before any simulation starts.

The commands' work (building a scene, running an episode, drawing the Diagram, a table, a
sweep, starting Meshcat) is replaced by a tripwire: a check made too late trips it and fails
the test with a traceback instead of the expected line. A control test shows that good
arguments do reach the tripwire.
"""

import functools
import os
import subprocess
import sys

import pytest
import yaml

from stucco_drake.cli import main
from stucco_drake.core.inputs import InputError, prepare_output_file, prepare_output_folder
from stucco_drake.scenes import DIAGRAMS_DIR


class WorkStarted(AssertionError):
    """A command got past its input checks."""


@pytest.fixture
def tripwire(monkeypatch):
    """Replaces everything a command does after its checks with a WorkStarted raise."""
    import stucco_drake.bor.cli
    import stucco_drake.bor.episode
    import stucco_drake.cli.sweep
    import stucco_drake.eval.cli_table
    import stucco_drake.scenes
    import stucco_drake.scenes.meshcat_session

    def work(*args, **kwargs):
        raise WorkStarted("the command started its work")

    for module, name in [
        (stucco_drake.scenes, "build_scene"),  # sim
        (stucco_drake.scenes.meshcat_session, "start_meshcat"),  # sim, run
        (stucco_drake.bor.episode, "run_episode"),  # run
        (stucco_drake.bor.cli, "bor_graphviz"),  # diagram
        (stucco_drake.eval.cli_table, "make_table"),  # table
        (stucco_drake.cli.sweep, "run_sweep"),  # sweep
    ]:
        monkeypatch.setattr(module, name, work)


def run_cli(argv: list[str], capsys) -> tuple[int, str]:
    """Exit status and stderr of ``stucco-drake argv`` (argparse's own errors exit)."""
    try:
        code = main(argv)
    except SystemExit as exit_:
        code = exit_.code
    return code, capsys.readouterr().err


def assert_one_line_error(argv: list[str], capsys, *fragments: str) -> str:
    code, err = run_cli(argv, capsys)
    assert code == 2, err
    assert err.count("\n") == 1 and err.endswith("\n"), err
    assert err.startswith(f"stucco-drake {argv[0]}: error: "), err
    for fragment in fragments:
        assert fragment in err, err
    return err


@pytest.fixture
def paths(tmp_path):
    """A regular file, a folder, and a scene file naming a model file that does not exist."""
    (tmp_path / "a_file").write_text("not a folder\n")
    (tmp_path / "a_folder").mkdir()
    fb = (DIAGRAMS_DIR / "FB.yaml").read_text()
    model = "package://stucco_drake_models/ycb/003_cracker_box_10kg.sdf"
    assert model in fb
    (tmp_path / "no_model.yaml").write_text(fb.replace(model, model.replace("003", "999")))
    (tmp_path / "no_package.yaml").write_text(fb.replace("stucco_drake_models", "no_such_pkg"))
    (tmp_path / "typo.yaml").write_text("lenght: 0.02\n")
    (tmp_path / "broken.yaml").write_text("length: [0.02\n")
    (tmp_path / "bad.yaml").write_text("probe:\n  max_bumps: 1.5\n")
    (tmp_path / "hypotheses.yaml").write_text("confidence_temperature: 3.0\n")
    (tmp_path / "bad_hypotheses.yaml").write_text("min_explained: 2.5\n")
    (tmp_path / "old_sweep").mkdir()
    (tmp_path / "old_sweep" / "sweep.csv").write_text("scene,seed,method,fmi\n")
    return tmp_path


# Each case: argv (with {tmp} for the fixture's folder) and fragments the error line holds.
BAD_INPUTS = {
    # Counts and seeds, checked by argparse.
    "seed < 0": ("run --scene FB --method stucco --seed -1",
                 "argument --seed: must be 0 or more, got -1"),
    "demo seed < 0": ("demo --seed -2", "argument --seed: must be 0 or more, got -2"),
    "run actions 0": ("run --scene FB --actions 0", "argument --actions: must be 1 or more, got 0"),
    "sim actions < 0": ("sim --scene FB --actions -3", "argument --actions: must be 1 or more"),
    "actions not a number": ("sim --scene FB --actions two", "expected an integer, got 'two'"),
    "table runs 0": ("table --scenes SYN2 --runs 0 --out {tmp}/t", "argument --runs: must be 1"),
    "table stream < 0": ("table --scenes SYN2 --filter-stream -1 --out {tmp}/t",
                         "argument --filter-stream: must be 0 or more, got -1"),
    "table workers 0": ("table --scenes SYN2 --workers 0 --out {tmp}/t",
                        "argument --workers: must be 1 or more, got 0"),
    "sweep trials 0": ("sweep --method dbscan --scenes SYN2 --trials 0 --out {tmp}/s",
                       "argument --trials: must be 1 or more, got 0"),
    "sweep workers < 0": ("sweep --method dbscan --scenes SYN2 --workers -4 --out {tmp}/s",
                          "argument --workers: must be 1 or more, got -4"),
    # Names.
    "run unknown method": ("run --scene FB --method optics", "invalid choice: 'optics'"),
    "diagram unknown method": ("diagram --method optics --out {tmp}/d.svg",
                               "invalid choice: 'optics'"),
    "run unknown scene": ("run --scene NOPE", "NOPE.yaml", "No such file"),
    "sim unknown scene": ("sim --scene NOPE", "NOPE.yaml", "No such file"),
    "diagram unknown scene": ("diagram --scene NOPE --out {tmp}/d.svg", "NOPE.yaml"),
    "table unknown names": ("table --scenes SYN2 NOPE --methods dbscan optics --out {tmp}/t",
                            "unknown scene(s) 'NOPE'", "unknown method(s) 'optics'"),
    "sweep unknown scene": ("sweep --method dbscan --scenes NOPE --out {tmp}/s",
                            "unknown scene(s) 'NOPE'"),
    "scheduler without dask": ("table --scenes SYN2 --scheduler tcp://127.0.0.1:1 --out {tmp}/t",
                               "--scheduler needs --executor dask"),
    "missing option": ("table --scenes SYN2", "required: --out"),
    "run unknown policy": ("run --scene FB --policy wander", "invalid choice: 'wander'"),
    "belief without a target": ("table --scenes SYN2 --policy belief --out {tmp}/t",
                                "--policy belief: scene SYN2 has no target to grasp"),
    "sweep without a target": ("table --scenes SYN2 --policy sweep --out {tmp}/t",
                               "--policy sweep: scene SYN2 has no target to grasp"),
    "estimates hypothesis params unknown key": (
        "estimates --table {tmp}/a_folder --hypothesis-params {tmp}/typo.yaml",
        "--hypothesis-params {tmp}/typo.yaml: lenght: not a setting of HypothesisParams"),
    "estimates stucco params unknown key": (
        "estimates --table {tmp}/a_folder --stucco-params {tmp}/typo.yaml",
        "--stucco-params {tmp}/typo.yaml: lenght: not a setting of SoftTrackingParams"),
    "estimates stucco params, a baseline": (
        "estimates --table {tmp}/a_folder --method kmeans --stucco-params {tmp}/typo.yaml",
        "--stucco-params: only with --method stucco, not kmeans"),
    "estimates threshold > 1": ("estimates --table {tmp}/a_folder --confident-from 1.2",
                                "argument --confident-from: must be in [0, 1], got 1.2"),
    "estimates cut at 0 actions": ("estimates --table {tmp}/a_folder --after-actions 12 0",
                                   "argument --after-actions: must be 1 or more, got 0"),
    "estimates scale > 1": ("estimates --table {tmp}/a_folder --motion-scales 0 1.5",
                            "--motion-scales: ", "in [0, 1], got [0.0, 1.5]"),
    "noise < 0": ("scenes noise --scenes FB --bubble-std -0.001 --out {tmp}/n",
                  "FB-noise: sensor_noise.bubble_point_std: must be >= 0, got -0.001"),
    # Input files.
    "model file missing": ("sim --scene {tmp}/no_model.yaml", "no_model.yaml: directives[",
                           "].add_model.file: ", "999_cracker_box_10kg.sdf", "does not exist"),
    "model package unknown": ("run --scene {tmp}/no_package.yaml", "no_package.yaml: directives[",
                              "unknown package 'no_such_pkg'"),
    "scene is a folder": ("sim --scene {tmp}/a_folder", "a_folder: <file>: Is a directory"),
    "params missing": ("run --scene FB --stucco-params {tmp}/none.yaml",
                       "--stucco-params: ", "no such file", "none.yaml"),
    "params not yaml": ("table --scenes SYN2 --stucco-params {tmp}/broken.yaml --out {tmp}/t",
                        "--stucco-params: ", "broken.yaml is not valid YAML"),
    "params unknown key": ("run --scene FB --stucco-params {tmp}/typo.yaml",
                           "typo.yaml: SoftTrackingParams: unknown key(s) lenght"),
    "policy params unknown key": (
        "table --scenes FB --policy probe --policy-params {tmp}/typo.yaml --out {tmp}/t",
        "--policy-params {tmp}/typo.yaml: lenght: not a setting of ProbeParams"),
    "policy params bad value": ("run --scene FB --policy belief --policy-params {tmp}/bad.yaml",
                                "--policy-params {tmp}/bad.yaml: probe.max_bumps: expected an "
                                "integer, got 1.5"),
    "policy params missing": ("run --scene FB --policy probe --policy-params {tmp}/none.yaml",
                              "--policy-params: no such file", "none.yaml"),
    "policy params not yaml": ("run --scene FB --policy sweep --policy-params {tmp}/broken.yaml",
                               "--policy-params: ", "broken.yaml is not valid YAML"),
    "policy params, prescribed": ("table --scenes SYN2 --policy-params {tmp}/bad.yaml "
                                  "--out {tmp}/t",
                                  "--policy-params: --policy prescribed takes no settings"),
    "table hypothesis params unknown key": (
        "table --scenes FB --hypothesis-params {tmp}/typo.yaml --out {tmp}/t",
        "--hypothesis-params {tmp}/typo.yaml: lenght: not a setting of HypothesisParams"),
    "table hypothesis params bad value": (
        "table --scenes FB --hypothesis-params {tmp}/bad_hypotheses.yaml --out {tmp}/t",
        "--hypothesis-params {tmp}/bad_hypotheses.yaml: min_explained: expected an integer, "
        "got 2.5"),
    "table hypothesis params missing": (
        "table --scenes FB --hypothesis-params {tmp}/none.yaml --out {tmp}/t",
        "--hypothesis-params: no such file", "none.yaml"),
    "table hypothesis params, synthetic scene": (
        "table --scenes FB SYN2 --hypothesis-params {tmp}/hypotheses.yaml --out {tmp}/t",
        "--hypothesis-params: scene SYN2 has no target pose estimator"),
    "run hypothesis params unknown key": (
        "run --scene FB --hypothesis-params {tmp}/typo.yaml",
        "--hypothesis-params {tmp}/typo.yaml: lenght: not a setting of HypothesisParams"),
    "params a folder": ("run --scene FB --stucco-params {tmp}/a_folder",
                        "cannot read", "a_folder (Is a directory)"),
    # Output paths.
    "table out is a file": ("table --scenes SYN2 --out {tmp}/a_file",
                            "--out {tmp}/a_file: is a file, not a folder"),
    "table out under a file": ("table --scenes SYN2 --out {tmp}/a_file/t",
                               "--out {tmp}/a_file/t: {tmp}/a_file is a file, not a folder"),
    "sweep.csv of another version": ("sweep --method dbscan --scenes SYN2 --out {tmp}/old_sweep",
                                     "old_sweep/sweep.csv: not a runs file of this version"),
    "sweep out is a file": ("sweep --method dbscan --scenes SYN2 --out {tmp}/a_file",
                            "--out {tmp}/a_file: is a file, not a folder"),
    "sim record under a file": ("sim --scene FB --record {tmp}/a_file/fb.html",
                                "--record {tmp}/a_file/fb.html: {tmp}/a_file is a file"),
    "run record is a folder": ("run --scene FB --record {tmp}/a_folder",
                               "--record {tmp}/a_folder: is a folder, not a file"),
    "run plot under a file": ("run --scene FB --plot {tmp}/a_file/x/fb.png",
                              "--plot {tmp}/a_file/x/fb.png: {tmp}/a_file is a file"),
    "diagram out is a folder": ("diagram --out {tmp}/a_folder",
                                "--out {tmp}/a_folder: is a folder"),
    "diagram out under a file": ("diagram --out {tmp}/a_file/bor.svg", "{tmp}/a_file is a file"),
}  # fmt: skip


@pytest.mark.parametrize("case", BAD_INPUTS)
def test_a_bad_input_is_one_error_line_before_any_work(case, paths, tripwire, capsys):
    command, *fragments = BAD_INPUTS[case]
    fill = {"tmp": str(paths)}
    assert_one_line_error(
        command.format(**fill).split(), capsys, *(f.format(**fill) for f in fragments)
    )


def test_a_table_folder_of_other_settings_or_versions_is_refused_before_any_work(
    tmp_path, tripwire, capsys
):
    argv = ["table", "--scenes", "SYN2", "--out", str(tmp_path)]
    with pytest.raises(WorkStarted):  # records this folder's settings, then works
        main([*argv, "--dx-model", "normal"])
    assert_one_line_error(argv, capsys, "table_config.yaml", "--dx-model normal, not ee")
    (tmp_path / "runs.csv").write_text("scene,seed,method,fmi\nSYN2,0,dbscan,1\n")
    assert_one_line_error([*argv, "--dx-model", "normal"], capsys, "runs.csv: not a runs file")


def test_policy_settings_reach_the_episodes_and_a_folder_keeps_its_own(
    tmp_path, tripwire, capsys, monkeypatch
):
    import stucco_drake.eval.cli_table

    seen = {}

    def make_table(scenes, methods, runs, out, executor, **kwargs):
        seen.update(kwargs)
        raise WorkStarted("the command started its work")

    monkeypatch.setattr(stucco_drake.eval.cli_table, "make_table", make_table)
    (tmp_path / "probe.yaml").write_text("end_face_first: true\nclearance: 0.05\n")
    argv = ["table", "--scenes", "FB", "--policy", "probe", "--out", str(tmp_path / "t")]
    with pytest.raises(WorkStarted):
        main([*argv, "--policy-params", str(tmp_path / "probe.yaml")])
    # The episodes of FB are recorded under the file's settings, the rest at the defaults.
    settings = seen["sources"]["FB"].produce.keywords["policy"]
    assert settings.end_face_first is True and settings.clearance == 0.05
    assert settings.max_bumps == 1
    assert seen["policy_params"] == {"end_face_first": True, "clearance": 0.05}
    # The folder recorded them: the defaults are another setting there.
    assert_one_line_error(argv, capsys, "table_config.yaml", "--policy-params ",
                          "end_face_first", "not {}")


def test_hypothesis_settings_reach_the_episodes_and_grasps_and_a_folder_keeps_its_own(
    tmp_path, tripwire, capsys, monkeypatch
):
    """``table --policy probe --hypothesis-params``: the episodes are recorded under both the
    policy's and the hypotheses' settings, the grasps (wrapped for the target estimator as
    the replay does) made with the latter; only the fields that differ from the defaults are
    recorded, and the folder then refuses other hypothesis settings."""
    import stucco_drake.bor.log
    import stucco_drake.eval.cli_table
    from stucco_drake.core.hypothesis_params import HypothesisParams

    seen, calls = {}, {}

    def make_table(scenes, methods, runs, out, executor, **kwargs):
        seen.update(kwargs)
        raise WorkStarted("the command started its work")

    def record_episode(scene, seed, **kwargs):
        calls["record"] = (scene.name, seed, kwargs)

    def grasp_from_log(log, tracker, scene, estimator, hypothesis_params):
        calls["grasp"] = (estimator, hypothesis_params)

    monkeypatch.setattr(stucco_drake.eval.cli_table, "make_table", make_table)
    monkeypatch.setattr(stucco_drake.bor.log, "record_episode", record_episode)
    monkeypatch.setattr(stucco_drake.bor.log, "grasp_from_log", grasp_from_log)
    # Two fields, one of them at its default: only the other is a change.
    (tmp_path / "hypotheses.yaml").write_text("confidence_temperature: 3.0\nmin_explained: 3\n")
    (tmp_path / "other.yaml").write_text("confidence_temperature: 2.0\n")
    argv = ["table", "--scenes", "FB", "--policy", "probe", "--out", str(tmp_path / "t")]
    with pytest.raises(WorkStarted):
        main([*argv, "--hypothesis-params", str(tmp_path / "hypotheses.yaml")])
    expected = HypothesisParams(confidence_temperature=3.0)
    source = seen["sources"]["FB"]
    source.produce("FB", 4)
    name, seed, kwargs = calls["record"]
    assert (name, seed) == ("FB", 4) and kwargs["hypothesis_params"] == expected
    assert kwargs["policy"].max_bumps == 1  # the policy's own settings are kept beside them
    functools.partial(source.grasp, estimator="hypotheses")(None, None)  # as replay_cached
    assert calls["grasp"] == ("hypotheses", expected)
    assert seen["hypothesis_params"] == {"confidence_temperature": 3.0}
    config = yaml.safe_load((tmp_path / "t" / "table_config.yaml").read_text())
    assert config["hypothesis_params"] == {"confidence_temperature": 3.0}
    for other in ([], ["--hypothesis-params", str(tmp_path / "other.yaml")]):
        assert_one_line_error([*argv, *other], capsys, "table_config.yaml",
                              "--hypothesis-params {'confidence_temperature': 3.0}, not ")


def test_a_table_folder_recorded_before_hypothesis_settings_existed_keeps_the_defaults(
    tmp_path, tripwire, capsys
):
    argv = ["table", "--scenes", "FB", "--out", str(tmp_path)]
    with pytest.raises(WorkStarted):
        main(argv)
    path = tmp_path / "table_config.yaml"
    config = yaml.safe_load(path.read_text())
    assert config.pop("hypothesis_params") == {}
    path.write_text(yaml.safe_dump(config))  # as written before the key existed
    with pytest.raises(WorkStarted):  # accepted: the same setting
        main(argv)
    assert "hypothesis_params" not in yaml.safe_load(path.read_text())  # left as it was
    (tmp_path / "hypotheses.yaml").write_text("confidence_temperature: 3.0\n")
    assert_one_line_error([*argv, "--hypothesis-params", str(tmp_path / "hypotheses.yaml")],
                          capsys, "--hypothesis-params {}, not ")


def test_run_hands_its_hypothesis_settings_to_the_episode(tmp_path, tripwire, monkeypatch):
    import stucco_drake.bor.episode
    import stucco_drake.scenes.meshcat_session
    from stucco_drake.core.hypothesis_params import HypothesisParams

    seen = {}

    def run_episode(*args, **kwargs):
        seen.update(kwargs)
        raise WorkStarted("the command started its work")

    monkeypatch.setattr(stucco_drake.bor.episode, "run_episode", run_episode)
    monkeypatch.setattr(stucco_drake.scenes.meshcat_session, "start_meshcat", lambda *a: None)
    (tmp_path / "hypotheses.yaml").write_text("grasp_margin: 0.02\n")
    with pytest.raises(WorkStarted):
        main(["run", "--scene", "FB", "--hypothesis-params", str(tmp_path / "hypotheses.yaml")])
    assert seen["hypothesis_params"] == HypothesisParams(grasp_margin=0.02)
    with pytest.raises(WorkStarted):
        main(["run", "--scene", "FB"])
    assert seen["hypothesis_params"] is None  # the defaults, as before the option


@pytest.mark.skipif(
    not hasattr(os, "geteuid") or os.geteuid() == 0,
    reason="needs a user whom a folder's permissions bind",
)
def test_a_read_only_folder_is_refused_before_any_work(tmp_path, tripwire, capsys):
    locked = tmp_path / "locked"
    locked.mkdir(mode=0o500)
    try:
        assert_one_line_error(
            ["sim", "--scene", "FB", "--record", str(locked / "fb.html")],
            capsys,
            "cannot be written",
            "Permission denied",
        )
        assert_one_line_error(
            ["table", "--scenes", "SYN2", "--out", str(locked)],
            capsys,
            "cannot write in it",
            "Permission denied",
        )
    finally:
        locked.chmod(0o700)


@pytest.mark.parametrize("argv", [
    "sim --scene FB --record {tmp}/new/fb.html",
    "run --scene FB --plot {tmp}/new/fb.png --stucco-params {tmp}/good.yaml",
    "diagram --scene FB --out {tmp}/new/bor.svg",
    "table --scenes SYN2 --out {tmp}/new",
    "table --scenes FB --policy probe --policy-params {tmp}/probe.yaml --out {tmp}/new",
    "table --scenes FB --hypothesis-params {tmp}/hypotheses.yaml --out {tmp}/new",
    "run --scene FB --hypothesis-params {tmp}/hypotheses.yaml --plot {tmp}/new/fb.png",
    "run --scene FB --policy belief --policy-params {tmp}/probe.yaml --plot {tmp}/new/fb.png",
    "sweep --method dbscan --scenes SYN2 --out {tmp}/new",
])  # fmt: skip
def test_good_inputs_pass_the_checks(argv, tmp_path, tripwire):
    (tmp_path / "good.yaml").write_text("n_particles: 50\n")
    (tmp_path / "probe.yaml").write_text("max_actions: 20\n")
    (tmp_path / "hypotheses.yaml").write_text("confidence_temperature: 3.0\n")
    with pytest.raises(WorkStarted):
        main(argv.format(tmp=tmp_path).split())
    assert (tmp_path / "new").is_dir()  # the output's folder is made before the work


def test_the_installed_command_prints_no_traceback():
    """The issue's case, as a process: exit status 2 and exactly one line, no traceback."""
    command = [sys.executable, "-m", "stucco_drake.cli", "run", "--scene", "FB", "--method",
               "stucco", "--seed", "-1"]  # fmt: skip
    result = subprocess.run(command, capture_output=True, text=True, timeout=120, check=False)
    assert result.returncode == 2
    assert result.stderr == "stucco-drake run: error: argument --seed: must be 0 or more, got -1\n"
    assert result.stdout == ""


def test_output_checks_leave_no_file_behind_and_existing_files_untouched(tmp_path):
    new = prepare_output_file("--record", tmp_path / "a" / "b" / "out.html")
    assert new == tmp_path / "a" / "b" / "out.html"
    assert new.parent.is_dir() and not new.exists()
    old = tmp_path / "old.png"
    old.write_bytes(b"previous picture")
    stamp = old.stat().st_mtime_ns
    assert prepare_output_file("--plot", old) == old
    assert old.read_bytes() == b"previous picture" and old.stat().st_mtime_ns == stamp
    assert prepare_output_file("--plot", None) is None
    folder = prepare_output_folder("--out", tmp_path / "c" / "d")
    assert folder.is_dir() and list(folder.iterdir()) == []
    with pytest.raises(InputError, match="is a folder, not a file"):
        prepare_output_file("--out", folder)
    with pytest.raises(InputError, match=r"old\.png is a file, not a folder"):
        prepare_output_folder("--out", old / "sub")
