"""Time schemes: each advances a :class:`~workbench.discretisation.Discretisation` one step (:mod:`.base`).

``explicit`` — the paper's fully discrete scheme (eqs. 7.1–7.4): viscous term
implicit, elastic and contact terms lagged; one back-substitution per step.
``implicit`` — backward Euler with the contact terms implicit (semismooth Newton
condensed onto the contact dofs): unconditionally stable, first order.
``bdf2`` — variable-step BDF2 with the same implicit contact, beta to second order.
``vi`` — Model B: one variational inequality per step (long memory, unilateral
constraint with a compliant layer), primal-dual active set on the contact nodes.

:data:`REGISTRY` is the one place a scheme is registered: its name, module, class and
model. The scene's choices of ``scheme`` and each model's schemes come from it; the
classes are imported when first used.
"""
from __future__ import annotations

import importlib

from ..errors import Diverged, NewtonFailed

#: scheme name -> (module in this package, class, model)
REGISTRY = {
    "explicit": ("explicit_euler", "ExplicitEuler", "A"),
    "implicit": ("implicit_euler", "ImplicitEuler", "A"),
    "bdf2": ("bdf2", "BDF2", "A"),
    "vi": ("memory_vi", "MemoryVI", "B"),
}


def scheme_class(name: str):
    """The class of the scheme called ``name``."""
    module, cls, _ = REGISTRY[name]
    return getattr(importlib.import_module(f"{__name__}.{module}"), cls)


def __getattr__(attr):  # ExplicitEuler, ImplicitEuler, MemoryVI, SCHEMES on first use
    for name, (_, cls, _) in REGISTRY.items():
        if attr == cls:
            return scheme_class(name)
    if attr == "SCHEMES":
        return {name: scheme_class(name) for name in REGISTRY}
    raise AttributeError(attr)


__all__ = ["REGISTRY", "scheme_class", "Diverged", "NewtonFailed"]
