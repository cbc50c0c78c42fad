"""The contact-tracking chain on a robot that is not our iiwa: a SCARA arm with a probe.

A three-joint SCARA-type arm (``models/scara_probe``) with a rigid spherical probe pushes three
boxes through 34 prescribed planar steps. The same systems as in the BOR Diagram
(``add_contact_tracking``: momentum observer, chi-square detector, contact particle filter,
STUCCO) detect, isolate and track the contacts from the arm's joint torques alone, with the
probe's own surface samples, pxpen grid and free-space statistics. Scored against the plant's
own contact results (see ``stucco_drake.second_robot``); prints one line.

Run: python examples/second_robot.py [SEED]   (default 0; about 40 s)
"""

import sys

from stucco_drake.second_robot import run_second_robot

seed = int(sys.argv[1]) if len(sys.argv) > 1 else 0
print(run_second_robot(seed).line())
