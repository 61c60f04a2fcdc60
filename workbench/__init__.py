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

_BLAS_VARIABLES = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")
#: Whether every BLAS library of this process started with one thread (workbench came before them and the
#: variables say 1); :func:`_lean_process` lets a process of its own rely on it.
_BLAS_STARTED_SINGLE = not {"numpy", "scipy", "ngsolve"} & set(_sys.modules)
if _BLAS_STARTED_SINGLE:  # before any BLAS library loads: see workbench/threads.py
    for _var in _BLAS_VARIABLES:
        _os.environ.setdefault(_var, "1")
    _BLAS_STARTED_SINGLE = all(_os.environ[_var] == "1" for _var in _BLAS_VARIABLES)


def _lean_process() -> None:
    """For a process started to run scenes only (``workbench run``, a study's worker), where no user code runs
    before the run: skip what such a process does not need (measured on ``workbench run tp5``, 1.7 s in all).

    * dask counts as absent. With dask installed, xarray imports dask.array when it builds a Dataset and
      dask.distributed when it writes one (looking for chunked arrays and a scheduler's lock): 0.35 s, for
      a process whose arrays are all NumPy. Python's own rule (``sys.modules[name] is None``: the import
      raises ImportError) takes xarray down its no-dask path.
    * When every BLAS pool started with one thread, nobody can have raised them since: the runs skip
      threadpoolctl's library scan (40 ms; :func:`workbench.threads.blas_single_threaded`).

    Not for a session (a notebook may want dask, or set its own BLAS threads, later).
    """
    from . import threads

    for name in ("dask", "distributed"):
        _sys.modules.setdefault(name, None)
    threads.POOLS_STARTED_SINGLE = _BLAS_STARTED_SINGLE


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
