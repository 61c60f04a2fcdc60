"""Time schemes: each advances a :class:`~workbench.discretisation.Discretisation` one step.

``explicit`` — the paper's fully discrete scheme (eqs. 7.1–7.4): viscous term
implicit, elastic and contact terms lagged; one back-substitution per step.
"""
from .explicit_euler import ExplicitEuler
from .stepping import Diverged, march, time_grid

SCHEMES = {"explicit": ExplicitEuler}

__all__ = ["SCHEMES", "ExplicitEuler", "Diverged", "march", "time_grid"]
