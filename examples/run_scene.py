"""Rummage through scene FB blind, track the contacts with STUCCO, score the result.

Run: python examples/run_scene.py [N_ACTIONS]   (default 10; the full scene has 54 actions)
"""

import sys

from stucco_drake.bor.episode import run_episode

n_actions = int(sys.argv[1]) if len(sys.argv) > 1 else 10


def progress(k, contacts):
    print(f"action {k + 1:3d}: {len(contacts.points)} contact point(s)", flush=True)


result = run_episode("FB", method="stucco", seed=0, n_actions=n_actions, on_action=progress)
print(result.summary())
if result.estimate is not None:
    e, true = result.estimate, result.target_pose_true
    print(f"target estimate (x, y, yaw) = ({e.x:.3f}, {e.y:.3f}, {e.yaw:.2f}); "
          f"true ({true[0]:.3f}, {true[1]:.3f}, {true[2]:.2f})")
