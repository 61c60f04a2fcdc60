"""Time schemes: each advances a :class:`~workbench.discretisation.Discretisation` one step.

``explicit`` — the paper's fully discrete scheme (eqs. 7.1–7.4): viscous term
implicit, elastic and contact terms lagged; one back-substitution per step.
``implicit`` — backward Euler with the contact terms implicit (semismooth Newton
condensed onto the contact dofs): unconditionally stable, first order.
"""
from .explicit_euler import ExplicitEuler
from .implicit_euler import ImplicitEuler, NewtonFailed
from .stepping import Diverged, march, time_grid

SCHEMES = {"explicit": ExplicitEuler, "implicit": ImplicitEuler}

__all__ = ["SCHEMES", "ExplicitEuler", "ImplicitEuler", "Diverged", "NewtonFailed", "march", "time_grid"]
