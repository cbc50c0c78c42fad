"""Table II machinery: episode logs, replay by every method, resumable runs, table and figure."""

import argparse
import concurrent.futures as cf
import dataclasses
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from stucco_drake.core.baselines import TRACKER_NAMES
from stucco_drake.core.inputs import InputError
from stucco_drake.eval import (
    EpisodeLog,
    RunInterrupted,
    RunResults,
    make_executor,
    replay,
    run_table,
    synthetic_episode,
)
from stucco_drake.eval.cli_table import add_table_command, check_names, make_table

ROW_KEYS = ("scene", "seed", "method")


def fake_row(task, ce=1.5):
    scene, seed, method = task
    return {
        "scene": scene, "seed": seed, "method": method, "grasp_success": None, "ce_cm": ce,
        "fmi": 0.5, "ambiguity": float("nan"), "n_contacts": 3, "wall_time_s": 0.01,
    }


def dying_run(task, marker):
    """A run that kills its worker process on task ('A', 1, 'y') the first time only."""
    if task == ("A", 1, "y") and not os.path.exists(marker):
        Path(marker).touch()
        os._exit(3)
    time.sleep(0.05)
    return fake_row(task)


def quick_run(task):
    return fake_row(task)


@pytest.fixture(scope="module")
def syn2_log(tmp_path_factory):
    path = tmp_path_factory.mktemp("logs") / "SYN2_0.npz"
    synthetic_episode("SYN2", 0).save(path)
    return EpisodeLog.load(path)


def distance_to_box_outline(points, pose, half_extents) -> np.ndarray:
    """Planar distance (m) from points (n, 2+) to the outline of an unturned box."""
    x, y, yaw = pose
    assert yaw == 0.0  # the synthetic world's boxes only translate
    d = np.abs(np.asarray(points)[:, :2] - (x, y)) - half_extents
    return np.abs(np.linalg.norm(np.maximum(d, 0.0), axis=1) + np.minimum(d.max(axis=1), 0.0))


def holds_box0(log, tracker) -> bool:
    """A grasp stand-in judged against the world's truth: the gripper closes on the tracker's
    largest segment and holds box0 (the target) when every point of that segment lies on
    box0's final outline, within 5 mm. Each of SYN2's pushing rounds moves a face 1 cm, so a
    point left behind by a single push, or one of the other box (25 cm away at the end, 4.5
    cm at the start), fails it; the synthetic contacts are exact and the boxes translate
    with the end effector as every tracker's motion model assumes, so points kept with their
    box stay on it to round-off."""
    assert tracker.n_contacts == log.n_contacts  # asked after the last action
    labels = tracker.segment()
    if not np.any(labels >= 0):
        return False
    largest = tracker.map_points()[labels == np.bincount(labels[labels >= 0]).argmax()]
    box0 = log.object_names.index("box0")
    (shape,) = log.object_shapes[log.shape_object == box0]
    assert not shape[4:].any()  # one box centred in the object's frame
    half = shape[1:3]
    return bool(distance_to_box_outline(largest, log.object_poses[-1, box0], half).max() <= 0.005)


def test_every_method_replays_a_logged_episode_with_finite_metrics(syn2_log):
    assert syn2_log.n_contacts > 10 and syn2_log.n_actions > 100
    assert syn2_log.action_noise == 5e-4
    verdicts = {}
    for method in TRACKER_NAMES:

        def grasp(log, tracker, method=method):
            assert log is syn2_log
            verdicts[method] = holds_box0(log, tracker)
            return verdicts[method]

        row = replay(syn2_log, method, grasp=grasp)
        assert row["n_contacts"] == syn2_log.n_contacts, method
        assert np.isfinite([row["ce_cm"], row["fmi"], row["ambiguity"]]).all(), method
        assert 0.0 <= row["fmi"] <= 1.0, method
        # The row reports the hook's verdict on this method's final tracker.
        assert row["grasp_success"] is verdicts[method], method
    print("\ngrasp verdicts", verdicts)
    # SYN2 is STUCCO's key case: it keeps box0's points on box0 and holds it. Measured: DBSCAN
    # does too; BIRCH and k-means put both boxes' points in one segment, GM-PHD mixes them, and
    # fail: the hook's False reaches the row as well.
    assert verdicts["stucco"] is True
    assert False in verdicts.values()
    assert replay(syn2_log, "stucco")["grasp_success"] is None
    # Without logged robot-object distances the ambiguity is undefined.
    k = len(syn2_log.object_names)
    blind = dataclasses.replace(syn2_log, robot_object_distance=np.zeros((0, k)))
    assert np.isnan(replay(blind, "dbscan")["ambiguity"])


