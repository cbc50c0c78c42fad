"""Contact isolation: cost per call, and accuracy of particle reuse across a contact's steps.

Synthetic single contacts on the bubble gripper's surface (points from a sampling independent of
the filter's), each held for ``STEPS`` steps of noisy wrenches; prints, for the filter with and
without particle reuse and for exhaustive scoring, the median and 90th-percentile isolation
error (m) and the mean time per call (ms). Prints only.
"""

from __future__ import annotations

import time

import numpy as np

from stucco_drake.core.contact_isolation import ContactParticleFilter
from stucco_drake.robot.gripper_samples import sample_gripper_surface
from stucco_drake.systems.contact_isolator import ContactIsolator, pose_vector

STEPS = 20  # isolation calls per contact
CONTACTS = 150
NOISE = [(0.0, 0.0), (0.03, 0.3), (0.1, 0.5)]  # (torque N m, force N) std per wrench component


def contacts(rng, points, normals):
    """(point, force) pairs: 5-10 N within 30 degrees of the inward normal."""
    for k in rng.choice(len(points), CONTACTS, replace=False):
        tilt = rng.normal(size=3)
        tilt -= (tilt @ normals[k]) * normals[k]
        angle = np.radians(rng.uniform(0, 30))
        d = -np.cos(angle) * normals[k] + np.sin(angle) * tilt / np.linalg.norm(tilt)
        yield points[k], d * rng.uniform(5.0, 10.0)


def run(cpf: ContactParticleFilter, noise, mode: str, seed: int = 0):
    # Separate streams: every mode sees the same contacts and wrench noise.
    rng, filter_rng = np.random.default_rng(seed), np.random.default_rng(seed + 1)
    truth_points, truth_normals = sample_gripper_surface(np.random.default_rng(99), 0.01)
    errors, elapsed, calls = [], 0.0, 0
    for c, f in contacts(rng, truth_points, truth_normals):
        particles = None
        for _ in range(STEPS):
            torque = np.cross(c, f) + noise[0] * rng.standard_normal(3)
            force = f + noise[1] * rng.standard_normal(3)
            start = time.perf_counter()
            if mode == "exhaustive":
                result = cpf.exhaustive(torque, force)
            else:
                result, kept = cpf.step(torque, force, filter_rng, particles)
                particles = kept if mode == "reuse" else None
            elapsed += time.perf_counter() - start
            calls += 1
            errors.append(np.linalg.norm(result.point - c))
    errors = np.array(errors)
    return np.median(errors), np.quantile(errors, 0.9), 1e3 * elapsed / calls


def isolator_update_cost(iso: ContactIsolator, n: int = 300) -> float:
    """Mean ms per periodic update of the Drake system under a Simulator (CPF path, reused
    particles), the simulator's own stepping included."""
    from pydrake.math import RigidTransform
    from pydrake.systems.analysis import Simulator

    simulator = Simulator(iso)
    context = simulator.get_mutable_context()
    iso.GetInputPort("ee_wrench").FixValue(context, [0.0, -0.4, 0.0, 7.0, 0.0, 0.0])
    iso.GetInputPort("gripper_pose").FixValue(context, pose_vector(RigidTransform()))
    iso.GetInputPort("in_contact").FixValue(context, [1.0])
    simulator.AdvanceTo(0.0105)  # the first (exhaustive) updates
    start = time.perf_counter()
    simulator.AdvanceTo(0.0105 + n * 1e-3)
    assert iso.GetOutputPort("contact_source").Eval(context)[0] == 1.0
    return 1e3 * (time.perf_counter() - start) / n


def main():
    start = time.perf_counter()
    iso = ContactIsolator(1e-3, seed=0)
    seconds, n = time.perf_counter() - start, len(iso.filter.points)
    print(f"isolator construction (sampling + neighbour lists): {seconds:.2f} s, {n} samples")
    cpf = iso.filter
    for noise in NOISE:
        for mode in ("fresh", "reuse", "exhaustive"):
            median, p90, ms = run(cpf, noise, mode)
            print(
                f"noise tau {noise[0]:.2f} N m, f {noise[1]:.1f} N | {mode:10s}: median "
                f"{1e3 * median:6.2f} mm, 90th pct {1e3 * p90:6.1f} mm, {ms:.3f} ms/call"
            )
    print(f"ContactIsolator update (CPF, reuse): {isolator_update_cost(iso):.3f} ms/call")


if __name__ == "__main__":
    main()
