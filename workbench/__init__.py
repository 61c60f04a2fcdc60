"""workbench: quasistatic contact of viscoelastic bodies with adhesion, on NGSolve.

>>> import workbench
>>> ds = workbench.run("tp1", h=0.1, k=0.1, progress=False)
>>> float(ds.beta.isel(time=-1, facet=0)) < 1.0
True
"""
from .parameters import ParameterError
from .results import load, write
from .run import run
from .scenes import Scene, scene
from .schemes import Diverged
from .study import Study

__version__ = "0.1.0"
__all__ = ["run", "load", "write", "scene", "Scene", "Study", "ParameterError", "Diverged"]
