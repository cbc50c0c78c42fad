"""stucco_drake: soft tracking of contacts in clutter (STUCCO) on Drake."""

# Before anything loads numpy: the same numerical kernels on every machine (see runtime/kernels.py).
from stucco_drake.runtime import kernels as _kernels

_kernels.pin()