def test_same_seed_gives_identical_rows_and_the_seed_perturbs_the_actions():
    first, second = synthetic_episode("SYNC", 3), synthetic_episode("SYNC", 3)
    other = synthetic_episode("SYNC", 4)
    np.testing.assert_array_equal(first.ee_position, second.ee_position)
    step = np.abs(first.ee_position - other.ee_position).max()
    assert 0.0 < step < 0.02  # noise of +-0.5 mm per action, accumulated
    for method in ("stucco", "kmeans", "gmphd"):
        rows = [replay(log, method) for log in (first, second)]
        for row in rows:
            row.pop("wall_time_s")
        assert rows[0] == rows[1], method


def test_wrong_version_and_malformed_logs_give_one_line_errors(syn2_log, tmp_path):
    good = tmp_path / "good.npz"
    syn2_log.save(good)
    with np.load(good) as data:
        arrays = dict(data)
    np.savez(tmp_path / "v9.npz", **{**arrays, "format_version": np.int64(9)})
    del arrays["contact_dx"]
    np.savez(tmp_path / "missing.npz", **arrays)
    (tmp_path / "junk.npz").write_bytes(b"not a zip file")
    cases = {"v9.npz": "format version 9", "missing.npz": "not a valid episode log",
             "junk.npz": "not a valid episode log", "absent.npz": "not a valid episode log"}
    for name, message in cases.items():
        with pytest.raises(ValueError, match=message) as error:
            EpisodeLog.load(tmp_path / name)
        assert "\n" not in str(error.value) and name in str(error.value)


def test_truncated_last_line_is_ignored_and_repaired(tmp_path):
    results = RunResults(tmp_path / "runs.csv")
    assert results.append(fake_row(("S", 0, "m")))
    assert results.append(fake_row(("S", 1, "m")))
    with open(results.path, "ab") as file:
        file.write(b"S,2,m,,0.3")  # a crash mid-write
    fresh = RunResults(results.path)
    assert len(fresh.rows()) == 2 and ("S", 2, "m") not in fresh.done()
    assert fresh.append(fake_row(("S", 2, "m"), ce=float("nan")))
    assert not fresh.append(fake_row(("S", 0, "m")))  # duplicate: not written
    lines = results.path.read_text().splitlines()
    assert len(lines) == 4 and lines[0].startswith("scene,seed,method,grasp_success")
    rows = RunResults(results.path).rows()
    assert [r["seed"] for r in rows] == [0, 1, 2] and np.isnan(rows[2]["ce_cm"])
    assert rows[0]["grasp_success"] is None and rows[0]["ce_cm"] == 1.5


def test_a_dead_worker_is_reported_and_a_rerun_completes_the_table(tmp_path):
    import functools

    tasks = [(s, seed, m) for s in ("A", "B") for seed in range(3) for m in ("x", "y")]
    results = RunResults(tmp_path / "runs.csv")
    run = functools.partial(dying_run, marker=str(tmp_path / "died"))
    with make_executor("process", workers=2) as executor:
        with pytest.raises(RunInterrupted, match="rerun the same command") as error:
            run_table(tasks, run, results, executor, progress=False)
    assert isinstance(error.value.__cause__, cf.process.BrokenProcessPool)
    assert ("A", 1, "y") not in results.done() and len(results.done()) < len(tasks)
    with make_executor("process", workers=2) as executor:
        run_table(tasks, run, results, executor, progress=False)
    lines = results.path.read_text().splitlines()[1:]
    keys = [tuple(line.split(",")[:3]) for line in lines]
    assert len(keys) == len(set(keys)) == len(tasks)
    assert {(s, int(seed), m) for s, seed, m in keys} == set(tasks)


#: A table on SYN2 whose STUCCO replay of seed 1 never ends (run in a process of its own).
STALLING_TABLE = """
import time
from stucco_drake.eval.cli_table import make_table
from stucco_drake.eval.runner import make_executor
from stucco_drake.eval.sources import EpisodeSource
from stucco_drake.eval.synthetic_episode import synthetic_episode

def penetration(log):
    if log.seed == 1:
        time.sleep(600)
    return None  # as the synthetic source: replay builds pxpen from the log's robot shape

def run(out):
    sources = {"SYN2": EpisodeSource(synthetic_episode, penetration)}
    with make_executor("process", workers=2) as executor:
        make_table(["SYN2"], ["dbscan", "stucco"], 2, out, executor, progress=False,
                   sources=sources)
"""


