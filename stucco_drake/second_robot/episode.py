"""The contact-tracking chain on a second robot: the SCARA probe arm pushing three boxes.

:func:`run_second_robot` wires :func:`~stucco_drake.tracking.add_contact_tracking`
(the chain our BOR Diagram uses, unchanged) around the probe station of
:mod:`stucco_drake.scenes.probe_station`, with the probe's own surface samples (CPF), pxpen
grid and free-space statistics, plays the prescribed pushes and scores the chain against the
plant's own contact results:

- detection, per action: an action is truly in contact when the plant's strongest
  probe-object contact force is at least ``CONTACT_FORCE`` on at least ``MIN_CONTACT_STEPS``
  steps of it, truly free when it stays below ``GRAZE_FORCE`` on every step; the others are
  grazes (the probe leaving a box it pushed, the box sliding against it for a few steps at
  0.5-2 N) and count neither way. An action is detected when the detector flags at least one
  of its steps. Precision and recall over the contact and free actions.
- isolation: for every point the tracker receives (each detected action's last isolated
  contact), the distance to the true contact nearest it at the step it was isolated (the
  assembler's ``action_truth``); the median, and the per-step median over every step with an
  isolated point and a true contact of at least ``CONTACT_FORCE``.
- tracking: the tracked points' contact error (mean distance to the nearest box surface at
  the boxes' final poses, :func:`~stucco_drake.core.metrics.contact_error`) and the
  Fowlkes-Mallows index of their segments against the boxes they truly belong to; and each
  tracked point's distance to its *carried* true contact (the contact point fixed in the box
  it touched, at the box's final pose), which also sees a point left behind on a face that
  slid under it.

Per-step truth is logged here (a :class:`RobotContactTruth` every step) because detection is
scored per step of each action; the BOR Diagram asks for truth once per action only.

Units: m, N, s (CE reported in cm).
"""

from __future__ import annotations

import dataclasses
import time

import numpy as np
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import LogVectorOutput

from stucco_drake.core.metrics import contact_error, fowlkes_mallows
from stucco_drake.core.params import SoftTrackingParams
from stucco_drake.core.shapes import BoxSdf
from stucco_drake.core.soft_tracker import SoftTracker
from stucco_drake.robot.scara_probe import (
    probe_penetration,
    probe_surface_samples,
    scara_observed_robot_arguments,
)
from stucco_drake.scenes.probe_station import (
    ProbeScene,
    build_probe_station,
    free_space_statistics,
    make_station_simulator,
)
from stucco_drake.systems.contact_truth import (
    TRUTH_OBJECT,
    TRUTH_POINT,
    TRUTH_STRONGEST,
    RobotContactTruth,
    RobotObjectContacts,
)
from stucco_drake.systems.observed_robot import ObservedRobot
from stucco_drake.tracking import add_contact_tracking

#: A true contact step: the strongest probe-object force is at least this (N). The isolator
#: ignores wrench forces under 1 N (``ContactIsolator.min_force``), so weaker ones are not
#: contacts this chain is meant to see.
CONTACT_FORCE = 1.0
#: An action whose true contact force stays below this (N) on every step is truly free.
GRAZE_FORCE = 0.1
#: An action is truly in contact with this many true contact steps (10 ms at 2 ms steps).
MIN_CONTACT_STEPS = 5
#: Observer bandwidth K_O (1/s), the BOR Diagram's.
GAIN = 50.0
#: STUCCO's parameters and contact motion of Table II (``results/table_ii/stucco.yaml``):
#: Table I (sim) plus the touched-side rule, points moved within the friction cone.
TABLE_II_PARAMS = SoftTrackingParams(touched_side_margin=0.002, touched_side_softness=0.02,
                                     normal_probe_radius=0.003)  # fmt: skip
TABLE_II_DX_MODEL = "cone"
#: Steps after an action's end at which its results are read (the chain's pipeline delay).
_PIPELINE_STEPS = 5


