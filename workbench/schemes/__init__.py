"""Time schemes: each advances a :class:`~workbench.discrete.discretisation.Discretisation` one step (:mod:`.base`).

``explicit`` — the paper's fully discrete scheme (eqs. 7.1–7.4): viscous term
implicit, elastic and contact terms lagged; one back-substitution per step.
``implicit`` — backward Euler with the contact terms implicit (semismooth Newton
condensed onto the contact dofs): unconditionally stable, first order.
``bdf2`` — variable-step BDF2 with the same implicit contact, beta to second order.
``vi`` — Model B: one variational inequality per step (long memory, unilateral
constraint with a compliant layer), primal-dual active set on the contact nodes.

:data:`workbench.input.numerics.SCHEMES` is the one place a scheme is registered: its name,
model, module and class. The scene's choices of ``scheme`` and each model's schemes come
from it; the classes are imported when first used.
"""
from __future__ import annotations

import importlib

from ..errors import Diverged, NewtonFailed
from ..input.numerics import SCHEMES


def scheme_class(name: str):
    """The class of the scheme called ``name``."""
    entry = SCHEMES[name]
    return getattr(importlib.import_module(f"{__name__}.{entry.module}"), entry.cls)


def __getattr__(attr):  # ExplicitEuler, ImplicitEuler, MemoryVI on first use
    for name, entry in SCHEMES.items():
        if attr == entry.cls:
            return scheme_class(name)
    raise AttributeError(attr)


__all__ = ["scheme_class", "Diverged", "NewtonFailed"]
