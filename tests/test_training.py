"""The training set (closed-loop trials in Drake) and the parameter sweep that tunes on it."""

from __future__ import annotations

import concurrent.futures as cf

import numpy as np
import pytest
import yaml

from stucco_drake.cli import main
from stucco_drake.eval.episode_log import EpisodeLog, box_spec
from stucco_drake.eval.sources import EpisodeSource
from stucco_drake.eval.sweep import (
    best_combination,
    combination_label,
    parse_grid,
    run_sweep,
    training_summary,
)
from stucco_drake.eval.synthetic_episode import synthetic_episode
from stucco_drake.scenes import load_scene
from stucco_drake.systems.planar_controller import StartUnreachable
from stucco_drake.training import (
    WALK_LENGTH,
    ClearanceCheck,
    GreedyRandomWalkPolicy,
    TrialPlan,
    discard_reason,
    is_discarded,
    plan_trial,
    record_trial,
)

# SELECT1's 0.3 m box spans y in [-0.4, -0.1] at x = 0.25: starting 12 cm below it and heading
# for a goal beyond it, the gripper (5 cm half-width along y) touches it in its third action.
PLAN = TrialPlan(start=(0.25, -0.52), goal=(0.25, 0.05))
N_ACTIONS = 7


# ------------------------------------------------------------------------ closed-loop trials
@pytest.fixture(scope="module")
def trial_logs():
    return [record_trial("SELECT1", 5, max_actions=N_ACTIONS, plan=PLAN) for _ in range(2)]


def test_trial_heads_for_its_goal_then_walks_randomly_after_contact(trial_logs):
    log = trial_logs[0]
    trial = log.info["trial"]
    assert log.scene == "SELECT1" and log.n_actions == N_ACTIONS and not trial["reached_goal"]
    actions, verdicts = np.array(trial["actions"]), trial["detector_in_contact"]
    first = verdicts.index(True)  # the first action the detector judged in contact
    assert 1 <= first <= 4, verdicts
    # Greedy before the contact: straight +y at full step, and the gripper follows.
    np.testing.assert_allclose(actions[: first + 1, 1], 1.0)
    assert np.all(np.abs(actions[: first + 1, 0]) < 0.2)
    assert np.all(np.diff(log.ee_position[: first + 1, 1]) > 0.02)
    # After it: uniform random actions, not the greedy +y.
    walk = actions[first + 1 :]
    assert len(walk) >= 2 and np.all(np.abs(walk) <= 1.0)
    assert not np.allclose(walk[:, 1], 1.0), walk
    # The box was touched and logged as such; the log is a valid, kept trial.
    box = log.object_names.index("box")
    assert log.n_contacts >= 1 and np.any(log.contact_object == box)
    assert log.info["contact_fraction"] > 0.05 and log.info["discarded"] is False
    assert log.info["trial"]["start"] == list(PLAN.start)


def test_same_seed_gives_the_identical_log(trial_logs):
    a, b = trial_logs
    for name in ("ee_position", "contact_points", "contact_dx", "contact_object",
                 "object_poses", "robot_object_distance", "final_state"):  # fmt: skip
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)
    info_a, info_b = dict(a.info), dict(b.info)
    info_a.pop("wall_time_s"), info_b.pop("wall_time_s")
    assert info_a == info_b


def test_plan_is_reachable_clear_and_seeded():
    scene = load_scene("SELECT4")
    clear_calls = []

    def clear(xy):  # stands in for the Drake clearance check: away from the 0.3 m box
        clear_calls.append(tuple(xy))
        return np.hypot(xy[0] - 0.25, xy[1] - 0.25) > 0.3

    plans = [plan_trial(scene, np.random.default_rng(s), clear) for s in (0, 0, 1)]
    assert plans[0] == plans[1] != plans[2]
    for plan in plans:
        start, goal = np.array(plan.start), np.array(plan.goal)
        assert np.linalg.norm(goal - start) >= 0.7
        assert scene.in_workspace(start) and scene.in_workspace(goal)
        assert clear(start) and clear(goal)


def test_clearance_check_keeps_the_gripper_off_the_objects():
    check = ClearanceCheck(load_scene("SELECT1"), np.random.default_rng(0))
    assert check(PLAN.start)  # 7 cm below the box
    assert not check((0.25, -0.45))  # its bubbles 5 cm out along y: touching the box
    assert not check((0.25, 0.25))  # inside the cylinder