@dataclasses.dataclass
class SecondRobotResult:
    """Scores of one run (see the module docstring), with what they were computed from.

    Attributes:
        truth_actions, detected_actions: (n_actions,) bool, true and detected contact.
        graze_actions: (n_actions,) bool, grazes (neither contact nor free: not scored).
        precision, recall: detection over the contact and free actions (NaN when undefined).
        isolation_errors: (n_points,) m, each tracked point's distance to its true contact.
        step_isolation_errors: (n_steps,) m, per step (isolated point and true contact).
        received: (n_points, 3) the points as the tracker received them (m, world).
        points, labels, truth_names: the tracked points (m, world), their segments and the
            boxes they truly belong to ("" when none was touched then).
        carried_truth: (n_points, 3) where each tracked point should be now (m, world): its
            true contact point, fixed in the box it touched, at that box's final pose (NaN
            for a point without a true contact). A tracker that follows the boxes puts its
            points there; one that leaves a point behind as its box is pushed does not, even
            when the point still lies on the box's surface (which CE alone cannot tell).
        ce: contact error (m); fmi: Fowlkes-Mallows index; wall: seconds.
        steps: the per-step logs (name -> (n_steps, k) array): ``truth``
            (:class:`RobotContactTruth`'s vector), ``action``, ``in_contact``,
            ``has_contact``, ``point`` (the isolator's), ``plant_state``.
    """

    truth_actions: np.ndarray
    detected_actions: np.ndarray
    graze_actions: np.ndarray
    precision: float
    recall: float
    isolation_errors: np.ndarray
    step_isolation_errors: np.ndarray
    received: np.ndarray
    points: np.ndarray
    labels: np.ndarray
    truth_names: np.ndarray
    carried_truth: np.ndarray
    ce: float
    fmi: float
    wall: float
    steps: dict

    def tracking_errors(self) -> np.ndarray:
        """(n_points,) m: each tracked point's distance to its carried true contact."""
        return np.linalg.norm(self.points - self.carried_truth, axis=1)

    def line(self) -> str:
        """The one-line summary the example prints."""
        n, t, g = (len(self.truth_actions), int(self.truth_actions.sum()),
                   int(self.graze_actions.sum()))  # fmt: skip
        return (f"second robot (SCARA probe, 3 boxes): detection precision "
                f"{self.precision:.2f} recall {self.recall:.2f} ({t} contact, {n - t - g} "
                f"free, {g} grazing actions), "
                f"isolation median {100 * np.median(self.isolation_errors):.2f} cm "
                f"(per step {100 * np.median(self.step_isolation_errors):.2f} cm), "
                f"tracking CE {100 * self.ce:.2f} cm, FMI {self.fmi:.3f}, points "
                f"{100 * np.nanmedian(self.tracking_errors()):.2f} cm from their carried "
                f"contacts (median), "
                f"{len(self.points)} points, wall {self.wall:.1f} s")  # fmt: skip


def _box_surfaces(station, plant_context) -> list:
    """World signed-distance callables of every box at its pose in ``plant_context``."""
    surfaces = []
    for box in station.scene.boxes:
        X_BW = station.objects[box.name].EvalPoseInWorld(plant_context).inverse()
        sdf = BoxSdf(tuple(0.5 * np.asarray(box.size)))
        surfaces.append(lambda p, sdf=sdf, X=X_BW: sdf(np.asarray(p) @ X.rotation().matrix().T
                                                       + X.translation()))  # fmt: skip
    return surfaces


def _build(station, stats, seed: int, tracker_params, dx_model: str):
    """The Diagram: the station, the chain around the arm, per-step truth and loggers."""
    scene, h = station.scene, float(station.scene.time_step)
    builder = DiagramBuilder()
    sub = builder.AddSystem(station.diagram)
    robot = ObservedRobot(**scara_observed_robot_arguments(scene.base_pose()))
    pxpen = probe_penetration()
    tracker_seed, icp_seed, cpf_seed = np.random.SeedSequence(seed).generate_state(3)
    samples = probe_surface_samples(np.random.default_rng([int(cpf_seed), 1]))
    labeller = RobotObjectContacts(station.plant, station.diagram, [station.robot],
                                   station.objects)  # fmt: skip
    target = scene.boxes[0]
    chain = add_contact_tracking(
        builder, robot, robot_state=sub.GetOutputPort("robot_state"),
        applied_torque=sub.GetOutputPort("applied_torque"),
        action_index=sub.GetOutputPort("action_index"), time_step=h,
        tracker=SoftTracker(pxpen, tracker_params), tracker_seed=int(tracker_seed),
        penetration=pxpen,
        target_shape=BoxSdf(tuple(0.5 * np.asarray(target.size))), icp_seed=int(icp_seed),
        cpf_seed=int(cpf_seed),
        estimator_kwargs={"gain": GAIN, "residual_statistics": stats,
                          "sampled_plant_outputs": False},
        isolator_kwargs={"samples": samples},
        truth=labeller, truth_state=sub.GetOutputPort("plant_state"), dx_model=dx_model,
    )  # fmt: skip
    for name, port in chain.outputs.items():
        builder.ExportOutput(port, name)
    truth = builder.AddSystem(RobotContactTruth(station.plant, [station.robot], station.objects))
    builder.Connect(sub.GetOutputPort("contact_results"), truth.get_input_port())
    logs = {name: LogVectorOutput(port, builder, h) for name, port in (
        ("truth", truth.get_output_port()),
        ("action", sub.GetOutputPort("action_index")),
        ("in_contact", chain.detector.GetOutputPort("in_contact")),
        ("has_contact", chain.isolator.GetOutputPort("has_contact")),
        ("point", chain.isolator.GetOutputPort("contact_point")),
        ("plant_state", sub.GetOutputPort("plant_state")),
    )}  # fmt: skip
    return builder.Build(), chain, logs


def _ratio(a: int, b: int) -> float:
    return a / b if b else float("nan")


