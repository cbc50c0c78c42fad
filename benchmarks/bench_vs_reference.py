"""Our SoftTracker beside the authors' (``stucco`` 1.2.1, torch) on the same contact stream.

Both trackers get the built-in planar rummaging stream of ``bench_soft_tracker.py`` (a 10 cm
disc EE pushing 8 boxes), Table I's simulation parameters (l = 0.02 m^2, lambda = 0.002 m^2,
tolerance 2 mm, 100 particles, ESS threshold 0.8) and the same pxpen: the 1 mm grid SDF of the
disc, trilinearly interpolated, for ours; for theirs by default the disc's exact signed distance
in closed form in torch (its cheapest possible pxpen, so the ratio is conservative), or with
``--reference-pxpen grid`` the same grid interpolated in torch. Each runs on
one thread (torch.set_num_threads(1); numpy's BLAS limited before numpy loads). For each contact
count both are brought to that many contacts, then one in-contact update of a copy of each is
timed, alternating which goes first, ``--repeats`` times (``--large-repeats`` from
``--large`` contacts on: the reference takes about a second per update there, and growing it
from 200 to 400 contacts takes minutes). Streams: one EE orientation, and one
orientation per contact (yaw within +-3 deg, as in closed-loop runs; the disc is symmetric
about z, so the contacts stay consistent). Prints medians and p90s (ms) and the ratio of
medians (reference / ours).

Needs the optional extra: pip install -e '.[reference]' (in a separate virtualenv, so the
project's stays as CI has it). Without it this prints how to install it and exits 0.

Run: taskset -c 1 python benchmarks/bench_vs_reference.py [--contacts 50 100 200 400]
     [--repeats 15] [--large 400 --large-repeats 7]
"""

from __future__ import annotations

import os

for _name in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_name, "1")  # before numpy loads its BLAS

import argparse  # noqa: E402
import copy  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_soft_tracker import contact_stream, robot_grid, yaw_rotation  # noqa: E402

#: The rummaging disc of ``robot_grid`` (m).
DISC_RADIUS, DISC_HALF_HEIGHT = 0.05, 0.05

from stucco_drake.core import RobotPenetration, SoftTracker, SoftTrackingParams  # noqa: E402

try:
    import torch
    from stucco.tracking import ContactParameters, ContactSetSoft
except ImportError:
    torch = None


class TorchGridPenetration:
    """The reference's pxpen(configs [c, 4], points [p, 3]) -> [c, p] signed distance (m).

    A config is (x, y, z, yaw) of the EE (m, rad); each point is looked up in the EE frame,
    R_z(yaw)^T (p - x), on the same grid as ours, trilinearly; +inf off the grid, as ours.
    """

    def __init__(self, grid):
        self.values = torch.tensor(grid.values, dtype=torch.float32)
        self.lower = torch.tensor(grid.lower, dtype=torch.float32)
        self.resolution = float(grid.resolution)
        self.shape = torch.tensor(grid.values.shape)

    def __call__(self, configs, points):
        offset = points[None, :, :] - configs[:, None, :3]
        c, s = torch.cos(configs[:, 3:4]), torch.sin(configs[:, 3:4])
        x, y = offset[..., 0], offset[..., 1]
        local = torch.stack([c * x + s * y, -s * x + c * y, offset[..., 2]], -1)
        u = (local - self.lower) / self.resolution
        top = (self.shape - 1).to(u.dtype)
        inside = ((u >= 0) & (u <= top)).all(-1)
        base = torch.minimum(torch.clamp(torch.floor(u), min=0), top - 1)
        f = u - base
        base = base.long()
        ny, nz = int(self.shape[1]), int(self.shape[2])
        index = (base[..., 0] * ny + base[..., 1]) * nz + base[..., 2]
        v = self.values.reshape(-1)
        fx, fy, fz = f[..., 0], f[..., 1], f[..., 2]

        def lerp_z(offset):
            lo = v[index + offset]
            return lo + (v[index + offset + 1] - lo) * fz

        c0 = lerp_z(0)
        c0 = c0 + (lerp_z(nz) - c0) * fy
        c1 = lerp_z(ny * nz)
        c1 = c1 + (lerp_z(ny * nz + nz) - c1) * fy
        result = c0 + (c1 - c0) * fx
        return torch.where(inside, result, torch.full_like(result, float("inf")))


class TorchDiscPenetration:
    """The reference's pxpen as the disc's exact signed distance in closed form (m): the
    cheapest pxpen the reference can be given, so the ratio against it is the conservative
    one. A config is (x, y, z, yaw); the disc is symmetric about z, so yaw does not enter."""

    def __init__(self, radius: float, half_height: float):
        self.radius, self.half_height = radius, half_height

    def __call__(self, configs, points):
        offset = points[None, :, :] - configs[:, None, :3]
        radial = torch.linalg.norm(offset[..., :2], dim=-1) - self.radius
        axial = offset[..., 2].abs() - self.half_height
        outside = torch.sqrt(radial.clamp(min=0) ** 2 + axial.clamp(min=0) ** 2)
        return outside + torch.minimum(torch.maximum(radial, axial), torch.zeros_like(radial))