def test_policy_walks_after_each_contact_and_stays_reachable():
    scene = load_scene("SELECT1")
    policy = GreedyRandomWalkPolicy(scene, goal=(0.5, 0.0), rng=np.random.default_rng(0))
    np.testing.assert_allclose(policy.act((0.3, 0.0), False), [1.0, 0.0])
    np.testing.assert_allclose(policy.act((0.49, 0.01), False), [1 / 3, -1 / 3])
    kinds = []
    for contact in [True] + [False] * 3 + [True] + [False] * (WALK_LENGTH + 1):
        u = policy.act((0.3, 0.0), contact)
        kinds.append("greedy" if np.allclose(u, [1.0, 0.0]) else "walk")
    # A contact restarts the walk: 4 walk steps, then WALK_LENGTH more, then greedy again.
    assert kinds == ["walk"] * (4 + WALK_LENGTH) + ["greedy"] * 2
    # Across the robot's column (base at the origin): the step turns to stay reachable.
    across = GreedyRandomWalkPolicy(scene, goal=(0.5, 0.0), rng=np.random.default_rng(0))
    u = across.act((-0.24, 0.0), False)
    assert scene.in_workspace(np.array([-0.24, 0.0]) + 0.03 * u) and abs(u[1]) > 0.2


# ------------------------------------------------------------------------------ discard rule
def _log_with_contacts(n_actions: int, contact_actions) -> EpisodeLog:
    counts = np.zeros(n_actions, dtype=np.int64)
    counts[list(contact_actions)] = 1
    n = int(counts.sum())
    return EpisodeLog(
        scene="X", seed=0, action_noise=0.0, ee_position=np.zeros((n_actions, 3)),
        ee_rotation=np.broadcast_to(np.eye(3), (n_actions, 3, 3)),
        contact_offsets=np.concatenate([[0], np.cumsum(counts)]),
        contact_points=np.zeros((n, 3)), contact_dx=np.zeros((n, 3)),
        contact_object=np.zeros(n, dtype=np.int64), object_names=["a"],
        object_poses=np.zeros((n_actions + 1, 1, 3)), object_shapes=box_spec(0.1, 0.1, 0.1)[None],
        robot_object_distance=np.zeros((0, 1)), robot_shape=np.zeros(0), final_state=np.zeros(1),
    )  # fmt: skip


def test_discard_rule():
    assert "2.5%" in discard_reason(_log_with_contacts(40, [3]))  # 1 of 40 < 5 %
    assert discard_reason(_log_with_contacts(40, [3, 9])) == ""  # 5 %: kept
    assert "only 1" in discard_reason(_log_with_contacts(10, [3]))  # 10 %, but one contact
    flung = _log_with_contacts(40, [3, 9])
    flung.object_poses[30:, 0, 0] = 0.12  # 12 cm in action 29: flung
    assert discard_reason(flung) == "a moved 0.12 m in action 29 (> 0.1 m: flung by the simulation)"
    flung.object_poses[30:, 0, 0] = 0.05  # 5 cm: a hard push, kept
    assert discard_reason(flung) == ""
    log = _log_with_contacts(40, [3])
    assert not is_discarded(log)
    log.info["discarded"] = True
    assert is_discarded(log)


# ------------------------------------------------------------------------------------- sweep
class CountingExecutor(cf.ThreadPoolExecutor):
    """Threads (no pickling of test-local sources) that count the tasks submitted."""

    def __init__(self):
        super().__init__(1)
        self.submitted = 0

    def submit(self, *args, **kwargs):
        self.submitted += 1
        return super().submit(*args, **kwargs)


def _discard_odd_seeds(scene: str, seed: int) -> EpisodeLog:
    log = synthetic_episode(scene, seed)
    log.info["discarded"] = bool(seed % 2)
    return log


