"""workbench: quasistatic contact of viscoelastic bodies with adhesion, on NGSolve.

The public names (``run``, ``load``, ``write``, ``scene``, ``Scene``, ``Study``, ``ParameterError``,
``Diverged``) are imported on first use, so that ``import workbench`` and the commands that need
neither NGSolve nor xarray (``workbench scenes``, ``workbench show``) start at once.

``import workbench`` changes nothing in the process: a run holds the BLAS thread pools at one thread while it
computes and gives them back after (:mod:`workbench.running.threads`); the command line and the study workers, processes
of workbench's own, start them with one thread (:func:`workbench.running.threads.lean_process`).

>>> import workbench
>>> ds = workbench.run("tp1", h=0.1, k=0.1, progress=False)
>>> float(ds.beta.isel(time=-1, facet=0)) < 1.0
True
"""
from importlib import import_module

from .errors import Diverged, Interrupted, ParameterError

__version__ = "0.1.0"
__all__ = ["run", "load", "write", "scene", "Scene", "Study", "ParameterError", "Diverged", "Interrupted"]

_LAZY = {"run": "running.runner", "load": "output.results", "write": "output.results", "scene": "input.scenes",
         "Scene": "input.scenes", "Study": "study"}


def __getattr__(name):
    if name in _LAZY:
        value = getattr(import_module(f".{_LAZY[name]}", __name__), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'workbench' has no attribute {name!r}")


def __dir__():
    return sorted(list(globals()) + list(_LAZY))
