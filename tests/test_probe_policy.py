"""The probe policy in the BOR Diagram (systems/probe_policy.py): after a few prescribed
actions that touch IB's cracker box, the probes' contacts are on the box, judged by the
plant's own contact results (the assembler's ground truth), and the policy stops within its
budget."""

import dataclasses

import pytest

from stucco_drake.core.probing import ProbeParams

# IB's prescribed actions 12-14 push the box (a development layout's log shows it); the
# first 15 leave tracked points on it for the hypotheses.
N_PRESCRIBED = 15
BUDGET = 20


@pytest.fixture(scope="module")
def probed_ib():
    from stucco_drake.bor.diagram import build_bor_diagram
    from stucco_drake.bor.episode import make_bor_simulator, run_episode
    from stucco_drake.scenes import load_scene

    scene = load_scene("IB")
    scene = dataclasses.replace(scene, actions=scene.actions[:N_PRESCRIBED])
    bor = build_bor_diagram(scene, "stucco", seed=0, dx_model="cone",
                            probe=ProbeParams(max_actions=BUDGET))
    simulator = make_bor_simulator(bor)
    truth = []

    def record(k, contacts):
        names = bor.diagram.GetOutputPort("action_truth").Eval(simulator.get_context())
        truth.append([t.name for t in names])

    result = run_episode(scene, bor=bor, simulator=simulator, on_action=record)
    state = bor.policy.probe_state(bor.policy.GetMyContextFromRoot(simulator.get_context()))
    return result, truth, state.policy


def test_prescribed_actions_touch_the_box_first(probed_ib):
    _, truth, _ = probed_ib
    assert any("target" in names for names in truth[:N_PRESCRIBED])


def test_probes_touch_the_box_again_and_stop_within_the_budget(probed_ib):
    result, truth, policy = probed_ib
    assert 1 <= policy.actions <= BUDGET
    assert result.n_actions == N_PRESCRIBED + policy.actions
    probed = [name for names in truth[N_PRESCRIBED:] for name in names]
    # Drake's contact results put the probes' contacts on the box, and most of them.
    assert probed.count("target") >= 1
    assert probed.count("target") >= len(probed) / 2

