"""Time schemes: each advances a :class:`~workbench.discretisation.Discretisation` one step.

``explicit`` — the paper's fully discrete scheme (eqs. 7.1–7.4): viscous term
implicit, elastic and contact terms lagged; one back-substitution per step.
``implicit`` — backward Euler with the contact terms implicit (semismooth Newton
condensed onto the contact dofs): unconditionally stable, first order.
``vi`` — Model B: one variational inequality per step (long memory, unilateral
constraint with a compliant layer), primal-dual active set on the contact nodes.
"""
from ..errors import Diverged, NewtonFailed
from .explicit_euler import ExplicitEuler
from .implicit_euler import ImplicitEuler
from .memory_vi import MemoryVI
from .stepping import march, time_grid

SCHEMES = {"explicit": ExplicitEuler, "implicit": ImplicitEuler, "vi": MemoryVI}

__all__ = ["SCHEMES", "ExplicitEuler", "ImplicitEuler", "MemoryVI", "Diverged", "NewtonFailed", "march", "time_grid"]
