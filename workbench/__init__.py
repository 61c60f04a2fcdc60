"""workbench: quasistatic contact of viscoelastic bodies with adhesion, on NGSolve.

The public names (``run``, ``load``, ``write``, ``scene``, ``Scene``, ``Study``, ``ParameterError``,
``Diverged``) are imported on first use, so that ``import workbench`` and the commands that need
neither NGSolve nor xarray (``workbench scenes``, ``workbench show``) start at once.

Imported before NumPy, workbench starts the BLAS libraries with one thread (unless
``OPENBLAS_NUM_THREADS`` / ``OMP_NUM_THREADS`` / ``MKL_NUM_THREADS`` are set already): their
thread pools, started with more, stalled runs 3-10x at random on two cores even when held at
one thread later (:mod:`workbench.threads`).

>>> import workbench
>>> ds = workbench.run("tp1", h=0.1, k=0.1, progress=False)
>>> float(ds.beta.isel(time=-1, facet=0)) < 1.0
True
"""
import os as _os
import sys as _sys
from importlib import import_module

if "numpy" not in _sys.modules:  # before any BLAS library loads: see workbench/threads.py
    for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
        _os.environ.setdefault(_var, "1")

from .errors import Diverged, ParameterError  # noqa: E402

__version__ = "0.1.0"
__all__ = ["run", "load", "write", "scene", "Scene", "Study", "ParameterError", "Diverged"]

_LAZY = {"run": "runner", "load": "results", "write": "results", "scene": "scenes", "Scene": "scenes",
         "Study": "study"}


def __getattr__(name):
    if name in _LAZY:
        value = getattr(import_module(f".{_LAZY[name]}", __name__), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'workbench' has no attribute {name!r}")


def __dir__():
    return sorted(list(globals()) + list(_LAZY))