def test_sweep_picks_the_best_combination_and_resumes(tmp_path):
    sources = {"SYN2": EpisodeSource(_discard_odd_seeds)}
    grid = parse_grid("dbscan", ["eps=0.5,0.05", "min_samples=1"])
    executor = CountingExecutor()
    with executor:
        tuned = run_sweep("dbscan", ["SYN2"], 3, tmp_path, executor, grid, sources, progress=False)
    # Seeds 0 and 2 are kept (seed 1 is marked discarded): 2 combinations x 2 trials.
    assert executor.submitted == 3 + 4
    assert tuned["n_kept_trials"] == 2 and tuned["n_trials"] == 3
    # eps = 5 cm separates the two boxes (FMI 1); 50 cm merges them.
    assert tuned["swept"] == {"eps": 0.05, "min_samples": 1}
    assert tuned["params"] == {"eps": 0.05, "min_samples": 1}
    assert tuned["median_fmi"] == pytest.approx(1.0) and tuned["median_ce_cm"] < 0.01
    # SYN2 is ambiguous (0.40): every run counts in the ambiguous medians too.
    assert tuned["ambiguous"]["n_runs"] == 2 and tuned["ambiguous"]["threshold"] == 0.3
    worse = next(c for c in tuned["combinations"] if c["params"]["eps"] == 0.5)
    assert worse["median_fmi"] < 0.9
    # Each combination's median CE against the tuned one's, paired on the 2 kept trials.
    chosen = next(c for c in tuned["combinations"] if c["params"]["eps"] == 0.05)
    assert chosen["ce_gap_to_tuned"] == {"gap": 0.0, "low": 0.0, "high": 0.0, "n": 2,
                                         "n_lower": 0}  # fmt: skip
    gap = worse["ce_gap_to_tuned"]
    assert gap["n"] == 2 and gap["gap"] == pytest.approx(worse["median_ce_cm"]
                                                         - chosen["median_ce_cm"])
    assert gap["gap"] > 1.0 and 0.0 < gap["low"] <= gap["high"]  # merged boxes: cm off
    assert yaml.safe_load((tmp_path / "tuned_dbscan.yaml").read_text()) == tuned
    lines = (tmp_path / "sweep.csv").read_text().splitlines()
    assert len(lines) == 1 + 4
    assert sum(combination_label("dbscan", {"eps": 0.05, "min_samples": 1}) in line
               for line in lines) == 2  # fmt: skip

    # Rerun: nothing simulated, nothing replayed, the same result.
    before = {p.name: p.stat().st_mtime_ns for p in (tmp_path / "logs").iterdir()}
    again = CountingExecutor()
    with again:
        assert run_sweep("dbscan", ["SYN2"], 3, tmp_path, again, grid, sources,
                         progress=False) == tuned  # fmt: skip
    assert again.submitted == 0
    assert (tmp_path / "sweep.csv").read_text().splitlines() == lines
    assert {p.name: p.stat().st_mtime_ns for p in (tmp_path / "logs").iterdir()} == before


def test_tie_on_fmi_is_broken_by_ce_and_nan_ranks_last():
    def entry(name, fmi, ce):
        return {"params": {"x": name}, "median_fmi": fmi, "median_ce_cm": ce}

    summary = [entry("nan", float("nan"), 0.0), entry("a", 0.9, 2.0), entry("b", 0.9, 1.0),
               entry("c", 0.8, 0.1)]  # fmt: skip
    assert best_combination(summary)["params"] == {"x": "b"}


def test_sweep_command_on_synthetic_logs(tmp_path, capsys):
    out = tmp_path / "sweep"
    argv = ["sweep", "--method", "stucco", "--scenes", "SYN2", "--trials", "1", "--out",
            str(out), "--workers", "1", "--grid", "length=0.002,0.02"]  # fmt: skip
    assert main(argv) == 0
    tuned = yaml.safe_load((out / "tuned_stucco.yaml").read_text())
    # Both lengths segment SYN2 perfectly (FMI 1); the tie goes to the lower CE, l = 0.02.
    assert tuned["method"] == "stucco" and tuned["swept"] == {"length": 0.02}
    assert set(tuned["params"]) >= {"length", "penetration_length", "n_particles"}
    assert "median FMI" in capsys.readouterr().out
    assert len((out / "sweep.csv").read_text().splitlines()) == 1 + 2


