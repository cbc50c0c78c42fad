"""Watch the BOR run of scene FB in Meshcat (opens a local server; exits when the run ends).

Run: python examples/inspect_in_meshcat.py [N_ACTIONS]   (default 5)
Open the printed URL in a browser while it runs.
"""

import sys

from pydrake.geometry import Meshcat, MeshcatParams

from stucco_drake.bor.episode import run_episode

n_actions = int(sys.argv[1]) if len(sys.argv) > 1 else 5
meshcat = Meshcat(MeshcatParams(host="localhost"))  # this machine only
print(f"meshcat: {meshcat.web_url()}", flush=True)
result = run_episode("FB", "stucco", 0, n_actions, meshcat=meshcat)
# Draw the tracked contacts over the scene, one colour per segment.
for i, (point, label) in enumerate(zip(result.map_points, result.labels, strict=True)):
    from pydrake.geometry import Rgba, Sphere
    from pydrake.math import RigidTransform

    hue = [(0.9, 0.4, 0.1), (0.1, 0.6, 0.2), (0.2, 0.3, 0.9), (0.7, 0.2, 0.7)][int(label) % 4]
    meshcat.SetObject(f"contacts/{i}", Sphere(0.005), Rgba(*hue, 1.0))
    meshcat.SetTransform(f"contacts/{i}", RigidTransform(point))
print(result.summary())
