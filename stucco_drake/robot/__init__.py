"""Our robot: the models' package map and URLs, the iiwa14 + bubble gripper's robot model, the
gripper's signed-distance grid (pxpen) and surface samples. Below ``systems/``: a system takes
these by argument; only the builders above name our robot."""