@pytest.mark.parametrize(("entry", "message"), [
    ("bogus=1", "no sweepable parameter 'bogus'"),
    ("length=abc", "'abc' is not a number"),
    ("length=-1", "must be a positive number"),
    ("n_particles=1.5", "'1.5' is not an integer"),
    ("length", "expected name=v1,v2"),
    ("length=", "no values"),
])  # fmt: skip
def test_bad_grid_entry_is_a_one_line_error(tmp_path, capsys, entry, message):
    argv = ["sweep", "--method", "stucco", "--scenes", "SYN2", "--trials", "1", "--out",
            str(tmp_path), "--grid", entry]  # fmt: skip
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1, err
    assert not (tmp_path / "logs").exists()


def test_optional_parameter_is_swept_with_none_for_off():
    grid = parse_grid("stucco", ["touched_side_margin=none,0.002,None"])
    assert grid == {"touched_side_margin": (None, 0.002)}
    with pytest.raises(ValueError, match=r"touched_side_margin=-1.*must be None or >= 0"):
        parse_grid("stucco", ["touched_side_margin=-1"])
    with pytest.raises(ValueError, match="'off' is not a number"):
        parse_grid("stucco", ["touched_side_margin=off"])


def test_sweep_under_the_normal_contact_motion_keeps_its_own_runs(tmp_path):
    sources = {"SYN2": EpisodeSource(synthetic_episode)}
    grid = parse_grid("stucco", ["touched_side_margin=none,0.002"])
    runs = {}
    for dx_model in ("ee", "normal"):
        executor = CountingExecutor()
        with executor:
            runs[dx_model] = run_sweep("stucco", ["SYN2"], 1, tmp_path, executor, grid, sources,
                                       progress=False, dx_model=dx_model)  # fmt: skip
        # The second model simulates nothing new but replays both combinations again.
        assert executor.submitted == (1 if dx_model == "ee" else 0) + 2
    assert runs["ee"]["dx_model"] == "ee" and runs["normal"]["dx_model"] == "normal"
    assert yaml.safe_load((tmp_path / "tuned_stucco.yaml").read_text()) == runs["ee"]
    assert yaml.safe_load((tmp_path / "tuned_stucco_normal.yaml").read_text()) == runs["normal"]
    labels = [line.split(",")[2] for line in (tmp_path / "sweep.csv").read_text().splitlines()[1:]]
    assert sorted(labels) == sorted([
        "stucco[touched_side_margin=None]", "stucco[touched_side_margin=0.002]",
        "stucco@normal[touched_side_margin=None]", "stucco@normal[touched_side_margin=0.002]",
    ])  # fmt: skip
    for tuned in runs.values():
        assert tuned["n_runs"] == 1 and 0.0 <= tuned["median_fmi"] <= 1.0
        assert [c["params"] for c in tuned["combinations"]] == [
            {"touched_side_margin": None}, {"touched_side_margin": 0.002}]
    # Fig. 4: both tuned combinations, each with its one run, side by side.
    entries = training_summary(tmp_path)
    assert [(e["name"], len(e["rows"])) for e in entries] == [("stucco", 1), ("stucco@normal", 1)]
    assert entries[1]["rows"][0]["method"] == combination_label(
        "stucco", runs["normal"]["swept"], "normal")
    table = (tmp_path / "tuned.md").read_text().splitlines()
    assert len(table) == 2 + 2 and "| ours (STUCCO) | normal | touched_side_margin = " in table[3]
    assert (tmp_path / "fmi_ce.png").stat().st_size > 10_000


def test_unreachable_start_is_drawn_again():
    """SELECT2 seed 3 first draws a start straight behind the arm's base (joint 1 stops at
    170 degrees): the trial draws again from the same generator instead of failing."""
    scene = load_scene("SELECT2")
    first = plan_trial(scene, np.random.default_rng(np.random.SeedSequence(3).spawn(2)[0]))
    with pytest.raises(StartUnreachable, match="start IK did not converge"):
        record_trial(scene, 3, max_actions=1, plan=first)  # a given plan is never redrawn
    log = record_trial(scene, 3, max_actions=1)
    start = log.info["trial"]["start"]
    assert np.linalg.norm(np.subtract(start, first.start)) > 0.1
    # It did start there: after one action of at most 3 cm per axis, within 4.3 cm of it.
    assert np.linalg.norm(log.ee_position[0, :2] - start) < 0.043