def runs_without_wall_time(path: Path) -> list[str]:
    """The lines of a runs file, sorted, without the wall time (which no two runs share)."""
    header, *lines = path.read_text().splitlines()
    wall = header.split(",").index("wall_time_s")
    return sorted(",".join(f for i, f in enumerate(line.split(",")) if i != wall)
                  for line in lines)  # fmt: skip


def _live_members(group: int) -> list[int]:
    """The processes of process group ``group`` that are neither gone nor zombies (read
    from /proc: a zombie still answers ``kill(pid, 0)``)."""
    members = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except (OSError, IndexError):
            continue  # ended while being read
        if int(fields[2]) == group and fields[0] != "Z":
            members.append(int(stat.parent.name))
    return members


@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="reads processes from /proc")
def test_a_killed_table_keeps_its_rows_and_the_rerun_computes_only_the_rest(tmp_path,
                                                                             monkeypatch):
    """SIGKILL of a table with two workers, stuck in its last run: the workers end with it,
    the finished rows stay, the rerun computes the missing run only, and the result is an
    uninterrupted table's."""
    import stucco_drake.eval.cli_table as cli_table

    (tmp_path / "stalling_table.py").write_text(STALLING_TABLE)
    out = tmp_path / "killed"
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(
        [str(tmp_path), *filter(None, [os.environ.get("PYTHONPATH")])])}  # fmt: skip
    code = f"import stalling_table; stalling_table.run({str(out)!r})"
    table = subprocess.Popen([sys.executable, "-c", code], env=env, start_new_session=True,
                             stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)  # fmt: skip
    finished = {("SYN2", 0, "dbscan"), ("SYN2", 0, "stucco"), ("SYN2", 1, "dbscan")}
    try:
        deadline = time.monotonic() + 300
        while RunResults(out / "runs.csv").done() != finished:
            assert table.poll() is None, table.stderr.read().decode()
            assert time.monotonic() < deadline, "the table did not reach its stuck run"
            time.sleep(0.1)
        os.kill(table.pid, signal.SIGKILL)  # the table's own process, as `kill -9 PID`
        assert table.wait(timeout=30) == -signal.SIGKILL
        # Its two workers, one of them 600 s from the end of its run, end on their own (30 s
        # allowed: they notice within milliseconds; the slack is for a loaded machine).
        deadline = time.monotonic() + 30
        while _live_members(table.pid) and time.monotonic() < deadline:
            time.sleep(0.1)
        assert _live_members(table.pid) == []
    finally:  # whatever is left of the group (nothing, when the assertion above held)
        try:
            os.killpg(table.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
        table.wait(timeout=30)
        table.stderr.close()
    killed_lines = (out / "runs.csv").read_text().splitlines()
    assert RunResults(out / "runs.csv").done() == finished
    log_stamps = {p.name: p.stat().st_mtime_ns for p in (out / "logs").iterdir()}
    assert sorted(log_stamps) == ["SYN2_0.npz", "SYN2_1.npz"]

    replayed, simulated = [], []
    real_replay, real_produce = cli_table.replay, cli_table.produce_episode

    def counted_replay(log, method, **kwargs):
        replayed.append((log.scene, log.seed, method))
        return real_replay(log, method, **kwargs)

    def counted_produce(episode, *args):
        simulated.append(episode)
        return real_produce(episode, *args)

    monkeypatch.setattr(cli_table, "replay", counted_replay)
    monkeypatch.setattr(cli_table, "produce_episode", counted_produce)
    with cf.ThreadPoolExecutor(2) as executor:
        make_table(["SYN2"], ["dbscan", "stucco"], 2, out, executor, progress=False)
        assert replayed == [("SYN2", 1, "stucco")] and simulated == []
        lines = (out / "runs.csv").read_text().splitlines()
        assert lines[: len(killed_lines)] == killed_lines and len(lines) == 5  # kept as written
        assert {p.name: p.stat().st_mtime_ns for p in (out / "logs").iterdir()} == log_stamps
        uninterrupted = tmp_path / "uninterrupted"
        make_table(["SYN2"], ["dbscan", "stucco"], 2, uninterrupted, executor, progress=False)
    assert len(simulated) == 2 and len(replayed) == 1 + 4
    assert runs_without_wall_time(out / "runs.csv") == runs_without_wall_time(
        uninterrupted / "runs.csv")
    assert (out / "table.md").read_text() == (uninterrupted / "table.md").read_text()


def test_small_table_writes_layout_and_figure_and_resumes(tmp_path):
    scenes, methods = ("SYN2", "SYNC"), ("stucco", "dbscan")
    with make_executor("process", workers=2) as executor:
        rows = make_table(scenes, methods, 2, tmp_path, executor, progress=False)
    assert len(rows) == 8 and all(np.isfinite(r["ce_cm"]) for r in rows)
    table = (tmp_path / "table.md").read_text().splitlines()
    header = [c.strip() for c in table[0].strip("|").split("|")]
    assert header == ["method", "SYN2 GS %", "SYN2 FMI", "SYN2 CE cm",
                      "SYNC GS %", "SYNC FMI", "SYNC CE cm"]
    assert table[2].startswith("| ours (STUCCO) |") and table[3].startswith("| DBSCAN |")
    assert all(len(line.strip("|").split("|")) == 7 for line in table[2:4])
    assert "n/a" in table[2]  # no grasp check given: GS is empty
    from matplotlib.image import imread

    image = imread(tmp_path / "fmi_ce.png")
    assert image.shape[1] > image.shape[0]  # two scene columns, two rows (all, ambiguous)
    logs = sorted(p.name for p in (tmp_path / "logs").iterdir())
    assert logs == ["SYN2_0.npz", "SYN2_1.npz", "SYNC_0.npz", "SYNC_1.npz"]
    stamp = (tmp_path / "logs" / "SYNC_1.npz").stat().st_mtime_ns
    with cf.ThreadPoolExecutor(2) as executor:  # everything is done: nothing re-simulated
        again = make_table(scenes, methods, 2, tmp_path, executor, progress=False)
    assert again == rows and (tmp_path / "logs" / "SYNC_1.npz").stat().st_mtime_ns == stamp


def test_layouts_of_one_family_share_a_column_group(tmp_path):
    """Two scenes whose sources name one family (as a base scene's randomized layouts do) are
    tabled as one column group: its CE is the mean over both scenes' runs in runs.csv."""
    from stucco_drake.eval.results import RunResults
    from stucco_drake.eval.sources import EpisodeSource
    from stucco_drake.eval.synthetic_episode import synthetic_episode

    sources = {name: EpisodeSource(synthetic_episode, family="SYN") for name in ("SYN2", "SYNC")}
    with cf.ThreadPoolExecutor(1) as executor:
        make_table(["SYN2", "SYNC"], ["dbscan"], 1, tmp_path, executor, progress=False,
                   sources=sources)  # fmt: skip
    table = (tmp_path / "table.md").read_text().splitlines()
    assert [c.strip() for c in table[0].strip("|").split("|")] == [
        "method", "SYN GS %", "SYN FMI", "SYN CE cm"]
    ce = [row["ce_cm"] for row in RunResults(tmp_path / "runs.csv").rows()]
    assert len(ce) == 2
    cell = table[2].strip("|").split("|")[3].strip().strip("*")
    assert float(cell.split()[0]) == pytest.approx(np.mean(ce), abs=0.005)  # two decimals
    assert "SYN: 2 runs per method" in table


def test_a_table_folder_refuses_rows_of_another_setting(tmp_path):
    from stucco_drake.core.params import SoftTrackingParams

    with cf.ThreadPoolExecutor(1) as executor:
        rows = make_table(["SYN2"], ["dbscan"], 1, tmp_path, executor, progress=False)
        assert len(rows) == 1
        config = (tmp_path / "table_config.yaml").read_text()
        assert "dx_model: ee" in config and "length: 0.02" in config
        with pytest.raises(ValueError, match=r"--dx-model ee, not normal") as error:
            make_table(["SYN2"], ["dbscan"], 1, tmp_path, executor, progress=False,
                       dx_model="normal")
        assert "\n" not in str(error.value)
        with pytest.raises(ValueError, match=r"--filter-stream 0, not 2"):
            make_table(["SYN2"], ["dbscan"], 1, tmp_path, executor, progress=False,
                       filter_stream=2)
        with pytest.raises(ValueError, match=r"--target-estimator rules, not hypotheses"):
            make_table(["SYN2"], ["dbscan"], 1, tmp_path, executor, progress=False,
                       target_estimator="hypotheses")
        with pytest.raises(ValueError, match=r"target_estimator: expected one of"):
            make_table(["SYN2"], ["dbscan"], 1, tmp_path, executor, progress=False,
                       target_estimator="best")
        longer = SoftTrackingParams.from_mapping({"length": 0.04})
        with pytest.raises(ValueError, match=r"STUCCO's length = 0.02, not 0.04"):
            make_table(["SYN2"], ["dbscan"], 1, tmp_path, executor, progress=False,
                       stucco_params=longer)
        # The same setting resumes; Table I given explicitly is the same setting as None.
        again = make_table(["SYN2"], ["dbscan"], 1, tmp_path, executor, progress=False,
                           stucco_params=SoftTrackingParams.sim())
    assert again == rows
    (tmp_path / "table_config.yaml").write_text("[1, 2]\n")
    with pytest.raises(ValueError, match="is not a table config"):
        make_table(["SYN2"], ["dbscan"], 1, tmp_path, cf.ThreadPoolExecutor(1), progress=False)


def test_another_filter_stream_redraws_stucco_and_leaves_the_baselines(tmp_path):
    rows = {}
    with cf.ThreadPoolExecutor(2) as executor:
        for stream in (0, 1):
            out = tmp_path / f"stream{stream}"
            if stream:  # the same episodes: a stream redraws the filter, not the world
                out.mkdir()
                (out / "logs").symlink_to(tmp_path / "stream0" / "logs")
            found = make_table(["SYNC"], ["stucco", "dbscan"], 2, out, executor,
                               progress=False, filter_stream=stream)
            rows[stream] = {(r["seed"], r["method"]): r for r in found}
        with pytest.raises(ValueError, match="filter_stream must be 0 or more"):
            make_table(["SYNC"], ["dbscan"], 1, tmp_path / "bad", executor, progress=False,
                       filter_stream=-1)
    assert "filter_stream: 1" in (tmp_path / "stream1" / "table_config.yaml").read_text()
    for seed in (0, 1):
        a, b = rows[0][(seed, "dbscan")], rows[1][(seed, "dbscan")]
        assert (a["ce_cm"], a["fmi"]) == (b["ce_cm"], b["fmi"])  # DBSCAN draws nothing
    # STUCCO's particle filter draws: on SYNC's random clutter another stream moves its CE.
    assert any(rows[0][(seed, "stucco")]["ce_cm"] != rows[1][(seed, "stucco")]["ce_cm"]
               for seed in (0, 1))  # fmt: skip
    assert all(np.isfinite(r["ce_cm"]) for r in rows[1].values())


def test_bad_names_raise_naming_them(tmp_path):
    with pytest.raises(ValueError, match=r"'FOO'.*'optics'") as error:
        check_names(["SYN2", "FOO"], ["stucco", "optics"])
    assert "\n" not in str(error.value)
    parser = argparse.ArgumentParser()
    add_table_command(parser.add_subparsers())
    args = parser.parse_args(["table", "--scenes", "SYNX", "--out", str(tmp_path / "out")])
    with pytest.raises(InputError, match="'SYNX'"):
        args.run(args)
    assert not (tmp_path / "out").exists()
    with pytest.raises(ValueError, match="'spark'"):
        make_executor("spark")


def test_dask_missing_gives_install_hint(monkeypatch):
    monkeypatch.setitem(sys.modules, "dask.distributed", None)  # import fails as if absent
    with pytest.raises(RuntimeError, match=r"pip install 'stucco_drake\[dask\]'"):
        make_executor("dask")


def test_dask_executor_runs_the_table_on_a_loopback_cluster(tmp_path):
    distributed = pytest.importorskip("dask.distributed", reason="dask not installed")
    with distributed.LocalCluster(
        processes=False, n_workers=1, threads_per_worker=2, protocol="tcp://", host="127.0.0.1",
        dashboard_address=None,
    ) as cluster, distributed.Client(cluster) as client:
        tasks = [("A", seed, "x") for seed in range(4)]
        results = RunResults(tmp_path / "runs.csv")
        assert run_table(tasks, quick_run, results, client.get_executor(), progress=False) == 4
        assert results.done() == set(tasks)


def test_the_package_imports_no_pydrake():
    code = "import sys, stucco_drake.eval.cli_table; assert 'pydrake' not in sys.modules"
    subprocess.run([sys.executable, "-c", code], check=True)