def reference_dynamics(points, configs, dx):
    """pxdyn: points and configs translate with the EE; the config's yaw part moves by 0."""
    return points + dx[..., :3], configs + dx


def make_reference(grid, pxpen: str):
    params = SoftTrackingParams.sim()
    penetration = TorchGridPenetration(grid) if pxpen == "grid" else TorchDiscPenetration(
        DISC_RADIUS, DISC_HALF_HEIGHT)  # fmt: skip
    contact = ContactParameters(length=params.length,
                                penetration_length=params.penetration_length,
                                hard_assignment_threshold=params.connection_threshold,
                                intersection_tolerance=params.intersection_tolerance)  # fmt: skip
    return ContactSetSoft(penetration, contact, pxdyn=reference_dynamics,
                          n_particles=params.n_particles,
                          n_eff_threshold=params.resample_ess_fraction, dim=3)  # fmt: skip


def reference_update(tracker, position, yaw, point, dx):
    config = torch.tensor([*position, yaw], dtype=torch.float32)
    motion = torch.tensor([[*dx, 0.0]], dtype=torch.float32)
    tracker.update(config, motion, torch.tensor(point[None], dtype=torch.float32))


def run_stream(grid, args, orientations: bool, pxpen: str):
    rng = np.random.default_rng(0)
    positions, points, dx = contact_stream(rng, max(args.contacts) + max(args.repeats,
                                                                         args.large_repeats))
    yaws = rng.uniform(-0.05, 0.05, len(points)) if orientations else np.zeros(len(points))
    ours = SoftTracker(RobotPenetration(grid), SoftTrackingParams.sim())
    reference = make_reference(grid, pxpen)
    shared = {id(reference.pxpen): reference.pxpen}
    ours_rng = np.random.default_rng(1)
    torch.manual_seed(1)
    done = 0
    for contacts in sorted(args.contacts):
        for t in range(done, contacts):  # both trackers grow along the same stream
            ours.update(ours_rng, positions[t], points[t : t + 1], dx[t : t + 1],
                        yaw_rotation(yaws[t]))  # fmt: skip
            reference_update(reference, positions[t], yaws[t], points[t], dx[t])
        done = contacts
        timings = {"ours": [], "reference": []}
        repeats = args.large_repeats if contacts >= args.large else args.repeats
        for r in range(repeats):
            t = contacts + r
            order = ("ours", "reference") if r % 2 == 0 else ("reference", "ours")
            for name in order:
                if name == "ours":
                    trial = copy.deepcopy(ours)
                    start = time.perf_counter()
                    trial.update(np.random.default_rng(r), positions[t], points[t : t + 1],
                                 dx[t : t + 1], yaw_rotation(yaws[t]))  # fmt: skip
                else:
                    trial = copy.deepcopy(reference, dict(shared))
                    start = time.perf_counter()
                    reference_update(trial, positions[t], yaws[t], points[t], dx[t])
                timings[name].append(time.perf_counter() - start)
        o, f = (np.array(timings[k]) * 1e3 for k in ("ours", "reference"))
        stream = "one per contact" if orientations else "one"
        print(f"| {stream} | {pxpen} | {contacts} ({repeats}) | {np.median(o):.2f} | "
              f"{np.percentile(o, 90):.2f} | {np.median(f):.2f} | {np.percentile(f, 90):.2f} | "
              f"{np.median(f) / np.median(o):.1f} |", flush=True)  # fmt: skip


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--contacts", type=int, nargs="+", default=[50, 100, 200, 400])
    parser.add_argument("--repeats", type=int, default=15)
    parser.add_argument("--large", type=int, default=400,
                        help="from this many contacts on, time --large-repeats updates")
    parser.add_argument("--large-repeats", type=int, default=7)
    parser.add_argument("--stream", choices=("one", "per-contact", "both"), default="both")
    parser.add_argument("--reference-pxpen", choices=("disc", "grid", "both"), default="disc",
                        help="the reference's pxpen: the disc's closed form (default, its "
                             "cheapest) or the same 1 mm grid as ours, interpolated in torch")
    args = parser.parse_args()
    if torch is None:
        print("bench_vs_reference: needs the reference extra; install it (in a separate "
              "virtualenv) with: pip install -e '.[reference]'")  # fmt: skip
        return
    torch.set_num_threads(1)
    grid = robot_grid()
    print(f"# in-contact update, 100 particles, Table I sim; numpy {np.__version__}, "
          f"torch {torch.__version__}, one thread each; load average at start "
          f"{' '.join(f'{x:.2f}' for x in os.getloadavg())}")  # fmt: skip
    print("| EE orientations | reference pxpen | contacts (repeats) | ours median (ms) | ours p90 "
          "| reference median (ms) | reference p90 | reference / ours |")
    print("|---|---|---:|---:|---:|---:|---:|---:|")
    streams = {"one": (False,), "per-contact": (True,), "both": (False, True)}[args.stream]
    kinds = ("disc", "grid") if args.reference_pxpen == "both" else (args.reference_pxpen,)
    for orientations in streams:
        for pxpen in kinds:
            run_stream(grid, args, orientations, pxpen)


if __name__ == "__main__":
    main()
