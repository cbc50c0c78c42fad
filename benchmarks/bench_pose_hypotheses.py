"""The target-pose hypotheses' search: time per call on logged development episodes.

For each log (default: one probed development episode per scene family, committed under
``results/development/``), STUCCO is replayed at the settings its folder recorded (not timed),
then :func:`~stucco_drake.eval.target_estimates.hypotheses_estimate` (every motion scale, the
free space of every logged config) is timed ``--repeats`` times from the same generator seed.
Prints each log's contact count, hypotheses kept, median and best time per call (s), and the
load average the run saw. Prints only; run it at two commits for a before/after.

Run: taskset -c 1 python benchmarks/bench_pose_hypotheses.py [--repeats 5] [--logs A.npz ...]
"""

from __future__ import annotations

import os

for _name in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_name, "1")  # before numpy loads its BLAS

import argparse  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
DEVELOPMENT = ROOT / "results" / "development"
LOGS = (DEVELOPMENT / "probe_disc_fb" / "logs" / "FB-L1006_0.npz",
        *(DEVELOPMENT / "probe_disc" / "logs" / f"{name}_0.npz"
          for name in ("BC-L1021", "IB-L1020", "TC-L1024")))  # fmt: skip


def time_log(path: Path, repeats: int) -> tuple[int, int, list[float]]:
    """(contacts, hypotheses kept, seconds per call) of the search on one replayed log."""
    from stucco_drake.bor.log import log_penetration
    from stucco_drake.cli.estimates import _table_settings
    from stucco_drake.eval.episode_log import EpisodeLog
    from stucco_drake.eval.replay import replay
    from stucco_drake.eval.target_estimates import hypotheses_estimate, log_target_shape

    dx_model, params, stream, hypothesis_params = _table_settings(path.parent.parent)
    log = EpisodeLog.load(path)
    penetration = log_penetration(log)
    timed: list[float] = []
    kept = []

    def search(replayed, tracker):
        shape = log_target_shape(replayed)
        for _ in range(repeats):
            start = time.perf_counter()
            found = hypotheses_estimate(np.random.default_rng([replayed.seed, 1]), replayed,
                                        tracker, shape, penetration, hypothesis_params)  # fmt: skip
            timed.append(time.perf_counter() - start)
        kept.append(0 if found is None else len(found.poses))

    replay(log, "stucco", log.seed + 1000 * stream, params, penetration=penetration,
           dx_model=dx_model, grasp=search)  # fmt: skip
    return len(log.contact_points), kept[0], timed


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--logs", nargs="+", type=Path, default=list(LOGS),
                        help="episode logs inside a table folder (its table_config.yaml is read)")
    args = parser.parse_args()
    if args.repeats < 1:
        parser.error("--repeats: must be at least 1")
    missing = [str(p) for p in args.logs if not p.is_file()]
    if missing:
        parser.error(f"--logs: no such file: {', '.join(missing)}")
    print(f"{'log':<16} {'contacts':>8} {'kept':>6} {'median s':>9} {'best s':>7}")
    total = []
    for path in args.logs:
        contacts, kept, timed = time_log(path, args.repeats)
        total.append(np.median(timed))
        print(f"{path.stem:<16} {contacts:>8} {kept:>6} {np.median(timed):9.2f} "
              f"{min(timed):7.2f}")
    print(f"sum of medians: {sum(total):.2f} s; load average {os.getloadavg()[0]:.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