def run_second_robot(seed: int = 0, scene: ProbeScene | None = None, stats=None, *,
                     tracker_params: SoftTrackingParams | None = TABLE_II_PARAMS,
                     dx_model: str = TABLE_II_DX_MODEL) -> SecondRobotResult:  # fmt: skip
    """Plays ``scene`` (default: :class:`ProbeScene`'s three boxes and pushes) through the
    chain and scores it (module docstring). ``stats``: the detector's free-space statistics
    (default :func:`free_space_statistics` of the scene, computed here)."""
    start = time.perf_counter()
    station = build_probe_station(scene)
    scene, h = station.scene, float(station.scene.time_step)
    stats = stats if stats is not None else free_space_statistics(scene, gain=GAIN)
    diagram, _, logs = _build(station, stats, seed, tracker_params, dx_model)
    simulator = make_station_simulator(diagram, h)
    context = simulator.get_context()
    pairs = []  # (point, its TruthContact, its action), in the order the tracker got them
    for k in range(len(scene.actions)):
        simulator.AdvanceTo((k + 1) * scene.action_duration + _PIPELINE_STEPS * h)
        contacts = diagram.GetOutputPort("action_contacts").Eval(context)
        truth = diagram.GetOutputPort("action_truth").Eval(context)
        pairs.extend((p, t, k) for p, t in zip(contacts.points, truth, strict=True))
    points = np.asarray(diagram.GetOutputPort("map_points").Eval(context)).reshape(-1, 3)
    labels = np.asarray(diagram.GetOutputPort("segment_labels").Eval(context))
    data = {name: log.FindLog(context).data().T for name, log in logs.items()}
    truth_actions, grazes, detected = _per_action(data, len(scene.actions))
    scored = detected & ~grazes
    tp = int(np.sum(truth_actions & scored))
    names = np.array([t.name for _, t, _ in pairs], dtype=object).astype(str)
    errors = np.array([np.linalg.norm(p - t.point) for p, t, _ in pairs])
    plant_context = station.plant.GetMyContextFromRoot(context)
    carried = _carried_truth(station, data, pairs, plant_context)
    ce = contact_error(points, _box_surfaces(station, plant_context)) if len(points) else np.nan
    known = names != ""
    fmi = fowlkes_mallows(names[known], labels[known]) if known.sum() >= 2 else np.nan
    return SecondRobotResult(
        truth_actions, detected, grazes, _ratio(tp, int(scored.sum())),
        _ratio(tp, int(truth_actions.sum())), errors, _step_errors(data),
        np.array([p for p, _, _ in pairs]).reshape(-1, 3), points, labels,
        names, carried, float(ce), float(fmi), time.perf_counter() - start, data,
    )  # fmt: skip


def _per_action(data: dict, n_actions: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(true contact, graze, detected) per action from the per-step logs."""
    action = np.round(data["action"][:, 0]).astype(int)
    force = data["truth"][:, TRUTH_STRONGEST]
    flagged = data["in_contact"][:, 0] > 0.5
    steps = [action == k for k in range(n_actions)]
    truth = np.array([np.sum(force[s] >= CONTACT_FORCE) >= MIN_CONTACT_STEPS for s in steps])
    free = np.array([not np.any(force[s] >= GRAZE_FORCE) for s in steps])
    detected = np.array([np.any(flagged[s]) for s in steps])
    return truth, ~truth & ~free, detected


def _carried_truth(station, data: dict, pairs, final_context) -> np.ndarray:
    """Each tracked point's true contact carried with its box to the box's final pose (see
    ``SecondRobotResult.carried_truth``). The box's pose at the contact is read from the
    logged plant state at the last step of the point's action that had an isolated point
    (the step the assembler latched it from)."""
    plant = station.plant
    scratch = plant.CreateDefaultContext()
    action = np.round(data["action"][:, 0]).astype(int)
    isolated = data["has_contact"][:, 0] > 0.5
    out = np.full((len(pairs), 3), np.nan)
    for i, (_, truth, k) in enumerate(pairs):
        steps = np.flatnonzero((action == k) & isolated)
        if truth.name == "" or not len(steps):
            continue
        plant.SetPositionsAndVelocities(scratch, data["plant_state"][steps[-1]])
        body = station.objects[truth.name]
        X_then, X_now = body.EvalPoseInWorld(scratch), body.EvalPoseInWorld(final_context)
        out[i] = X_now.multiply(X_then.inverse().multiply(truth.point))
    return out


def _step_errors(data: dict) -> np.ndarray:
    """Per-step isolation errors (m): steps with an isolated point and a true contact."""
    truth = data["truth"]
    both = (data["has_contact"][:, 0] > 0.5) & (truth[:, TRUTH_STRONGEST] >= CONTACT_FORCE)
    both &= truth[:, TRUTH_OBJECT] >= 0
    return np.linalg.norm(data["point"][both] - truth[both][:, TRUTH_POINT], axis=1)


__all__ = [
    "CONTACT_FORCE",
    "GRAZE_FORCE",
    "MIN_CONTACT_STEPS",
    "TABLE_II_DX_MODEL",
    "TABLE_II_PARAMS",
    "SecondRobotResult",
    "run_second_robot",
]
