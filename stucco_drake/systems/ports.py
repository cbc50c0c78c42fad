"""Input checks shared by the systems: bad sensor data fails loudly, naming the port."""

from __future__ import annotations

import math

import numpy as np


def eval_finite(system_name: str, context, port) -> np.ndarray:
    """``port.Eval(context)``, raising a one-line ValueError when an entry is NaN or infinite."""
    value = np.asarray(port.Eval(context))
    # A sum is NaN or inf when any entry is: one cheap test per step, the full scan on failure.
    if not math.isfinite(float(value.sum())) and not np.all(np.isfinite(value)):
        bad = np.flatnonzero(~np.isfinite(value)).tolist()
        raise ValueError(
            f"{system_name} input port '{port.get_name()}' has NaN or infinite entries at "
            f"indices {bad} at t={context.get_time():.6g} s"
        )
    return value
