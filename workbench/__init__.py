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
import os as _os
from importlib import import_module

from .errors import Diverged, Interrupted, ParameterError


def _source_stats() -> tuple:
    """(name, modification time in ns, size) of each of the package's source files, sorted; an editor's files (names
    starting with a dot) and the compiled caches left out."""
    root, out = _os.path.dirname(_os.path.abspath(__file__)), []
    for folder, subfolders, files in _os.walk(root):
        subfolders[:] = [d for d in subfolders if not d.startswith(".") and d != "__pycache__"]
        for name in files:
            if name.endswith(".py") and not name.startswith("."):
                path = _os.path.join(folder, name)
                try:
                    stat = _os.stat(path)
                except OSError:
                    continue
                out.append((_os.path.relpath(path, root).replace(_os.sep, "/"), stat.st_mtime_ns, stat.st_size))
    return tuple(sorted(out))


#: The sources as this process imported them (1 ms): a run's code digest says where they changed since
#: (:func:`workbench.output.results.code_digest`).
_SOURCES = _source_stats()

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
