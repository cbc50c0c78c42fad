"""The contact-tracking chain on a second robot: the SCARA probe arm pushing three boxes.

:func:`run_second_robot` (``episode``) wires :mod:`stucco_drake.tracking` around the probe
station of :mod:`stucco_drake.scenes.probe_station` with the probe's own model data
(:mod:`stucco_drake.robot.scara_probe`), plays the pushes and scores the chain against the
plant's contact results. Beside ``bor/``: both are the one chain around a robot.
"""

from stucco_drake.second_robot.episode import (
    CONTACT_FORCE,
    GRAZE_FORCE,
    MIN_CONTACT_STEPS,
    TABLE_II_DX_MODEL,
    TABLE_II_PARAMS,
    SecondRobotResult,
    run_second_robot,
)

__all__ = [
    "CONTACT_FORCE",
    "GRAZE_FORCE",
    "MIN_CONTACT_STEPS",
    "TABLE_II_DX_MODEL",
    "TABLE_II_PARAMS",
    "SecondRobotResult",
    "run_second_robot",
]
