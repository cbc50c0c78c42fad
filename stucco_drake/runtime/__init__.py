"""How the process computes: the numerical kernels pinned when ``stucco_drake`` is imported.

Below every other package. ``stucco_drake/__init__.py`` imports :mod:`.kernels` before anything
loads numpy, so this package and its modules import only the standard library.
"""
